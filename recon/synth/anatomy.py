"""Harder anatomy for the phantom and the guiding catheter: what one tree draw leaves out.

:class:`Anatomy` names a variant of the tree (:data:`ANATOMIES`):

- ``plain``: the plain tree of :func:`recon.synth.tree.draw_tree`;
- ``branch-stenosis``: a branch origin on the lesion's shoulder;
- ``crossing``: another contrast-filled vessel passes over (or under) the
  lesion so that, in one view, its projection crosses the lesion; in the
  other view it lies clear of the lesion (:func:`add_crossing`);
- ``loop``: the main vessel makes a full turn that crosses itself in
  projection (:func:`recon.synth.tree.draw_tree` with ``loop``);
- ``faint``: the contrast fades strongly towards the distal ends
  (:func:`faint_fade`);
- ``eccentric``: the lumen narrows from one side, so the lumen centre (the
  truth centerline) moves off the vessel axis.

The truth (segment, radii, stenosis) stays exact in every variant: the
variants change the geometry that is rendered and measured, not the way it
is measured.

:func:`guiding_catheter` draws the 3D guiding catheter that an imaging
chain with a ``catheter`` background renders: a contrast-filled tube of 6
or 7 F (1 F = 1/3 mm outer diameter) engaged in the ostium (the main
vessel's proximal end), bending up towards the aortic root and leaving the
field at the image edge.

:func:`pacing_lead` draws a pacing lead (or a guide wire) for a chain with
a ``lead`` background: a thin, dense, straight or gently curved line that
crosses the whole field and passes a few millimetres from the clicked
segment, as in the real clinical pairs of issue 45.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from recon.geometry import ViewGeometry
from recon.synth.tree import SAMPLE_STEP_MM, TreeDraw

__all__ = [
    "Anatomy",
    "ANATOMIES",
    "ANATOMY_CYCLE",
    "Catheter",
    "Lead",
    "add_crossing",
    "catheter_beside",
    "faint_fade",
    "guiding_catheter",
    "loop_crossing_views",
    "pacing_lead",
    "resolve_anatomy",
]

FloatArray = NDArray[np.float64]

CROSSING_DEPTH_MM = (12.0, 25.0)  # crossing vessel's distance from the lesion along the ray
CROSSING_LENGTH_MM = (45.0, 70.0)
CROSSING_RADIUS_MM = (1.0, 1.4)
CROSSING_ANGLE_DEG = (50.0, 90.0)  # angle to the main vessel in the crossing view
CROSSING_CLEAR_MM = 5.0  # least detector-plane distance from the lesion in the other view
FAINT_DISTAL_FRACTION = (0.12, 0.25)  # distal / proximal attenuation (plain tree: 0.7)
FAINT_POWER = 2.0  # the fade grows as (arc fraction)^2: strongest distally

#: French size -> (outer diameter, inner diameter) mm of a guiding catheter. Outer:
#: 1 F = 1/3 mm. Inner: contemporary guides are about 0.070 in (6 F) and 0.080 in
#: (7 F) in lumen (manufacturers' figures).
CATHETER_DIAMETERS_MM = {6: (2.0, 0.070 * 25.4), 7: (7.0 / 3.0, 0.080 * 25.4)}
CATHETER_BEND_MM = (20.0, 35.0)  # from the ostium's direction to the aortic direction
CATHETER_LENGTH_MM = 320.0  # long enough to leave any field of view

# Pacing lead / guide wire (pacing_lead). The figures are this benchmark's design
# choice after the real pairs (a thin line much darker than a filled vessel), not
# measured values: the lead's conductor coil or a wire, 0.3-0.6 mm wide.
LEAD_RADIUS_MM = (0.15, 0.30)
LEAD_PEAK = (0.5, 1.0)  # line integral through the lead's axis (a 3 mm vessel: about 0.3)
LEAD_OFFSET_MM = (2.0, 6.0)  # 3D distance from the segment where it passes nearest
LEAD_ANGLE_DEG = (10.0, 45.0)  # angle to the segment there
LEAD_CURVATURE_PER_MM = 1.0 / 400.0  # largest curvature: gently curved
LEAD_LENGTH_MM = 400.0  # crosses any field of view
LEAD_MIN_FIELD_FRACTION = 0.5  # its projection inside a view is at least half the image size


@dataclass(frozen=True)
class Anatomy:
    """A variant of the phantom's tree (see the module docstring)."""

    name: str
    loop: bool = False
    branch_stenosis: bool = False
    eccentric: bool = False
    crossing: bool = False
    faint: bool = False


ANATOMIES: dict[str, Anatomy] = {
    "plain": Anatomy("plain"),
    "branch-stenosis": Anatomy("branch-stenosis", branch_stenosis=True),
    "crossing": Anatomy("crossing", crossing=True),
    "loop": Anatomy("loop", loop=True),
    "faint": Anatomy("faint", faint=True),
    "eccentric": Anatomy("eccentric", eccentric=True),
}
#: The order a suite cycles through the variants.
ANATOMY_CYCLE = tuple(ANATOMIES)


def resolve_anatomy(anatomy: str | Anatomy | None) -> Anatomy | None:
    """The :class:`Anatomy` of a name (None stays None); ValueError for an unknown name."""
    if anatomy is None or isinstance(anatomy, Anatomy):
        return anatomy
    if anatomy not in ANATOMIES:
        raise ValueError(f"unknown anatomy {anatomy!r} (use one of {', '.join(ANATOMIES)})")
    return ANATOMIES[anatomy]


def faint_fade(rng: np.random.Generator) -> tuple[float, float]:
    """(distal fraction, power) of a strong contrast fade along the vessels."""
    return float(rng.uniform(*FAINT_DISTAL_FRACTION)), FAINT_POWER


def add_crossing(
    tree: TreeDraw, rng: np.random.Generator, views: Sequence[ViewGeometry], view_index: int
) -> TreeDraw | None:
    """The tree with a vessel that crosses the lesion in ``views[view_index]`` only.

    The crossing vessel (a gently bent tube, 1.0-1.4 mm radius, tapering)
    passes through a point on the ray of that view through the lesion
    centre, 12-25 mm in front of or behind it, at 50-90 degrees to the main
    vessel in that view's image. None when, in the other view, it comes
    within :data:`CROSSING_CLEAR_MM` (detector plane) of the lesion centre.
    """
    view = views[view_index]
    other = views[1 - view_index]
    i = int(round(tree.sten_s_main / SAMPLE_STEP_MM))
    P = tree.main_X[i]
    d = P - view.source_world
    d /= np.linalg.norm(d)
    t = np.gradient(tree.main_X, axis=0)[i]
    t_img = t - (t @ d) * d
    t_img /= np.linalg.norm(t_img)
    n_img = np.cross(d, t_img)
    angle = np.deg2rad(rng.uniform(*CROSSING_ANGLE_DEG)) * rng.choice([-1.0, 1.0])
    w = np.cos(angle) * t_img + np.sin(angle) * n_img
    bend_dir = np.cross(d, w)
    Q = P + rng.uniform(*CROSSING_DEPTH_MM) * rng.choice([-1.0, 1.0]) * d
    length = rng.uniform(*CROSSING_LENGTH_MM)
    u = np.arange(-length / 2, length / 2 + 1e-9, SAMPLE_STEP_MM)
    bend = rng.uniform(-1.0, 1.0) * 0.004  # 1/mm: a radius of curvature of 250 mm and more
    X = Q + u[:, None] * w + (0.5 * bend * u**2)[:, None] * bend_dir
    r0 = rng.uniform(*CROSSING_RADIUS_MM)
    radius = r0 * (1.0 - 0.3 * (u - u[0]) / (u[-1] - u[0]))
    p = other.project(X)
    dist_px = np.min(np.linalg.norm(p - other.project(P[None])[0], axis=1))
    if dist_px * min(other.pixel_spacing_mm) < CROSSING_CLEAR_MM:
        return None
    return replace(tree, extra=(*tree.extra, (X, radius, "crossing")))


def loop_crossing_views(
    main_X: FloatArray, loop_s: tuple[float, float], views: Sequence[ViewGeometry]
) -> tuple[int, ...]:
    """Indices of the views in which the loop's projection crosses itself.

    The loop's stretch of the main vessel (``loop_s`` mm of arc, 2 mm more
    each side) is projected as a polyline of 0.5 mm steps; it crosses itself
    when two of its non-adjacent pieces intersect.
    """
    s = np.arange(len(main_X)) * SAMPLE_STEP_MM
    pick = np.flatnonzero((s >= loop_s[0] - 2.0) & (s <= loop_s[1] + 2.0))[::5]
    return tuple(k for k, view in enumerate(views)
                 if _self_intersects(view.project(main_X[pick])))


def _self_intersects(p: FloatArray) -> bool:
    """Whether the 2D polyline p (N, 2) crosses itself (pieces two or more apart)."""
    a, b = p[:-1], p[1:]
    d = b - a

    def cross(u: FloatArray, v: FloatArray) -> FloatArray:
        return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]

    # piece i against piece j: a_i + t d_i = a_j + u d_j
    rel = a[None, :, :] - a[:, None, :]
    den = cross(d[:, None, :], d[None, :, :])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = cross(rel, d[None, :, :]) / den
        u = cross(rel, d[:, None, :]) / den
    n = len(d)
    far = np.abs(np.arange(n)[:, None] - np.arange(n)[None, :]) >= 2
    hit = far & (np.abs(den) > 1e-12) & (t >= 0) & (t <= 1) & (u >= 0) & (u <= 1)
    return bool(np.any(hit))


@dataclass(frozen=True, eq=False)
class Catheter:
    """A guiding catheter (world mm): centerline from its tip in the ostium outwards.

    Attributes
    ----------
    X_world : (M, 3) centerline, tip first, every 0.1 mm.
    french : 6 or 7.
    outer_radius_mm, inner_radius_mm : the tube and its contrast-filled lumen.
    """

    X_world: FloatArray
    french: int
    outer_radius_mm: float
    inner_radius_mm: float


def guiding_catheter(
    rng: np.random.Generator, main_X: FloatArray, views: Sequence[ViewGeometry]
) -> Catheter:
    """A guiding catheter engaged in the ostium ``main_X[0]`` that leaves every view's field.

    The tip sits 0.5 mm outside the ostium, coaxial with the vessel; over
    20-35 mm the catheter turns (smoothly) to a direction within about 35
    degrees of the patient's head (+z, towards the aortic root and arch) and
    runs straight on. Directions whose far end projects inside a view are
    redrawn.
    """
    t0 = main_X[min(20, len(main_X) - 1)] - main_X[0]
    t0 /= np.linalg.norm(t0)
    french = int(rng.choice([6, 7]))
    outer, inner = CATHETER_DIAMETERS_MM[french]
    tip = main_X[0] - 0.5 * t0
    a = -t0
    X = _bent_line(tip, a, np.array([0.0, 0.0, 1.0]), CATHETER_BEND_MM[0], CATHETER_LENGTH_MM)
    for _ in range(50):
        b = np.array([0.0, 0.0, 1.0]) + rng.normal(0.0, 0.4, 3)
        b /= np.linalg.norm(b)
        if b[2] < 0.8:
            continue
        X = _bent_line(tip, a, b, rng.uniform(*CATHETER_BEND_MM), CATHETER_LENGTH_MM)
        if all(_leaves_field(view, X) for view in views):
            break
    return Catheter(X_world=X, french=french, outer_radius_mm=outer / 2,
                    inner_radius_mm=inner / 2)


#: catheter_beside: the shaft (past this arc from the tip, mm) passes the segment at a
#: centre-to-centre distance (mm in the detector plane) drawn in CATHETER_BESIDE_MM.
CATHETER_SHAFT_FROM_MM = 30.0
CATHETER_BESIDE_MM = (3.0, 8.0)
CATHETER_BESIDE_DRAWS = 40


def catheter_beside(
    rng: np.random.Generator, main_X: FloatArray, seg_X: FloatArray,
    views: Sequence[ViewGeometry], view_index: int,
) -> Catheter:
    """A guiding catheter as :func:`guiding_catheter` whose shaft runs beside the segment.

    Of :data:`CATHETER_BESIDE_DRAWS` aortic directions that leave every
    view's field, the one whose shaft (the catheter past
    :data:`CATHETER_SHAFT_FROM_MM` of arc) comes, in ``views[view_index]``,
    nearest to a distance drawn in :data:`CATHETER_BESIDE_MM` (detector
    plane, centre to centre) from the segment ``seg_X`` (P, 3); the
    plain catheter of the first draw when none leaves every field.
    """
    t0 = main_X[min(20, len(main_X) - 1)] - main_X[0]
    t0 /= np.linalg.norm(t0)
    french = int(rng.choice([6, 7]))
    outer, inner = CATHETER_DIAMETERS_MM[french]
    tip = main_X[0] - 0.5 * t0
    target_mm = rng.uniform(*CATHETER_BESIDE_MM)
    view = views[view_index]
    seg_px = view.project(seg_X[::4])
    shaft_from = int(CATHETER_SHAFT_FROM_MM / SAMPLE_STEP_MM)
    best, best_miss = None, np.inf
    for _ in range(CATHETER_BESIDE_DRAWS):
        b = np.array([0.0, 0.0, 1.0]) + rng.normal(0.0, 0.4, 3)
        b /= np.linalg.norm(b)
        X = _bent_line(tip, -t0, b, rng.uniform(*CATHETER_BEND_MM), CATHETER_LENGTH_MM)
        if b[2] < 0.8 or not all(_leaves_field(v, X) for v in views):
            continue
        shaft = view.project(X[shaft_from::4])
        gap_px = np.min(np.linalg.norm(shaft[:, None, :] - seg_px[None, :, :], axis=2))
        miss = abs(gap_px * min(view.pixel_spacing_mm) - target_mm)
        if miss < best_miss:
            best, best_miss = X, miss
    if best is None:
        best = _bent_line(tip, -t0, np.array([0.0, 0.0, 1.0]), CATHETER_BEND_MM[0],
                          CATHETER_LENGTH_MM)
    return Catheter(X_world=best, french=french, outer_radius_mm=outer / 2,
                    inner_radius_mm=inner / 2)


def _bent_line(
    start: FloatArray, a: FloatArray, b: FloatArray, bend_mm: float, length_mm: float
) -> FloatArray:
    """Polyline (M, 3) from ``start``, heading turning from unit ``a`` to unit ``b``.

    The heading is a spherical interpolation (through the mid direction when
    a and b are nearly opposite) with a smoothstep weight over ``bend_mm``.
    """
    s = np.arange(0.0, length_mm, SAMPLE_STEP_MM)
    x = np.clip(s / bend_mm, 0.0, 1.0)
    wgt = x * x * (3.0 - 2.0 * x)
    mid = a + b
    if np.linalg.norm(mid) < 0.3:  # nearly opposite: turn through a perpendicular
        perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        mid = perp
    mid = mid / np.linalg.norm(mid)
    first = wgt < 0.5
    dirs = np.where(first[:, None], _slerp(a, mid, 2 * wgt), _slerp(mid, b, 2 * wgt - 1))
    steps = dirs * SAMPLE_STEP_MM
    return start + np.vstack([[0.0, 0.0, 0.0], np.cumsum(steps[:-1], axis=0)])


def _slerp(a: FloatArray, b: FloatArray, w: FloatArray) -> FloatArray:
    """Unit vectors (N, 3) between unit a and b at weights w (N,) in [0, 1]."""
    w = np.clip(w, 0.0, 1.0)[:, None]
    omega = np.arccos(np.clip(a @ b, -1.0, 1.0))
    if omega < 1e-6:
        return np.broadcast_to(a, (len(w), 3)).copy()
    return (np.sin((1 - w) * omega) * a + np.sin(w * omega) * b) / np.sin(omega)


def _leaves_field(view: ViewGeometry, X: FloatArray) -> bool:
    """Whether the polyline's far end projects outside the image (in front of the source)."""
    if view.depth_mm(X[-1:])[0] <= 0:
        return False
    c, r = view.project(X[-1:])[0]
    return not (0 <= c <= view.cols - 1 and 0 <= r <= view.rows - 1)


@dataclass(frozen=True, eq=False)
class Lead:
    """A pacing lead or guide wire (world mm), a thin dense tube across the field.

    Attributes
    ----------
    X_world : (M, 3) centerline every 0.5 mm.
    radius_mm : the tube's radius (0.15-0.3 mm).
    mu_per_mm : its attenuation per mm (peak line integral / diameter).
    """

    X_world: FloatArray
    radius_mm: float
    mu_per_mm: float


def pacing_lead(
    rng: np.random.Generator, seg_X: FloatArray, views: Sequence[ViewGeometry],
    max_draws: int = 50,
) -> Lead:
    """A lead that passes 2-6 mm from the segment ``seg_X`` (P, 3) and crosses every view.

    At a point P of the segment (30-70 % of its arc) the lead runs at 10-45
    degrees to the segment, its nearest approach on their common
    perpendicular; it is 400 mm long, bent in a plane with a curvature of at
    most 1/400 per mm. A draw whose projection inside some view is shorter
    than half the image size is drawn again (the last draw is kept).
    """
    i_max = len(seg_X) - 1
    tangent = np.gradient(seg_X, axis=0)
    radius = float(rng.uniform(*LEAD_RADIUS_MM))
    mu = float(rng.uniform(*LEAD_PEAK)) / (2.0 * radius)
    u = np.arange(-LEAD_LENGTH_MM / 2, LEAD_LENGTH_MM / 2 + 1e-9, SAMPLE_STEP_MM)
    X = seg_X
    for _ in range(max_draws):
        i = int(round(rng.uniform(0.3, 0.7) * i_max))
        t = tangent[i] / np.linalg.norm(tangent[i])
        n = _unit_perpendicular(t, rng.normal(size=3))
        a = np.deg2rad(rng.uniform(*LEAD_ANGLE_DEG))
        w = np.cos(a) * t + np.sin(a) * n
        m = np.cross(t, w)
        m /= np.linalg.norm(m)
        Q = seg_X[i] + rng.uniform(*LEAD_OFFSET_MM) * rng.choice([-1.0, 1.0]) * m
        bend_dir = _unit_perpendicular(w, rng.normal(size=3))
        kappa = rng.uniform(-1.0, 1.0) * LEAD_CURVATURE_PER_MM
        X = Q + u[:, None] * w + (0.5 * kappa * u**2)[:, None] * bend_dir
        if all(_in_field_length_px(v, X) >= LEAD_MIN_FIELD_FRACTION * max(v.rows, v.cols)
               for v in views):
            break
    return Lead(X_world=X, radius_mm=radius, mu_per_mm=mu)


def _unit_perpendicular(t: FloatArray, v: FloatArray) -> FloatArray:
    """The unit vector along v's part perpendicular to unit t."""
    p = v - (v @ t) * t
    return p / np.linalg.norm(p)


def _in_field_length_px(view: ViewGeometry, X: FloatArray) -> float:
    """Projected length (px) of the polyline's pieces that lie inside the image."""
    p = view.project(X)
    inside = ((p[:, 0] >= 0) & (p[:, 0] <= view.cols - 1) & (p[:, 1] >= 0)
              & (p[:, 1] <= view.rows - 1) & (view.depth_mm(X) > 0))
    steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
    return float(steps[inside[1:] & inside[:-1]].sum())
