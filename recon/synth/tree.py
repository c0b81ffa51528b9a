"""The phantom's coronary tree: geometry, radii, stenosis and its ground truth.

A random main vessel and 1-3 side branches are drawn as wiggly curves on a
heart-sized ellipsoid (every 0.1 mm), kept only when the whole tree fits
both fields of view and the reconstruction segment is not strongly
foreshortened; the main vessel tapers linearly and carries a cosine stenosis
of a given diameter percentage. :func:`truth_from_tree` turns a draw into
the :class:`PhantomTruth` a benchmark measures against (mm, world frame =
view A's frame).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recon.geometry import ViewGeometry, rotation_from_rotvec
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
FIELD_MARGIN_PX = (20.0, 490.0)  # every projected tree point must fall inside
TREE_EXTENT_MM = 60.0  # and every tree point within this of the isocenter (inf-norm)
MIN_PROJECTED_FRACTION = 0.5  # segment's projected / (true length x magnification), per view


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
    return _resample_uniform(heart.from_unit(y), SAMPLE_STEP_MM, length)


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


def draw_tree(rng: np.random.Generator) -> TreeDraw | None:
    """One random tree; None when the draw does not satisfy the constraints."""
    radii = np.asarray(HEART_RADII_MM) * rng.uniform(0.85, 1.1)
    heart = _Heart(
        centre=rng.uniform(-8.0, 8.0, 3),
        Q=rotation_from_rotvec(rng.normal(0.0, 0.5, 3)),
        radii=radii,
    )
    length = rng.uniform(*MAIN_LENGTH_MM)
    y0 = rng.normal(size=3)
    y0 /= np.linalg.norm(y0)
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
    if np.min(np.abs(branch_s - sten_s)) < sten_len / 2 + 3.0:
        return None
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
    return TreeDraw(
        heart=heart,
        main_X=main_X,
        branches_X=tuple(branches),
        branch_s=branch_s,
        seg_start=seg_start,
        seg_end=seg_end,
        sten_s_main=float(sten_s),
        sten_len=float(sten_len),
        r_main=(rng.uniform(*MAIN_RADIUS_PROXIMAL_MM), rng.uniform(*MAIN_RADIUS_DISTAL_MM)),
        r_branch=tuple(r_branch),
    )


def tree_fits(tree: TreeDraw, views: Sequence[ViewGeometry]) -> bool:
    """Whether the whole tree projects inside every view and the segment is not foreshortened."""
    X = np.vstack([tree.main_X, *tree.branches_X])
    if np.max(np.abs(X)) > TREE_EXTENT_MM:
        return False
    lo, hi = FIELD_MARGIN_PX
    seg_X = tree.main_X[tree.seg_start : tree.seg_end + 1]
    seg_len = (len(seg_X) - 1) * SAMPLE_STEP_MM
    for view in views:
        p = view.project(X)
        if p.min() < lo or p.max() > hi:
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


def _main_reference_radius(tree: TreeDraw, s_mm: float) -> float:
    r0, r1 = tree.r_main
    return float(r0 + (r1 - r0) * s_mm / ((len(tree.main_X) - 1) * SAMPLE_STEP_MM))



def truth_from_tree(
    tree: TreeDraw, stenosis_pct: float, rotvec: FloatArray, t_mm: FloatArray
) -> tuple[PhantomTruth, list[str]]:
    """The ground truth of a tree with a ``stenosis_pct`` stenosis, and the bifurcations' names.

    ``rotvec`` and ``t_mm`` are view B's header error (stored in the truth).
    """
    s_main = np.arange(len(tree.main_X)) * SAMPLE_STEP_MM
    r_main = _main_radius(tree, s_main, stenosis_pct)
    vessels = [(tree.main_X, r_main)]
    names = ["main"]
    branch_names = []
    for k, (Xb, (rb0, rb1)) in enumerate(zip(tree.branches_X, tree.r_branch, strict=True)):
        sb = np.arange(len(Xb)) * SAMPLE_STEP_MM
        vessels.append((Xb, rb0 + (rb1 - rb0) * sb / sb[-1]))
        names.append(f"branch {k + 1}")
        branch_names.append(f"bifurcation {k + 1}")
    i0, i1 = tree.seg_start, tree.seg_end
    seg_X = tree.main_X[i0 : i1 + 1]
    seg_r = r_main[i0 : i1 + 1]
    seg_s = s_main[i0 : i1 + 1] - s_main[i0]
    volume = float(np.pi * np.trapezoid(seg_r**2, seg_s))
    sten_s = tree.sten_s_main - s_main[i0]
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
        mld_mm=float(2.0 * seg_r[np.abs(seg_s - sten_s) <= tree.sten_len / 2].min()),
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

