"""Synthetic two-view coronary phantom with exact ground truth.

Every benchmark and the demo stand on this generator. One call,
:func:`make_phantom`, draws a random coronary tree on a heart-sized
ellipsoid, a stenosis of a given diameter percentage, a random error of view
B's header geometry, the clinician's clicks (seeds) and, optionally, the two
rendered X-ray images. The same ``(preset, seed)`` always gives the same case;
the stenosis percentage, ``render`` and ``n_frames`` do not change the tree,
the header error or the clicks.

Frames and conventions
----------------------
World = view A's frame (DICOM LPS, mm, isocenter origin; see
:mod:`recon.geometry`). View A's header is its true geometry. View B's
header (``view_b_nominal``) is off by a rigid rig correction:
``view_b_true = view_b_nominal.with_correction(truth.correction_rotvec,
truth.correction_t_mm)``; images and clicks are made with the TRUE
geometries, the DICOM header of b.dcm holds the NOMINAL one.

Ground truth a benchmark uses
-----------------------------
- true projected centerline of view k: ``view_k_true.project(segment_X_world)``
  (or :meth:`PhantomTruth.segment_px`);
- true projected radius in px: ``radius_mm * SID / depth / spacing`` with
  ``depth = view.depth_mm(X)`` along the central ray
  (:meth:`PhantomTruth.segment_radius_px`);
- calibration: the correction above; ``features_world`` rows are in the
  order of ``Seeds.correspondences()`` (segment ends, then bifurcations).

truth.json schema (version 1; all lengths mm, points in the world frame)
------------------------------------------------------------------------
::

    {"version": 1, "preset": str, "seed": int,
     "frame_index": int (0-based frame of a cine the truth holds for),
     "view_a": ViewGeometry dict (true = header),
     "view_b_nominal": ViewGeometry dict (the b.dcm header),
     "view_b_true": ViewGeometry dict (nominal with the correction applied),
     "correction_rotvec": [3] rad, "correction_t_mm": [3],
     "vessels": [{"name": str, "X_world": [[x, y, z], ...], "radius_mm": [...]}],
                                   (0 = main vessel, proximal first; 0.1 mm steps)
     "segment": {"name": "main", "X_world": [[...]], "radius_mm": [...], "s_mm": [...],
                 "start_s_mm": float (position of the segment on vessel 0),
                 "volume_mm3": float},
     "stenosis": {"s_mm": float (centre, along the segment), "length_mm": float,
                  "diameter_pct": float, "mld_mm": float, "reference_diameter_mm": float},
     "features": [{"name": str, "X_world": [x, y, z]}]}

Image model
-----------
Beer-Lambert: counts = N0 * background(x, y) * exp(-sum mu L), where L is
the iodine path length through the lumen computed exactly for a chain of
truncated cones (union of the per-cone ray intervals, so consecutive cones
are not double counted and true crossings add up), supersampled per pixel;
a smooth random anatomical background, a diaphragm edge, a collimator
border, Poisson quantum noise, detector blur, 12-bit output (MONOCHROME2:
vessels dark).
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from recon.errors import CoronaryError
from recon.fileio import atomic_write_bytes
from recon.geometry import ViewGeometry, rotation_from_rotvec, rotvec_from_rotation
from recon.seeds import Feature, Seeds, Segment, save_seeds
from recon.types import arclength

__all__ = [
    "PhantomPreset",
    "PhantomTruth",
    "PhantomCase",
    "PhantomError",
    "PRESETS",
    "make_phantom",
    "random_header_error",
    "write_phantom_case",
    "load_truth",
    "path_length_image",
    "HEADER_ANGLE_ERROR_DEG",
    "HEADER_SOD_ERROR_MM",
    "HEADER_SHIFT_MM",
    "CLICK_NOISE_PX",
    "click_px",
]

FloatArray = NDArray[np.float64]

# ------------------------------------------------------------- constants
IMAGE_SIZE_PX = 512
PIXEL_SPACING_MM = 0.390625  # 200 mm field on 512 px, as the real files
SAMPLE_STEP_MM = 0.1  # centerline sampling of the truth

# Header error of view B (random_header_error): magnitudes in one place.
HEADER_ANGLE_ERROR_DEG = (1.0, 2.0)  # |primary| and |secondary| angle error range
HEADER_SOD_ERROR_MM = (5.0, 15.0)  # |rig translation along B's d| range (SOD error)
HEADER_SHIFT_MM = (2.0, 5.0)  # |isocenter / table shift| range, random direction

CLICK_NOISE_PX = 0.7  # sd of the clinician's click error per coordinate
CLICK_ROUND_PX = 0.1  # clicks are stored rounded to this
WAYPOINT_MIN_GAP_PX = 5.0  # no waypoint this close to a neighbouring click

# Tree.
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

# Rendering.
SUPERSAMPLE = 2  # rays per pixel along each axis
CONE_MAX_LENGTH_MM = 0.4  # truncated-cone chain: longest cone
CONE_MAX_DR_MM = 0.02  # largest radius change within one cone
CONE_MAX_TURN_RAD = 0.01  # largest bend between consecutive cones
MU_PROXIMAL_PER_MM = (0.085, 0.11)  # iodine attenuation; 3 mm vessel darkens ~25 %
MU_DISTAL_FRACTION = 0.7  # contrast fades ~30 % from proximal to distal
PHOTONS_PER_PIXEL = 2500.0  # unattenuated counts (Poisson)
DETECTOR_BLUR_PX = 0.7
BACKGROUND_LEVEL = 2600.0  # 12-bit value of unattenuated background
MAX_VALUE = 4095


class PhantomError(CoronaryError):
    """A phantom request that cannot be served (bad preset, unreadable truth file)."""


# ------------------------------------------------------------- presets
def _view(alpha: float, beta: float, sid: float, sod: float) -> ViewGeometry:
    return ViewGeometry(
        alpha_deg=alpha,
        beta_deg=beta,
        sid_mm=sid,
        sod_mm=sod,
        pixel_spacing_mm=(PIXEL_SPACING_MM, PIXEL_SPACING_MM),
        rows=IMAGE_SIZE_PX,
        cols=IMAGE_SIZE_PX,
    )


@dataclass(frozen=True)
class PhantomPreset:
    """A pair of nominal header geometries.

    Attributes
    ----------
    name : preset key.
    view_a, view_b : nominal (header) geometries of the two views.
    description : where the numbers come from.
    """

    name: str
    view_a: ViewGeometry
    view_b: ViewGeometry
    description: str


PRESETS: dict[str, PhantomPreset] = {
    "data1": PhantomPreset(
        "data1",
        _view(45.5, -28.2, 1200.0, 749.0),
        _view(-24.8, -27.0, 1147.0, 844.0),
        "seed paper Table 1, data 1 (LAO 45.5 CAU 28.2 / RAO 24.8 CAU 27)",
    ),
    "data2": PhantomPreset(
        "data2",
        _view(45.2, 0.0, 1028.0, 759.4),
        _view(0.9, 33.0, 1064.0, 766.4),
        "seed paper Table 1, data 2 (LAO 45.2 / LAO 0.9 CRA 33)",
    ),
    "data3": PhantomPreset(
        "data3",
        _view(-21.6, -21.0, 1075.0, 782.7),
        _view(44.3, -28.8, 1118.0, 785.0),
        "seed paper Table 1, data 3 (RAO 21.6 CAU 21 / LAO 44.3 CAU 28.8)",
    ),
    "static": PhantomPreset(
        "static",
        _view(-29.3, 25.5, 976.0, 720.0),
        _view(30.7, 23.6, 976.0, 720.0),
        "like the real static phantom pair IM7/IM8 (RAO 29.3 CRA 25.5 / LAO 30.7 CRA 23.6)",
    ),
}


# ------------------------------------------------------------- dataclasses
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
        """JSON-ready part of truth.json about the tree (see the module docstring)."""
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


@dataclass(frozen=True, eq=False)
class PhantomCase:
    """One synthetic two-view case.

    Attributes
    ----------
    preset, seed : what made it.
    view_a : view A's geometry (header == truth; it defines the world).
    view_b_nominal : view B's header geometry.
    view_b_true : view B's true geometry (images and clicks are made with it).
    image_a, image_b : (H, W) float32 12-bit values (0..4095, integers), or
        None when ``render=False``.
    frames_a, frames_b : (F, H, W) float32 cine stacks when ``n_frames > 1``,
        else None; ``image_k = frames_k[frame_index]``.
    frame_index : the frame the truth holds for (the sharpest, full contrast).
    seeds : the clinician's clicks, made with the true geometries.
    truth : the ground truth.
    """

    preset: str
    seed: int
    view_a: ViewGeometry
    view_b_nominal: ViewGeometry
    view_b_true: ViewGeometry
    image_a: NDArray[np.float32] | None
    image_b: NDArray[np.float32] | None
    seeds: Seeds
    truth: PhantomTruth
    frames_a: NDArray[np.float32] | None = None
    frames_b: NDArray[np.float32] | None = None
    frame_index: int = 0
    stenosis_pct: float = field(default=50.0)


def _rounded(arr: ArrayLike, decimals: int = 5) -> list:
    return np.round(np.asarray(arr, dtype=float), decimals).tolist()


# ------------------------------------------------------------- header error
def random_header_error(
    rng: np.random.Generator, view: ViewGeometry | None = None
) -> tuple[FloatArray, FloatArray]:
    """Draw a realistic error of view B's header as a rigid rig correction.

    The true geometry is ``nominal.with_correction(rotvec, t_mm)``. The
    rotation is a primary-angle error about the patient's long axis z then a
    secondary-angle error about the view's u axis, each of magnitude
    uniform in :data:`HEADER_ANGLE_ERROR_DEG` with a random sign; the
    translation is an SOD error along the view's d (magnitude uniform in
    :data:`HEADER_SOD_ERROR_MM`, random sign) plus a table/isocenter shift of magnitude
    uniform in :data:`HEADER_SHIFT_MM` in a random direction.

    Parameters
    ----------
    rng : random generator.
    view : the nominal view B (for its u and d axes); an AP view if None.

    Returns
    -------
    rotvec : (3,) rotation vector in radians.
    t_mm : (3,) translation in mm.
    """
    axes = (view if view is not None else _view(0.0, 0.0, 1000.0, 750.0)).nominal_axes
    u, d = axes[0], axes[2]
    lo, hi = HEADER_ANGLE_ERROR_DEG
    d_alpha, d_beta = np.deg2rad(rng.uniform(lo, hi, 2) * rng.choice([-1.0, 1.0], 2))
    R = rotation_from_rotvec(u * d_beta) @ rotation_from_rotvec(np.array([0.0, 0.0, d_alpha]))
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    shift = direction * rng.uniform(*HEADER_SHIFT_MM)
    sod_error = rng.uniform(*HEADER_SOD_ERROR_MM) * rng.choice([-1.0, 1.0])
    t_mm = sod_error * d + shift
    return rotvec_from_rotation(R), t_mm


# ------------------------------------------------------------- tree
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
class _TreeDraw:
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


def _draw_tree(rng: np.random.Generator) -> _TreeDraw | None:
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
    return _TreeDraw(
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


def _tree_fits(tree: _TreeDraw, views: Sequence[ViewGeometry]) -> bool:
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


def _main_radius(tree: _TreeDraw, s_mm: FloatArray, stenosis_pct: float) -> FloatArray:
    """Main-vessel radius (M,) at arc lengths ``s_mm``: linear taper times a cosine stenosis."""
    r0, r1 = tree.r_main
    length = len(tree.main_X) - 1
    r_ref = r0 + (r1 - r0) * s_mm / (length * SAMPLE_STEP_MM)
    x = (s_mm - tree.sten_s_main) / tree.sten_len
    bump = np.where(np.abs(x) < 0.5, 0.5 * (1.0 + np.cos(2 * np.pi * x)), 0.0)
    return r_ref * (1.0 - stenosis_pct / 100.0 * bump)


def _main_reference_radius(tree: _TreeDraw, s_mm: float) -> float:
    r0, r1 = tree.r_main
    return float(r0 + (r1 - r0) * s_mm / ((len(tree.main_X) - 1) * SAMPLE_STEP_MM))


# ------------------------------------------------------------- seeds
def click_px(rng: np.random.Generator, points_px: FloatArray) -> FloatArray:
    """Clicks (N, 2) on points (N, 2): CLICK_NOISE_PX noise, stored to CLICK_ROUND_PX."""
    noisy = points_px + rng.normal(0.0, CLICK_NOISE_PX, points_px.shape)
    return np.round(noisy / CLICK_ROUND_PX) * CLICK_ROUND_PX


def _click(rng: np.random.Generator, points_px: FloatArray) -> list[tuple[float, float]]:
    return [(round(float(c), 1), round(float(r), 1)) for c, r in click_px(rng, points_px)]


def _make_seeds(
    rng: np.random.Generator,
    seg_X: FloatArray,
    branch_X: FloatArray,
    branch_names: Sequence[str],
    view_a: ViewGeometry,
    view_b: ViewGeometry,
) -> Seeds:
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


# ------------------------------------------------------------- make_phantom
def make_phantom(
    preset: str = "data1",
    seed: int = 0,
    *,
    stenosis_pct: float = 50.0,
    render: bool = True,
    n_frames: int = 1,
    header_error: bool = True,
) -> PhantomCase:
    """Make one synthetic two-view case with its ground truth.

    Parameters
    ----------
    preset : key of :data:`PRESETS` ("data1", "data2", "data3", "static").
    seed : random seed; the same (preset, seed) gives an identical case.
    stenosis_pct : diameter stenosis in percent (0 <= pct < 100).
    render : also render the two images (else image_a/image_b are None).
    n_frames : frames of the cine stacks (1: no stacks).
    header_error : draw a random header error of view B (else nominal == true).

    Returns
    -------
    PhantomCase
    """
    if preset not in PRESETS:
        raise PhantomError(f"unknown phantom preset {preset!r} (use one of {', '.join(PRESETS)})")
    if not 0.0 <= stenosis_pct < 100.0:
        raise PhantomError(f"stenosis_pct must be in [0, 100), got {stenosis_pct}")
    if n_frames < 1:
        raise PhantomError(f"n_frames must be at least 1, got {n_frames}")
    p = PRESETS[preset]
    ss_error, ss_tree, ss_click, ss_render = np.random.SeedSequence(
        [int(seed), _preset_key(preset)]
    ).spawn(4)
    view_a = p.view_a
    view_b_nominal = p.view_b
    if header_error:
        rotvec, t_mm = random_header_error(np.random.default_rng(ss_error), view_b_nominal)
    else:
        rotvec, t_mm = np.zeros(3), np.zeros(3)
    view_b_true = view_b_nominal.with_correction(rotvec, t_mm)

    rng = np.random.default_rng(ss_tree)
    for _ in range(2000):
        tree = _draw_tree(rng)
        if tree is not None and _tree_fits(tree, (view_a, view_b_true, view_b_nominal)):
            break
    else:  # pragma: no cover - the constraints are loose enough in practice
        raise PhantomError(f"could not draw a tree inside the field for preset {preset!r}")

    truth, branch_names = _truth_from_tree(tree, stenosis_pct, rotvec, t_mm)
    seeds = _make_seeds(
        np.random.default_rng(ss_click),
        truth.segment_X_world,
        truth.features_world[2:],
        branch_names,
        view_a,
        view_b_true,
    )
    image_a = image_b = frames_a = frames_b = None
    frame_index = 0
    if render:
        rrng = np.random.default_rng(ss_render)
        frames_a, frame_index = _render_view(rrng, view_a, truth, n_frames)
        frames_b, _ = _render_view(rrng, view_b_true, truth, n_frames)
        image_a, image_b = frames_a[frame_index], frames_b[frame_index]
        if n_frames == 1:
            frames_a = frames_b = None
    return PhantomCase(
        preset=preset,
        seed=int(seed),
        view_a=view_a,
        view_b_nominal=view_b_nominal,
        view_b_true=view_b_true,
        image_a=image_a,
        image_b=image_b,
        seeds=seeds,
        truth=truth,
        frames_a=frames_a,
        frames_b=frames_b,
        frame_index=frame_index,
        stenosis_pct=float(stenosis_pct),
    )


def _preset_key(preset: str) -> int:
    return sum((k + 1) * ord(c) for k, c in enumerate(preset))


def _truth_from_tree(
    tree: _TreeDraw, stenosis_pct: float, rotvec: FloatArray, t_mm: FloatArray
) -> tuple[PhantomTruth, list[str]]:
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


# ------------------------------------------------------------- rendering
@dataclass(frozen=True)
class _Primitives:
    """Truncated cones (K) and spheres (J) whose union is the lumen, with attenuation."""

    A: FloatArray  # (K, 3) cone start
    B: FloatArray  # (K, 3) cone end
    ra: FloatArray  # (K,) radius at A
    rb: FloatArray  # (K,) radius at B
    mu_cone: FloatArray  # (K,) attenuation per mm
    C: FloatArray  # (J, 3) sphere centres (vessel end caps)
    rs: FloatArray  # (J,) sphere radii
    mu_sphere: FloatArray  # (J,)


def _cone_chain(
    vessels: Sequence[tuple[ArrayLike, ArrayLike]], mus: Sequence[ArrayLike]
) -> _Primitives:
    """Cut each sampled tube into truncated cones (short where it bends or narrows).

    Break points are kept where the accumulated length, radius change or
    bend exceeds :data:`CONE_MAX_LENGTH_MM`, :data:`CONE_MAX_DR_MM` or
    :data:`CONE_MAX_TURN_RAD`; the ends get spherical caps.
    """
    parts: dict[str, list] = {k: [] for k in ("A", "B", "ra", "rb", "mu", "C", "rs", "mus")}
    for (X, r), mu in zip(vessels, mus, strict=True):
        X = np.asarray(X, dtype=float).reshape(-1, 3)
        r = np.asarray(r, dtype=float).reshape(-1)
        mu = np.broadcast_to(np.asarray(mu, dtype=float), r.shape)
        if len(X) != len(r):
            raise ValueError(f"centerline has {len(X)} points but {len(r)} radii")
        if len(X) < 2:
            continue
        steps = np.diff(X, axis=0)
        seg_len = np.linalg.norm(steps, axis=1)
        tang = steps / np.maximum(seg_len[:, None], 1e-12)
        turn = np.arccos(np.clip(np.sum(tang[1:] * tang[:-1], axis=1), -1.0, 1.0))
        cost = np.concatenate([[0.0], np.cumsum(seg_len)]) / CONE_MAX_LENGTH_MM
        cost += np.concatenate([[0.0], np.cumsum(np.abs(np.diff(r)))]) / CONE_MAX_DR_MM
        cost += np.concatenate([[0.0, 0.0], np.cumsum(turn)]) / CONE_MAX_TURN_RAD
        keep = np.flatnonzero(np.diff(np.floor(cost)) > 0) + 1
        idx = np.unique(np.concatenate([[0], keep, [len(X) - 1]]))
        parts["A"].append(X[idx[:-1]])
        parts["B"].append(X[idx[1:]])
        parts["ra"].append(r[idx[:-1]])
        parts["rb"].append(r[idx[1:]])
        parts["mu"].append(0.5 * (mu[idx[:-1]] + mu[idx[1:]]))
        parts["C"].append(X[[0, -1]])
        parts["rs"].append(r[[0, -1]])
        parts["mus"].append(mu[[0, -1]])

    def cat(key: str, width: int | None) -> FloatArray:
        if not parts[key]:
            return np.zeros((0, width) if width else (0,))
        return np.concatenate(parts[key])

    return _Primitives(
        A=cat("A", 3),
        B=cat("B", 3),
        ra=cat("ra", None),
        rb=cat("rb", None),
        mu_cone=cat("mu", None),
        C=cat("C", 3),
        rs=cat("rs", None),
        mu_sphere=cat("mus", None),
    )


def _pixel_pairs(
    view: ViewGeometry, P0: FloatArray, P1: FloatArray, rmax: FloatArray, ss: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """All (primitive, subpixel) pairs of each primitive's projected bounding box.

    Returns the primitive index (N,) and the flat subpixel index (N,) in the
    (H ss, W ss) grid whose subpixel (m, n) is centred at pixel
    ((n + 0.5) / ss - 0.5, (m + 0.5) / ss - 0.5).
    """
    H, W = view.rows * ss, view.cols * ss
    p0, p1 = view.project(P0), view.project(P1)
    depth = np.minimum(view.depth_mm(P0), view.depth_mm(P1)) - rmax
    spacing = min(view.pixel_spacing_mm)
    r_px = rmax * view.sid_mm / np.maximum(depth, 1e-6) / spacing + 1.0
    lo = np.minimum(p0, p1) - r_px[:, None]
    hi = np.maximum(p0, p1) + r_px[:, None]
    m_lo = np.ceil((lo + 0.5) * ss - 0.5).astype(np.int64)
    m_hi = np.floor((hi + 0.5) * ss - 0.5).astype(np.int64)
    m_lo = np.maximum(m_lo, 0)
    m_hi = np.minimum(m_hi, np.array([W - 1, H - 1]))
    size = np.maximum(m_hi - m_lo + 1, 0)  # (K, 2) columns, rows
    count = size[:, 0] * size[:, 1]
    prim = np.repeat(np.arange(len(P0)), count)
    local = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    w = size[prim, 0]
    col = m_lo[prim, 0] + local % np.maximum(w, 1)
    row = m_lo[prim, 1] + local // np.maximum(w, 1)
    return prim, row * W + col


def _subpixel_rays(view: ViewGeometry, flat: NDArray[np.int64], ss: int) -> FloatArray:
    """Unit world directions (N, 3) of the rays through flat subpixel indices."""
    W = view.cols * ss
    sr, sc = view.pixel_spacing_mm
    cx, cy = view.centre_px
    xn = ((flat % W + 0.5) / ss - 0.5 - cx) * (sc / view.sid_mm)
    yn = ((flat // W + 0.5) / ss - 0.5 - cy) * (sr / view.sid_mm)
    R = view.R_view_from_world  # rows u, v, d: orthonormal, so |(xn, yn, 1) R| = sqrt(...)
    inv = 1.0 / np.sqrt(1.0 + xn**2 + yn**2)
    return (xn * inv)[:, None] * R[0] + (yn * inv)[:, None] * R[1] + inv[:, None] * R[2]


def _cone_intervals(
    S: FloatArray, w: FloatArray, A: FloatArray, B: FloatArray, ra: FloatArray, rb: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Entry and exit distances (N,) of rays S + t w through truncated cones (inf if missed).

    A point is inside when its axial coordinate y in [0, h] and its distance
    from the axis is at most ra + (rb - ra) y / h; along the ray this is the
    quadratic a t^2 + 2 b t + c <= 0 clipped to the slab. Distances are
    computed from the ray point closest to A for precision.
    """
    axis = B - A
    h = np.linalg.norm(axis, axis=1)
    e = axis / np.maximum(h, 1e-12)[:, None]
    k = (rb - ra) / np.maximum(h, 1e-12)
    t0 = np.einsum("ij,ij->i", w, A - S)
    oa = S + t0[:, None] * w - A
    y0 = np.einsum("ij,ij->i", oa, e)
    wy = np.einsum("ij,ij->i", w, e)
    wo = np.einsum("ij,ij->i", w, oa)
    rho0 = ra + k * y0
    a = 1.0 - wy**2 * (1.0 + k**2)
    b = wo - y0 * wy - k * wy * rho0
    c = np.einsum("ij,ij->i", oa, oa) - y0**2 - rho0**2
    disc = b**2 - a * c
    sq = np.sqrt(np.maximum(disc, 0.0))
    inf = np.inf
    with np.errstate(divide="ignore", invalid="ignore"):
        # The slab 0 <= y0 + t wy <= h.
        along = np.abs(wy) > 1e-12
        s1 = np.where(along, -y0 / wy, np.where((y0 >= 0) & (y0 <= h), -inf, inf))
        s2 = np.where(along, (h - y0) / wy, np.where((y0 >= 0) & (y0 <= h), inf, -inf))
        ts_lo, ts_hi = np.minimum(s1, s2), np.maximum(s1, s2)
        # The quadratic's solution set: up to two intervals [l1, h1], [l2, h2].
        pos = a > 1e-12
        neg = a < -1e-12
        lin = ~(pos | neg)
        r_1 = (-b - sq) / a
        r_2 = (-b + sq) / a
        r_lo, r_hi = np.minimum(r_1, r_2), np.maximum(r_1, r_2)
        t_lin = -c / (2.0 * b)
        l1 = np.full_like(a, inf)
        h1 = np.full_like(a, -inf)
        l2 = np.full_like(a, inf)
        h2 = np.full_like(a, -inf)
        m = pos & (disc >= 0)
        l1[m], h1[m] = r_lo[m], r_hi[m]
        m = neg & (disc < 0)
        l1[m], h1[m] = -inf, inf
        m = neg & (disc >= 0)
        l1[m], h1[m] = -inf, r_lo[m]
        l2[m], h2[m] = r_hi[m], inf
        m = lin & (b > 0)
        l1[m], h1[m] = -inf, t_lin[m]
        m = lin & (b < 0)
        l1[m], h1[m] = t_lin[m], inf
        m = lin & (b == 0) & (c <= 0)
        l1[m], h1[m] = -inf, inf
    i1_lo, i1_hi = np.maximum(l1, ts_lo), np.minimum(h1, ts_hi)
    i2_lo, i2_hi = np.maximum(l2, ts_lo), np.minimum(h2, ts_hi)
    ok1, ok2 = i1_hi > i1_lo, i2_hi > i2_lo
    t_in = np.minimum(np.where(ok1, i1_lo, inf), np.where(ok2, i2_lo, inf))
    t_out = np.maximum(np.where(ok1, i1_hi, -inf), np.where(ok2, i2_hi, -inf))
    return t0 + t_in, t0 + t_out


def _sphere_intervals(
    S: FloatArray, w: FloatArray, C: FloatArray, r: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Entry and exit distances (N,) of rays S + t w through spheres (inf if missed)."""
    t0 = np.einsum("ij,ij->i", w, C - S)
    oc = S + t0[:, None] * w - C
    h = r**2 - np.einsum("ij,ij->i", oc, oc)
    sq = np.sqrt(np.maximum(h, 0.0))
    hit = h > 0
    return np.where(hit, t0 - sq, np.inf), np.where(hit, t0 + sq, -np.inf)


_CHUNK_PAIRS = 1_000_000


def _attenuation_subpixels(
    view: ViewGeometry, prims: _Primitives, ss: int
) -> tuple[FloatArray, FloatArray]:
    """Line integrals of mu and path lengths (H ss, W ss) through the union of primitives.

    Each ray's intervals through all primitives are sorted by (subpixel,
    entry) and merged with a running maximum of the exit: a piece of ray
    inside several overlapping primitives counts once (attributed to the
    first), disjoint pieces (vessels crossing) add up.
    """
    S = view.source_world
    pix_parts, tin_parts, tout_parts, mu_parts = [], [], [], []
    n_cone = len(prims.A)
    P0 = np.vstack([prims.A, prims.C])
    P1 = np.vstack([prims.B, prims.C])
    rmax = np.concatenate([np.maximum(prims.ra, prims.rb), prims.rs])
    mu_all = np.concatenate([prims.mu_cone, prims.mu_sphere])
    prim, flat = _pixel_pairs(view, P0, P1, rmax, ss)
    for start in range(0, len(prim), _CHUNK_PAIRS):
        p = prim[start : start + _CHUNK_PAIRS]
        f = flat[start : start + _CHUNK_PAIRS]
        w = _subpixel_rays(view, f, ss)
        t_in = np.empty(len(p))
        t_out = np.empty(len(p))
        cone = p < n_cone
        pc = p[cone]
        t_in[cone], t_out[cone] = _cone_intervals(
            S, w[cone], prims.A[pc], prims.B[pc], prims.ra[pc], prims.rb[pc]
        )
        ps = p[~cone] - n_cone
        t_in[~cone], t_out[~cone] = _sphere_intervals(S, w[~cone], prims.C[ps], prims.rs[ps])
        hit = t_out > t_in
        pix_parts.append(f[hit])
        tin_parts.append(t_in[hit])
        tout_parts.append(t_out[hit])
        mu_parts.append(mu_all[p[hit]])
    size = view.rows * ss * view.cols * ss
    if not pix_parts or sum(len(x) for x in pix_parts) == 0:
        zero = np.zeros((view.rows * ss, view.cols * ss))
        return zero, zero.copy()
    pix = np.concatenate(pix_parts)
    t_in = np.concatenate(tin_parts)
    t_out = np.concatenate(tout_parts)
    mu = np.concatenate(mu_parts)
    order = np.lexsort((t_in, pix))
    pix, t_in, t_out, mu = pix[order], t_in[order], t_out[order], mu[order]
    # Segmented running maximum of the exits: offset each subpixel's group so
    # that a plain cumulative maximum never carries over from the previous one.
    t_min = float(t_in.min())
    span = float(t_out.max() - t_min) + 1.0
    key = (t_out - t_min) + pix * span
    run = np.maximum.accumulate(key)
    prev = np.concatenate([[-np.inf], run[:-1] - pix[1:] * span + t_min])
    piece = np.maximum(t_out - np.maximum(t_in, prev), 0.0)
    shape = (view.rows * ss, view.cols * ss)
    att = np.bincount(pix, weights=mu * piece, minlength=size).reshape(shape)
    length = np.bincount(pix, weights=piece, minlength=size).reshape(shape)
    return att, length


def _block_mean(arr: FloatArray, ss: int) -> FloatArray:
    H, W = arr.shape[0] // ss, arr.shape[1] // ss
    return arr.reshape(H, ss, W, ss).mean(axis=(1, 3))


def path_length_image(
    view: ViewGeometry,
    vessels: Sequence[tuple[ArrayLike, ArrayLike]],
    *,
    supersample: int = 1,
) -> FloatArray:
    """Iodine path length (H, W) in mm through the union of tubes, per pixel.

    Parameters
    ----------
    view : the projecting geometry.
    vessels : sequence of (centerline (M, 3) world mm, radius (M,) mm); each
        tube is a chain of truncated cones with spherical end caps.
    supersample : rays per pixel along each axis; the result is their mean.

    Returns
    -------
    (H, W) float64 path length in mm (overlaps counted once, crossings add).
    """
    prims = _cone_chain(vessels, [1.0] * len(vessels))
    _, length = _attenuation_subpixels(view, prims, supersample)
    return _block_mean(length, supersample)


def _smooth_field(rng: np.random.Generator, shape: tuple[int, int], sigma_px: float) -> FloatArray:
    """Zero-mean, unit-sd Gaussian random field (H, W) of correlation length ~sigma_px."""
    step = max(sigma_px / 3.0, 1.0)
    coarse = (int(np.ceil(shape[0] / step)) + 8, int(np.ceil(shape[1] / step)) + 8)
    noise = ndimage.gaussian_filter(rng.normal(size=coarse), sigma_px / step, mode="wrap")
    size = (int(round(coarse[1] * step)), int(round(coarse[0] * step)))  # (W, H) for cv2
    big = cv2.resize(noise, size, interpolation=cv2.INTER_CUBIC)
    off = int(4 * step)
    zoomed = big[off : off + shape[0], off : off + shape[1]]
    return (zoomed - zoomed.mean()) / max(zoomed.std(), 1e-12)


def _background_attenuation(rng: np.random.Generator, view: ViewGeometry) -> FloatArray:
    """Smooth anatomy (H, W) as a line integral: random field plus a diaphragm edge."""
    shape = (view.rows, view.cols)
    att = rng.uniform(-0.05, 0.05) * np.ones(shape)
    for sigma, amp in ((60.0, 0.10), (25.0, 0.05), (10.0, 0.02)):
        att += amp * rng.uniform(0.6, 1.2) * _smooth_field(rng, shape, sigma)
    # Diaphragm: the inside of a large circle entering from the lower part.
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
    radius = rng.uniform(300.0, 500.0)
    reach = rng.uniform(40.0, 150.0)  # how far the dome comes into the image
    angle = rng.uniform(-0.6, 0.6)  # tilt of the dome's approach from the bottom
    centre_c = shape[1] / 2 + rng.uniform(-150, 150) + np.sin(angle) * radius
    centre_r = shape[0] - reach + np.cos(angle) * radius
    dist = np.hypot(rows - centre_r, cols - centre_c) - radius
    att += rng.uniform(0.25, 0.45) / (1.0 + np.exp(dist / rng.uniform(3.0, 6.0)))
    return att


def _collimator(rng: np.random.Generator, view: ViewGeometry) -> FloatArray:
    """Mask (H, W): 1 inside the collimator, a small leakage in the black border."""
    rows, cols = view.rows, view.cols
    top, left = rng.integers(5, 9, 2)
    bottom, right = rows - rng.integers(4, 8), cols - rng.integers(3, 7)
    mask = np.full((rows, cols), 0.01)
    mask[top:bottom, left:right] = 1.0
    return mask


def _render_view(
    rng: np.random.Generator, view: ViewGeometry, truth: PhantomTruth, n_frames: int
) -> tuple[NDArray[np.float32], int]:
    """Render ``n_frames`` images (F, H, W) of the tree in ``view`` and the truth frame index."""
    ss = SUPERSAMPLE
    mu0 = rng.uniform(*MU_PROXIMAL_PER_MM)
    fade = 1.0 - MU_DISTAL_FRACTION
    main_X = truth.vessels[0][0]
    main_len = max((len(main_X) - 1) * SAMPLE_STEP_MM, 1e-9)
    mus = []
    for k, (X, _) in enumerate(truth.vessels):
        frac = np.arange(len(X)) / max(len(X) - 1, 1)
        if k == 0:  # contrast fades by `fade` from proximal to distal
            mus.append(mu0 * (1.0 - fade * frac))
        else:  # a branch starts at its origin's value and fades more slowly
            s_origin = np.argmin(np.linalg.norm(main_X - X[0], axis=1)) * SAMPLE_STEP_MM
            mus.append(mu0 * (1.0 - fade * s_origin / main_len) * (1.0 - 0.5 * fade * frac))
    prims = _cone_chain(truth.vessels, mus)
    att_sub, _ = _attenuation_subpixels(view, prims, ss)
    background = _background_attenuation(rng, view)
    collimator = _collimator(rng, view)
    frame_index = n_frames - 1 - n_frames // 4
    period = rng.uniform(6.0, 12.0)
    drift = rng.normal(size=2)
    drift *= rng.uniform(0.8, 2.0) / np.linalg.norm(drift)
    frames = np.empty((n_frames, view.rows, view.cols), dtype=np.float32)
    for f in range(n_frames):
        if n_frames == 1:
            contrast, phase = 1.0, 0.0
        else:
            contrast = min(1.0, 0.2 + 0.8 * (f + 1) / (frame_index + 1))
            phase = np.sin(2 * np.pi * (f - frame_index) / period)
        vessel_t = _block_mean(np.exp(-contrast * att_sub), ss)
        if phase != 0.0:
            vessel_t = ndimage.shift(vessel_t, drift[::-1] * phase, order=1, mode="nearest")
        expected = PHOTONS_PER_PIXEL * np.exp(-background) * vessel_t * collimator
        counts = rng.poisson(expected).astype(float)
        blur = DETECTOR_BLUR_PX * (1.0 + 0.5 * abs(phase))
        counts = ndimage.gaussian_filter(counts, blur)
        value = counts * (BACKGROUND_LEVEL / PHOTONS_PER_PIXEL)
        frames[f] = np.clip(np.round(value), 0, MAX_VALUE)
    return frames, frame_index


# ------------------------------------------------------------- files
def write_phantom_case(case: PhantomCase, out_dir: str | os.PathLike) -> dict[str, Path]:
    """Write a.dcm, b.dcm, seeds.json and truth.json into ``out_dir``.

    b.dcm carries view B's NOMINAL header although its image was rendered
    with the true geometry. A rendered case is required.

    Returns
    -------
    dict with keys "a", "b", "seeds", "truth" -> written paths.
    """
    from recon.dicom_io import write_xa_dicom

    if case.image_a is None or case.image_b is None:
        raise PhantomError("write_phantom_case needs a rendered case (make_phantom(render=True))")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "a": out / "a.dcm",
        "b": out / "b.dcm",
        "seeds": out / "seeds.json",
        "truth": out / "truth.json",
    }
    for key, view, image, frames in (
        ("a", case.view_a, case.image_a, case.frames_a),
        ("b", case.view_b_nominal, case.image_b, case.frames_b),
    ):
        data = frames if frames is not None else image
        pixels = np.clip(np.round(data), 0, MAX_VALUE).astype(np.uint16)
        kwargs = {}
        if frames is not None:
            kwargs = {
                "frame_time_ms": 66.6667,
                "r_wave_frames": [case.frame_index],
                "representative_frame": case.frame_index,
            }
        write_xa_dicom(
            paths[key],
            pixels,
            view.nominal(),
            bits_stored=12,
            series_description=f"coronary3d phantom {case.preset} seed {case.seed} view {key}",
            **kwargs,
        )
    save_seeds(case.seeds, paths["seeds"])
    doc = {
        "version": 1,
        "preset": case.preset,
        "seed": case.seed,
        "frame_index": case.frame_index,
        "view_a": case.view_a.to_dict(),
        "view_b_nominal": case.view_b_nominal.to_dict(),
        "view_b_true": case.view_b_true.to_dict(),
        **case.truth.to_dict(),
    }
    # One top-level key per line: readable, and the long arrays stay compact.
    body = ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}" for k, v in doc.items())
    atomic_write_bytes(paths["truth"], ("{\n" + body + "\n}\n").encode())
    return paths


def load_truth(path: str | os.PathLike) -> PhantomTruth:
    """Read truth.json (schema in the module docstring) back into a PhantomTruth."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
        seg = doc["segment"]
        sten = doc["stenosis"]
        vessels = tuple(
            (np.asarray(v["X_world"], float).reshape(-1, 3), np.asarray(v["radius_mm"], float))
            for v in doc["vessels"]
        )
        return PhantomTruth(
            vessels=vessels,
            segment_X_world=np.asarray(seg["X_world"], float).reshape(-1, 3),
            segment_radius_mm=np.asarray(seg["radius_mm"], float),
            segment_s_mm=np.asarray(seg["s_mm"], float),
            stenosis_s_mm=float(sten["s_mm"]),
            stenosis_length_mm=float(sten["length_mm"]),
            stenosis_diameter_pct=float(sten["diameter_pct"]),
            mld_mm=float(sten["mld_mm"]),
            reference_diameter_mm=float(sten["reference_diameter_mm"]),
            features_world=np.asarray([f["X_world"] for f in doc["features"]], float).reshape(
                -1, 3
            ),
            feature_names=tuple(str(f["name"]) for f in doc["features"]),
            correction_rotvec=np.asarray(doc["correction_rotvec"], float),
            correction_t_mm=np.asarray(doc["correction_t_mm"], float),
            segment_volume_mm3=float(seg["volume_mm3"]),
            segment_start_s_mm=float(seg.get("start_s_mm", 0.0)),
            vessel_names=tuple(str(v.get("name", "")) for v in doc["vessels"]),
        )
    except OSError as exc:
        raise PhantomError(f"{p}: cannot read ({exc.strerror or exc})") from None
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise PhantomError(f"{p}: not a valid phantom truth file ({exc})") from None
