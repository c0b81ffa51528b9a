"""The phantom's errors of a real study: view B's header error and the clinician's clicks.

:func:`random_header_error` draws how far view B's header is off its true
geometry, as a rigid rig correction (``view_b_true =
view_b_nominal.with_correction(rotvec, t_mm)``). :func:`make_seeds` clicks
the segment's ends, 1-2 waypoints and the bifurcations on their TRUE
projections, with :data:`CLICK_NOISE_PX` of noise, stored to
:data:`CLICK_ROUND_PX`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from recon.geometry import ViewGeometry, rotation_from_rotvec, rotvec_from_rotation
from recon.seeds import Feature, Seeds, Segment
from recon.synth.presets import preset_view

__all__ = [
    "HEADER_ANGLE_ERROR_DEG",
    "HEADER_SOD_ERROR_MM",
    "HEADER_SHIFT_MM",
    "CLICK_NOISE_PX",
    "CLICK_ROUND_PX",
    "WAYPOINT_MIN_GAP_PX",
    "random_header_error",
    "click_px",
    "make_seeds",
]

FloatArray = NDArray[np.float64]

# Header error of view B (random_header_error): magnitudes in one place.
HEADER_ANGLE_ERROR_DEG = (1.0, 2.0)  # |primary| and |secondary| angle error range
HEADER_SOD_ERROR_MM = (5.0, 15.0)  # |rig translation along B's d| range (SOD error)
HEADER_SHIFT_MM = (2.0, 5.0)  # |isocenter / table shift| range, random direction

CLICK_NOISE_PX = 0.7  # sd of the clinician's click error per coordinate
CLICK_ROUND_PX = 0.1  # clicks are stored rounded to this
WAYPOINT_MIN_GAP_PX = 5.0  # no waypoint this close to a neighbouring click


def random_header_error(
    rng: np.random.Generator, view: ViewGeometry | None = None,
    shift_mm: tuple[float, float] = HEADER_SHIFT_MM,
    in_table_plane: bool = False,
) -> tuple[FloatArray, FloatArray]:
    """Draw a realistic error of view B's header as a rigid rig correction.

    The true geometry is ``nominal.with_correction(rotvec, t_mm)``. The
    rotation is a primary-angle error about the patient's long axis z then a
    secondary-angle error about the view's u axis, each of magnitude
    uniform in :data:`HEADER_ANGLE_ERROR_DEG` with a random sign; the
    translation is an SOD error along the view's d (magnitude uniform in
    :data:`HEADER_SOD_ERROR_MM`, random sign) plus a table/isocenter shift of magnitude
    uniform in ``shift_mm`` (default :data:`HEADER_SHIFT_MM`) in a random direction.

    Parameters
    ----------
    rng : random generator.
    view : the nominal view B (for its u and d axes); an AP view if None.
    shift_mm : range of the table / isocenter shift (a table move between the
        two runs: 10-15 mm in the clinical export chain); the same draws.
    in_table_plane : the shift lies in the table plane (world x and z: left-right
        and head-foot of a supine patient, DICOM LPS) as a table move does; the
        same draws, the direction's y part dropped.

    Returns
    -------
    rotvec : (3,) rotation vector in radians.
    t_mm : (3,) translation in mm.
    """
    axes = (view if view is not None else preset_view(0.0, 0.0, 1000.0, 750.0)).nominal_axes
    u, d = axes[0], axes[2]
    lo, hi = HEADER_ANGLE_ERROR_DEG
    d_alpha, d_beta = np.deg2rad(rng.uniform(lo, hi, 2) * rng.choice([-1.0, 1.0], 2))
    R = rotation_from_rotvec(u * d_beta) @ rotation_from_rotvec(np.array([0.0, 0.0, d_alpha]))
    direction = rng.normal(size=3)
    if in_table_plane:
        direction[1] = 0.0
    direction /= np.linalg.norm(direction)
    shift = direction * rng.uniform(*shift_mm)
    sod_error = rng.uniform(*HEADER_SOD_ERROR_MM) * rng.choice([-1.0, 1.0])
    t_mm = sod_error * d + shift
    return rotvec_from_rotation(R), t_mm


def click_px(rng: np.random.Generator, points_px: FloatArray) -> FloatArray:
    """Clicks (N, 2) on points (N, 2): CLICK_NOISE_PX noise, stored to CLICK_ROUND_PX."""
    noisy = points_px + rng.normal(0.0, CLICK_NOISE_PX, points_px.shape)
    return np.round(noisy / CLICK_ROUND_PX) * CLICK_ROUND_PX


def _click(rng: np.random.Generator, points_px: FloatArray) -> list[tuple[float, float]]:
    return [(round(float(c), 1), round(float(r), 1)) for c, r in click_px(rng, points_px)]


def make_seeds(
    rng: np.random.Generator,
    seg_X: FloatArray,
    branch_X: FloatArray,
    branch_names: Sequence[str],
    view_a: ViewGeometry,
    view_b: ViewGeometry,
) -> Seeds:
    """The clinician's clicks on the TRUE projections of the segment and the bifurcations.

    Per view: both ends of ``seg_X`` (P, 3) and 1-2 waypoints between 25 and
    75 % of it, less any waypoint within :data:`WAYPOINT_MIN_GAP_PX` of a
    neighbouring click; then one feature per row of ``branch_X`` (B, 3),
    named ``branch_names``. Every click goes through :func:`click_px`.
    """
    clicks = {}
    n = len(seg_X)
    for key, view in (("a", view_a), ("b", view_b)):
        n_way = int(rng.integers(1, 3))
        way = np.sort(rng.uniform(0.25, 0.75, n_way))
        idx = np.concatenate([[0], np.round(way * (n - 1)).astype(int), [n - 1]])
        pts = _click(rng, view.project(seg_X[idx]))
        # A clinician puts no waypoint where the vessel is foreshortened onto another
        # click (running along the ray): drop waypoints within WAYPOINT_MIN_GAP_PX.
        gaps = np.linalg.norm(np.subtract(pts[1:], pts[:-1]), axis=1)
        crowded = np.zeros(len(pts), dtype=bool)
        crowded[1:-1] = (gaps[:-1] < WAYPOINT_MIN_GAP_PX) | (gaps[1:] < WAYPOINT_MIN_GAP_PX)
        clicks[key] = tuple(p for p, c in zip(pts, crowded, strict=True) if not c)
    segment = Segment(name="main", a_px=clicks["a"], b_px=clicks["b"])
    features = []
    if len(branch_X):
        fa = _click(rng, view_a.project(branch_X))
        fb = _click(rng, view_b.project(branch_X))
        features = [
            Feature(name=name, a_px=a, b_px=b)
            for name, a, b in zip(branch_names, fa, fb, strict=True)
        ]
    return Seeds(segments=(segment,), features=tuple(features))

