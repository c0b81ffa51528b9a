"""The phantom's coronary tree: geometry, radii, stenosis and its ground truth.

A random main vessel and 1-3 side branches are drawn as wiggly curves on a
heart-sized ellipsoid (every 0.1 mm), kept only when the whole tree fits
both fields of view and the reconstruction segment is not strongly
foreshortened; the main vessel tapers linearly and carries a cosine stenosis
of a given diameter percentage. :func:`truth_from_tree` turns a draw into
the :class:`PhantomTruth` a benchmark measures against (mm, world frame =
view A's frame).

Harder anatomy (options of :func:`draw_tree`, all off by default; the draw
with every option off is the plain tree): ``loop`` gives the main vessel a
full turn that crosses itself on the heart surface, its second pass lifted
off the surface so the lumen does not touch itself; ``branch_stenosis``
puts a branch origin on the lesion's shoulder; ``eccentric`` narrows the
lumen from one side, so the lumen centre (the truth centerline) leaves the
vessel axis. Vessels that are not branches (a vessel crossing the lesion,
:mod:`recon.synth.anatomy`) ride along in ``TreeDraw.extra``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recon.geometry import ViewGeometry, rotation_from_rotvec
from recon.lumen.bifurcation import carina_s_mm
from recon.types import arclength

__all__ = [
    "PhantomTruth",
    "TreeDraw",
    "draw_tree",
    "tree_fits",
    "truth_from_tree",
    "SAMPLE_STEP_MM",
    "TREE_EXTENT_MM",
]

FloatArray = NDArray[np.float64]

SAMPLE_STEP_MM = 0.1  # centerline sampling of the truth

MAIN_LENGTH_MM = (80.0, 140.0)
MAIN_RADIUS_PROXIMAL_MM = (1.8, 2.1)
MAIN_RADIUS_DISTAL_MM = (0.9, 1.1)
BRANCH_LENGTH_MM = (25.0, 50.0)
BRANCH_RADIUS_MM = (1.0, 1.3)
BRANCH_ANGLE_DEG = (30.0, 70.0)
STENOSIS_LENGTH_MM = (6.0, 12.0)
HEART_RADII_MM = (50.0, 42.0, 58.0)  # ellipsoid semi-axes (scaled by 0.85..1.1)
FIELD_MARGIN_PX = (20.0, 490.0)  # every projected tree point must fall inside (512 px views)
#: The same margins as fractions of the image width / height (any detector size).
FIELD_MARGIN_FRACTION = (20.0 / 512.0, 490.0 / 512.0)
TREE_EXTENT_MM = 60.0  # and every tree point within this of the isocenter (inf-norm)
MIN_PROJECTED_FRACTION = 0.5  # segment's projected / (true length x magnification), per view
LOOP_LENGTH_MM = (28.0, 40.0)  # arc length over which a loop turns by 360 degrees
LOOP_PROXIMAL_START = (0.16, 0.2)  # a proximal loop starts here (fraction of the main)
LOOP_DISTAL_END = (0.8, 0.84)  # a distal loop ends here
LOOP_LIFT_MM = 5.5  # second pass over the surface: > twice the largest main radius + 1 mm
LOOP_CLEARANCE_MM = 0.5  # least lumen-to-lumen gap between the loop's two passes
BRANCH_ON_SHOULDER = (0.3, 0.6)  # branch origin from the lesion centre, x lesion length
ECCENTRICITY = (0.7, 1.0)  # lumen-centre offset / (reference - lumen radius)
OSTIUM_START_MM = 0.5  # an ostial branch lesion starts this far beyond the main wall
OSTIUM_LENGTH_MM = 6.0


@dataclass(frozen=True, eq=False)
class PhantomTruth:
    """Ground truth of one phantom case (mm, world frame = view A's frame).

    Attributes
    ----------
    vessels : tuple of (centerline_world (M, 3), radius_mm (M,)); index 0 is
        the main vessel, proximal first; samples every 0.1 mm.
    vessel_names : name of each vessel.
    segment_X_world : (P, 3) the reconstruction segment (part of vessel 0
        between the seeds' proximal and distal ends), every 0.1 mm.
    segment_radius_mm : (P,) lumen radius.
    segment_s_mm : (P,) arc length from the segment's proximal end.
    segment_start_s_mm : arc length of the segment's start on vessel 0.
    stenosis_s_mm : stenosis centre, arc length along the segment.
    stenosis_length_mm : length of the (cosine) stenosis.
    stenosis_diameter_pct : diameter stenosis, 100 (1 - d_min / d_ref).
    mld_mm : minimal lumen diameter of the stenosis (within its length).
    reference_diameter_mm : undiseased diameter at the stenosis centre.
    features_world : (F, 3) named points in the order of
        ``Seeds.correspondences()``: segment proximal, segment distal, then
        the bifurcations.
    feature_names : (F,) their names.
    correction_rotvec, correction_t_mm : (3,) view B's true geometry is
        ``nominal.with_correction(correction_rotvec, correction_t_mm)``.
    segment_volume_mm3 : lumen volume of the segment, pi * integral r^2 ds.
    """

    vessels: tuple[tuple[FloatArray, FloatArray], ...]
    segment_X_world: FloatArray
    segment_radius_mm: FloatArray
    segment_s_mm: FloatArray
    stenosis_s_mm: float
    stenosis_length_mm: float
    stenosis_diameter_pct: float
    mld_mm: float
    reference_diameter_mm: float
    features_world: FloatArray
    feature_names: tuple[str, ...]
    correction_rotvec: FloatArray
    correction_t_mm: FloatArray
    segment_volume_mm3: float
    segment_start_s_mm: float = 0.0
    vessel_names: tuple[str, ...] = ()

    @property
    def segment_length_mm(self) -> float:
        return float(self.segment_s_mm[-1])

    def segment_px(self, view: ViewGeometry) -> FloatArray:
        """True projected segment centerline (P, 2) (col, row) in ``view``."""
        return view.project(self.segment_X_world)

    def segment_radius_px(self, view: ViewGeometry) -> FloatArray:
        """True projected lumen radius (P,) in px: r SID / depth / spacing."""
        depth = view.depth_mm(self.segment_X_world)
        spacing = float(np.mean(view.pixel_spacing_mm))
        return self.segment_radius_mm * view.sid_mm / depth / spacing

    def to_dict(self) -> dict:
        """JSON-ready part of truth.json about the tree (schema: :mod:`recon.io.phantom_case`)."""
        names = self.vessel_names or tuple(f"vessel {k}" for k in range(len(self.vessels)))
        return {
            "correction_rotvec": [float(x) for x in self.correction_rotvec],
            "correction_t_mm": [float(x) for x in self.correction_t_mm],
            "vessels": [
                {"name": n, "X_world": _rounded(X), "radius_mm": _rounded(r)}
                for n, (X, r) in zip(names, self.vessels, strict=True)
            ],
            "segment": {
                "name": "main",
                "X_world": _rounded(self.segment_X_world),
                "radius_mm": _rounded(self.segment_radius_mm),
                "s_mm": _rounded(self.segment_s_mm),
                "start_s_mm": float(self.segment_start_s_mm),
                "volume_mm3": float(self.segment_volume_mm3),
            },
            "stenosis": {
                "s_mm": float(self.stenosis_s_mm),
                "length_mm": float(self.stenosis_length_mm),
                "diameter_pct": float(self.stenosis_diameter_pct),
                "mld_mm": float(self.mld_mm),
                "reference_diameter_mm": float(self.reference_diameter_mm),
            },
            "features": [
                {"name": n, "X_world": [float(x) for x in X]}
                for n, X in zip(self.feature_names, self.features_world, strict=True)
            ],
        }



def _rounded(arr: ArrayLike, decimals: int = 5) -> list:
    return np.round(np.asarray(arr, dtype=float), decimals).tolist()



@dataclass(frozen=True)
class _Heart:
    centre: FloatArray  # (3,)
    Q: FloatArray  # (3, 3) rotation of the ellipsoid axes
    radii: FloatArray  # (3,) semi-axes

    def to_unit(self, X: FloatArray) -> FloatArray:
        return ((X - self.centre) @ self.Q) / self.radii

    def from_unit(self, y: FloatArray) -> FloatArray:
        return (y * self.radii) @ self.Q.T + self.centre

    def normal(self, X: FloatArray) -> FloatArray:
        n = self.Q @ (((X - self.centre) @ self.Q) / self.radii**2)
        return n / np.linalg.norm(n)


def _resample_uniform(X: FloatArray, step: float, length: float | None = None) -> FloatArray:
    """Resample a dense polyline (N, 3) at uniform arc length ``step`` up to ``length``."""
    s = arclength(X)
    total = s[-1] if length is None else min(length, s[-1])
    s_new = np.arange(0.0, total + 1e-9, step)
    return np.column_stack([np.interp(s_new, s, X[:, k]) for k in range(3)])


def _surface_curve(
    rng: np.random.Generator, heart: _Heart, y0: FloatArray, w0: FloatArray, length: float
) -> FloatArray:
    """A wiggly curve (M, 3) on the heart surface, 0.1 mm steps, ``length`` mm long.

    A planar curve with smoothly varying heading is wrapped onto the unit
    sphere by the azimuthal equidistant map at ``y0`` (initial direction
    ``w0``, tangent) and scaled to the ellipsoid.
    """
    return _surface_curve_core(rng, heart, y0, w0, length, None)[0]


def _surface_curve_core(
    rng: np.random.Generator, heart: _Heart, y0: FloatArray, w0: FloatArray, length: float,
    loop: tuple[float, float, float] | None,
) -> tuple[FloatArray, tuple[float, float] | None]:
    """:func:`_surface_curve`, optionally with a loop; also the loop's arc-length range.

    ``loop`` = (start mm, length mm, sign): the planar heading gains
    sign 2 pi smoothstep((s - start) / length), a full turn whose entry and
    exit legs cross (the turn is slow at its ends, fast in the middle). The
    map onto the sphere is one-to-one, so the curve crosses itself on the
    surface too; the second pass is lifted :data:`LOOP_LIFT_MM` along the
    surface normal (a cos^2 bump) so that it runs over the first. The range
    is None when the planar loop has no crossing.
    """
    r0 = float(np.mean(heart.radii))
    n = int(np.ceil(1.6 * length / SAMPLE_STEP_MM))
    s = np.arange(n) * SAMPLE_STEP_MM
    n_waves = 3
    lam = rng.uniform(18.0, 60.0, n_waves)
    amp = rng.uniform(0.04, 0.22, n_waves)
    phase = rng.uniform(0.0, 2 * np.pi, n_waves)
    heading = rng.uniform(-1.0, 1.0) / 150.0 * s  # slow overall turn
    waves = amp * (np.sin(2 * np.pi * s[:, None] / lam + phase) - np.sin(phase))
    heading = heading + waves.sum(axis=1)
    if loop is not None:
        x = np.clip((s - loop[0]) / loop[1], 0.0, 1.0)
        heading = heading + loop[2] * 2 * np.pi * x * x * (3.0 - 2.0 * x)
    q = np.cumsum(np.column_stack([np.cos(heading), np.sin(heading)]), axis=0) * SAMPLE_STEP_MM
    q = np.vstack([[0.0, 0.0], q[:-1]])
    rho = np.linalg.norm(q, axis=1)
    ang = rho / r0
    with np.errstate(invalid="ignore", divide="ignore"):
        dirs2 = np.where(rho[:, None] > 0, q / rho[:, None], np.array([1.0, 0.0]))
    e1 = w0 / np.linalg.norm(w0)
    e2 = np.cross(y0, e1)
    dirs3 = dirs2[:, :1] * e1 + dirs2[:, 1:] * e2
    y = np.cos(ang)[:, None] * y0 + np.sin(ang)[:, None] * dirs3
    X = heart.from_unit(y)
    loop_s = None
    if loop is not None:
        crossing = _planar_crossing(q, s, loop[0], loop[1])
        if crossing is None or np.max(ang) >= np.pi:
            return _resample_uniform(X, SAMPLE_STEP_MM, length), None
        i, j = crossing
        half = 0.8 * (s[j] - s[i])
        u = np.clip((s - s[j]) / half, -1.0, 1.0)
        lift = LOOP_LIFT_MM * np.cos(0.5 * np.pi * u) ** 2
        X = X + lift[:, None] * _surface_normals(heart, X)
        s3 = arclength(X)
        k0, k1 = np.searchsorted(s, [loop[0], loop[0] + loop[1]])
        loop_s = (float(s3[min(k0, n - 1)]), float(s3[min(k1, n - 1)]))
    return _resample_uniform(X, SAMPLE_STEP_MM, length), loop_s


def _surface_normals(heart: _Heart, X: FloatArray) -> FloatArray:
    """Outward unit normals (N, 3) of the heart ellipsoid at points X (N, 3)."""
    n = (((X - heart.centre) @ heart.Q) / heart.radii**2) @ heart.Q.T
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _planar_crossing(
    q: FloatArray, s: FloatArray, start: float, length: float
) -> tuple[int, int] | None:
    """Sample indices (i < j) where the planar curve q (N, 2) crosses itself in the loop.

    The pair closest together among samples of the loop window at least 5 mm
    of arc apart, accepted when it is closer than one sample step.
    """
    idx = np.flatnonzero((s >= start - 2.0) & (s <= start + length + 2.0))
    if len(idx) < 3:
        return None
    d = np.linalg.norm(q[idx, None, :] - q[None, idx, :], axis=2)
    far = np.abs(s[idx, None] - s[None, idx]) >= 5.0
    d = np.where(far & (idx[:, None] < idx[None, :]), d, np.inf)
    a, b = np.unravel_index(int(np.argmin(d)), d.shape)
    if not d[a, b] < SAMPLE_STEP_MM:
        return None
    return int(idx[a]), int(idx[b])


def _loop_clear(X: FloatArray, loop_s: tuple[float, float]) -> bool:
    """Whether the loop's two passes keep :data:`LOOP_CLEARANCE_MM` between their lumens.

    Lumens are bounded by the largest main radius r; samples less than
    6 mm + 2 r of arc apart are neighbours along the vessel, not the other pass.
    """
    s = np.arange(len(X)) * SAMPLE_STEP_MM
    idx = np.flatnonzero((s >= loop_s[0] - 3.0) & (s <= loop_s[1] + 3.0))[::2]
    if len(idx) < 2:
        return False
    d = np.linalg.norm(X[idx, None, :] - X[None, idx, :], axis=2)
    apart = np.abs(s[idx, None] - s[None, idx]) > 6.0 + 2 * MAIN_RADIUS_PROXIMAL_MM[1]
    gap = 2 * MAIN_RADIUS_PROXIMAL_MM[1] + LOOP_CLEARANCE_MM
    return bool(np.all(d[apart] >= gap))


def _random_tangent(rng: np.random.Generator, y0: FloatArray) -> FloatArray:
    w = rng.normal(size=3)
    w -= (w @ y0) * y0
    return w / np.linalg.norm(w)


@dataclass(frozen=True)
class TreeDraw:
    """One random tree: the heart, the vessels' centerlines, and where segment and stenosis lie."""

    heart: _Heart
    main_X: FloatArray
    branches_X: tuple[FloatArray, ...]
    branch_s: FloatArray  # (B,) origin arc length on the main vessel
    seg_start: int  # sample indices of the segment on the main vessel
    seg_end: int
    sten_s_main: float  # stenosis centre, arc length on the main vessel
    sten_len: float
    r_main: tuple[float, float]
    r_branch: tuple[tuple[float, float], ...]
    #: (centerline (M, 3) mm, radius (M,) mm, name) of vessels that are not branches.
    extra: tuple[tuple[FloatArray, FloatArray, str], ...] = ()
    #: (fraction, angle rad) of an eccentric stenosis, or None (concentric).
    eccentric: tuple[float, float] | None = None
    #: (start, end) arc length (mm) of the main vessel's loop, or None.
    loop_s: tuple[float, float] | None = None


def draw_tree(
    rng: np.random.Generator,
    *,
    loop: bool = False,
    branch_stenosis: bool = False,
    eccentric: bool = False,
) -> TreeDraw | None:
    """One random tree; None when the draw does not satisfy the constraints.

    ``loop``, ``branch_stenosis`` and ``eccentric`` are the harder anatomy
    of the module docstring; with all three off the draw (and the random
    numbers it takes) is the plain tree's.
    """
    radii = np.asarray(HEART_RADII_MM) * rng.uniform(0.85, 1.1)
    heart = _Heart(
        centre=rng.uniform(-8.0, 8.0, 3),
        Q=rotation_from_rotvec(rng.normal(0.0, 0.5, 3)),
        radii=radii,
    )
    length = rng.uniform(*MAIN_LENGTH_MM)
    y0 = rng.normal(size=3)
    y0 /= np.linalg.norm(y0)
    loop_s = None
    if loop:
        loop_len = rng.uniform(*LOOP_LENGTH_MM)
        if rng.uniform() < 0.5:
            loop_start = rng.uniform(*LOOP_PROXIMAL_START) * length
        else:
            loop_start = rng.uniform(*LOOP_DISTAL_END) * length - loop_len
        loop_spec = (loop_start, loop_len, float(rng.choice([-1.0, 1.0])))
        main_X, loop_s = _surface_curve_core(rng, heart, y0, _random_tangent(rng, y0), length,
                                             loop_spec)
        if loop_s is None or not _loop_clear(main_X, loop_s):
            return None
    else:
        main_X = _surface_curve(rng, heart, y0, _random_tangent(rng, y0), length)
    if arclength(main_X)[-1] < 0.98 * length:
        return None
    n = len(main_X)
    seg_start = int(rng.uniform(0.08, 0.15) * (n - 1))
    seg_end = int(rng.uniform(0.85, 0.92) * (n - 1))
    s_main = np.arange(n) * SAMPLE_STEP_MM
    # Side branches: 1-3 origins spread along the main vessel (one per stretch).
    n_branch = int(rng.integers(1, 4))
    stretch = 0.7 / n_branch
    branch_s = 0.15 + stretch * (np.arange(n_branch) + rng.uniform(0.15, 0.85, n_branch))
    branch_s = branch_s * s_main[-1]
    # Stenosis centre inside the segment, clear of the bifurcations.
    sten_len = rng.uniform(*STENOSIS_LENGTH_MM)
    seg_s0, seg_s1 = s_main[seg_start], s_main[seg_end]
    sten_s = seg_s0 + rng.uniform(0.3, 0.7) * (seg_s1 - seg_s0)
    if loop_s is not None:  # the lesion goes anywhere in 20-80 % of the segment clear of the loop
        cand = seg_s0 + np.linspace(0.2, 0.8, 121) * (seg_s1 - seg_s0)
        clear = (cand + sten_len / 2 + 3.0 <= loop_s[0]) | (cand - sten_len / 2 - 3.0 >= loop_s[1])
        if not np.any(clear):
            return None
        sten_s = float(cand[clear][int(rng.integers(int(np.sum(clear))))])
    if branch_stenosis:  # the nearest branch moves onto the lesion's shoulder
        k = int(np.argmin(np.abs(branch_s - sten_s)))
        side = float(rng.choice([-1.0, 1.0]))
        branch_s = branch_s.copy()
        branch_s[k] = sten_s + side * sten_len * rng.uniform(*BRANCH_ON_SHOULDER)
        others = np.delete(branch_s, k)
        if len(others) and np.min(np.abs(others - sten_s)) < sten_len / 2 + 3.0:
            return None
    elif np.min(np.abs(branch_s - sten_s)) < sten_len / 2 + 3.0:
        return None
    if loop_s is not None and (
        (sten_s + sten_len / 2 + 3.0 > loop_s[0] and sten_s - sten_len / 2 - 3.0 < loop_s[1])
        or loop_s[0] < seg_s0 + 2.0 or loop_s[1] > seg_s1 - 2.0
    ):
        return None  # the loop lies inside the segment, clear of the lesion
    branches = []
    r_branch = []
    tangents = np.gradient(main_X, axis=0)
    for sb in branch_s:
        i = int(round(sb / SAMPLE_STEP_MM))
        Xb = main_X[i]
        t = tangents[i] / np.linalg.norm(tangents[i])
        nrm = heart.normal(Xb)
        theta = np.deg2rad(rng.uniform(*BRANCH_ANGLE_DEG)) * rng.choice([-1.0, 1.0])
        bw = rotation_from_rotvec(nrm * theta) @ t  # world direction, tangent to the surface
        yb = heart.to_unit(Xb[None])[0]
        yb /= np.linalg.norm(yb)
        w = (bw @ heart.Q) / heart.radii  # tangent vector in the unit-sphere frame
        w -= (w @ yb) * yb
        branches.append(_surface_curve(rng, heart, yb, w, rng.uniform(*BRANCH_LENGTH_MM)))
        rb0 = rng.uniform(*BRANCH_RADIUS_MM)
        r_branch.append((rb0, rb0 * rng.uniform(0.55, 0.7)))
    r_main = (rng.uniform(*MAIN_RADIUS_PROXIMAL_MM), rng.uniform(*MAIN_RADIUS_DISTAL_MM))
    ecc = (rng.uniform(*ECCENTRICITY), rng.uniform(0.0, 2 * np.pi)) if eccentric else None
    return TreeDraw(
        heart=heart,
        main_X=main_X,
        branches_X=tuple(branches),
        branch_s=branch_s,
        seg_start=seg_start,
        seg_end=seg_end,
        sten_s_main=float(sten_s),
        sten_len=float(sten_len),
        r_main=r_main,
        r_branch=tuple(r_branch),
        eccentric=ecc,
        loop_s=loop_s,
    )


def tree_fits(tree: TreeDraw, views: Sequence[ViewGeometry]) -> bool:
    """Whether the whole tree projects inside every view and the segment is not foreshortened."""
    X = np.vstack([tree.main_X, *tree.branches_X, *(e[0] for e in tree.extra)])
    if np.max(np.abs(X)) > TREE_EXTENT_MM:
        return False
    seg_X = tree.main_X[tree.seg_start : tree.seg_end + 1]
    seg_len = (len(seg_X) - 1) * SAMPLE_STEP_MM
    for view in views:
        size = np.array([view.cols, view.rows], dtype=float)
        lo, hi = FIELD_MARGIN_FRACTION[0] * size, FIELD_MARGIN_FRACTION[1] * size
        p = view.project(X)
        if np.any(p < lo) or np.any(p > hi):
            return False
        # Views are chosen to show the segment without strong foreshortening.
        mag_px = view.sid_mm / view.depth_mm(seg_X).mean() / min(view.pixel_spacing_mm)
        projected = np.sum(np.linalg.norm(np.diff(view.project(seg_X), axis=0), axis=1))
        if projected < MIN_PROJECTED_FRACTION * seg_len * mag_px:
            return False
    return True


def _main_radius(tree: TreeDraw, s_mm: FloatArray, stenosis_pct: float) -> FloatArray:
    """Main-vessel radius (M,) at arc lengths ``s_mm``: linear taper times a cosine stenosis."""
    r0, r1 = tree.r_main
    length = len(tree.main_X) - 1
    r_ref = r0 + (r1 - r0) * s_mm / (length * SAMPLE_STEP_MM)
    x = (s_mm - tree.sten_s_main) / tree.sten_len
    bump = np.where(np.abs(x) < 0.5, 0.5 * (1.0 + np.cos(2 * np.pi * x)), 0.0)
    return r_ref * (1.0 - stenosis_pct / 100.0 * bump)


def _eccentric_centre(tree: TreeDraw, s_mm: FloatArray, r_mm: FloatArray) -> FloatArray:
    """The lumen centre (M, 3) of an eccentric stenosis: the axis moved towards one wall.

    The wall on the side ``angle`` (about the axis, from the heart's outward
    normal) stays where the undiseased lumen had it when ``fraction`` is 1:
    the centre moves by ``fraction (r_ref - r)`` away from that side, so the
    lumen (radius r) narrows from the opposite side only.
    """
    fraction, angle = tree.eccentric
    r0, r1 = tree.r_main
    r_ref = r0 + (r1 - r0) * s_mm / ((len(tree.main_X) - 1) * SAMPLE_STEP_MM)
    offset = fraction * (r_ref - r_mm)
    X = tree.main_X
    t = np.gradient(X, axis=0)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    n1 = _surface_normals(tree.heart, X)
    n1 = n1 - np.sum(n1 * t, axis=1, keepdims=True) * t
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    n2 = np.cross(t, n1)
    side = np.cos(angle) * n1 + np.sin(angle) * n2
    return X - offset[:, None] * side


def _main_reference_radius(tree: TreeDraw, s_mm: float) -> float:
    r0, r1 = tree.r_main
    return float(r0 + (r1 - r0) * s_mm / ((len(tree.main_X) - 1) * SAMPLE_STEP_MM))



def _ostium_bump(tree: TreeDraw, s_b: FloatArray, k: int, main_X: FloatArray,
                 main_r: FloatArray) -> FloatArray:
    """(N,) raised-cosine profile (peak 1) of an ostial lesion on branch k at arc lengths s_b.

    It starts :data:`OSTIUM_START_MM` beyond the branch's carina (where its
    centerline leaves the main lumen: main_X (M, 3), main_r (M,)), so it
    lies outside the main lumen, and is :data:`OSTIUM_LENGTH_MM` long.
    """
    s_c = carina_s_mm(tree.branches_X[k], main_X, main_r)
    centre = s_c + OSTIUM_START_MM + OSTIUM_LENGTH_MM / 2
    x = (s_b - centre) / OSTIUM_LENGTH_MM
    return np.where(np.abs(x) < 0.5, 0.5 * (1.0 + np.cos(2 * np.pi * x)), 0.0)


def truth_from_tree(
    tree: TreeDraw, stenosis_pct: float, rotvec: FloatArray, t_mm: FloatArray,
    side_stenosis_pct: float = 0.0,
) -> tuple[PhantomTruth, list[str]]:
    """The ground truth of a tree with a ``stenosis_pct`` stenosis, and the bifurcations' names.

    ``rotvec`` and ``t_mm`` are view B's header error (stored in the truth).
    ``side_stenosis_pct`` narrows the ostium of the branch nearest the main
    lesion by that diameter percentage (:func:`_ostium_bump`); 0 leaves the
    branches healthy.
    """
    k_ostium = int(np.argmin(np.abs(np.asarray(tree.branch_s) - tree.sten_s_main)))
    s_main = np.arange(len(tree.main_X)) * SAMPLE_STEP_MM
    r_main = _main_radius(tree, s_main, stenosis_pct)
    main_X = tree.main_X
    if tree.eccentric is not None:
        main_X = _eccentric_centre(tree, s_main, r_main)
    vessels = [(main_X, r_main)]
    names = ["main"]
    branch_names = []
    for k, (Xb, (rb0, rb1)) in enumerate(zip(tree.branches_X, tree.r_branch, strict=True)):
        sb = np.arange(len(Xb)) * SAMPLE_STEP_MM
        rb = rb0 + (rb1 - rb0) * sb / sb[-1]
        if k == k_ostium and side_stenosis_pct > 0:
            bump = _ostium_bump(tree, sb, k, main_X, r_main)
            rb = rb * (1.0 - side_stenosis_pct / 100.0 * bump)
        vessels.append((Xb, rb))
        names.append(f"branch {k + 1}")
        branch_names.append(f"bifurcation {k + 1}")
    for Xe, re_, name in tree.extra:
        vessels.append((Xe, re_))
        names.append(name)
    i0, i1 = tree.seg_start, tree.seg_end
    seg_X = main_X[i0 : i1 + 1]
    seg_r = r_main[i0 : i1 + 1]
    in_lesion = np.abs(s_main[i0 : i1 + 1] - tree.sten_s_main) <= tree.sten_len / 2
    if tree.eccentric is None:
        seg_s = s_main[i0 : i1 + 1] - s_main[i0]
        sten_s = tree.sten_s_main - s_main[i0]
    else:  # the lumen centre's own arc length (it leaves the axis at the lesion)
        seg_s = arclength(seg_X)
        sten_s = float(np.interp(tree.sten_s_main - s_main[i0], s_main[i0 : i1 + 1] - s_main[i0],
                                 seg_s))
    volume = float(np.pi * np.trapezoid(seg_r**2, seg_s))
    branch_origins = np.array([Xb[0] for Xb in tree.branches_X]).reshape(-1, 3)
    features = np.vstack([seg_X[0], seg_X[-1], branch_origins])
    truth = PhantomTruth(
        vessels=tuple(vessels),
        segment_X_world=seg_X,
        segment_radius_mm=seg_r,
        segment_s_mm=seg_s,
        stenosis_s_mm=float(sten_s),
        stenosis_length_mm=tree.sten_len,
        stenosis_diameter_pct=float(stenosis_pct),
        mld_mm=float(2.0 * seg_r[in_lesion].min()),
        reference_diameter_mm=2.0 * _main_reference_radius(tree, tree.sten_s_main),
        features_world=features,
        feature_names=("main proximal", "main distal", *branch_names),
        correction_rotvec=np.asarray(rotvec, dtype=float),
        correction_t_mm=np.asarray(t_mm, dtype=float),
        segment_volume_mm3=volume,
        segment_start_s_mm=float(s_main[i0]),
        vessel_names=tuple(names),
    )
    return truth, branch_names



# ------------------------------------------------------------ tree seeds
#: Bifurcation lesions of the tree suite: the main lesion on a bifurcation's
#: shoulder (the carina / distal or proximal main), an ostial side-branch
#: lesion, or both at one bifurcation.
