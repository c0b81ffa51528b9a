"""Small frozen dataclasses that pass between pipeline stages.

Each stage module owns its own result types; the ones here cross stage
boundaries (loaded angiogram -> traced 2D centerline -> matching -> 3D
centerline -> surface).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray
from scipy.interpolate import make_interp_spline

from recon.errors import LoadError
from recon.geometry import ViewGeometry

FloatArray = NDArray[np.float64]

__all__ = ["Angiogram", "Centerline2D", "Matching", "Centerline3D", "arclength"]


@dataclass(frozen=True, eq=False)
class Angiogram:
    """One loaded angiogram: the chosen frame, its geometry and provenance.

    Attributes
    ----------
    image : (H, W) float32, the chosen frame, MONOCHROME2 sense (vessels
        dark), raw stored values.
    geometry : the view's nominal :class:`ViewGeometry` (rows, cols = H, W).
    path : the file it came from.
    frame_index : 0-based index of ``image`` in the run.
    frame_reason : why this frame ("explicit", "RepresentativeFrameNumber 5",
        "end-diastolic: R wave at frame 20 ...", "strongest vessel contrast",
        "single frame").
    n_frames : number of frames in the file.
    frame_time_ms : FrameTime, or None.
    frames : (F, H, W) float32 of the whole run, or None for a single frame.
    geometry_notes : how geometry values that are not plain header tags were
        obtained (overrides, fallbacks).
    info : header facts (sop_class, sop_class_name, modality, rows, cols,
        bits_stored, photometric, transfer_syntax, r_wave_pointer (1-based,
        raw), r_wave_frames (0-based), representative_frame_number, ...).
    """

    image: NDArray[np.float32]
    geometry: ViewGeometry
    path: str
    frame_index: int
    frame_reason: str
    n_frames: int
    frame_time_ms: float | None = None
    frames: NDArray[np.float32] | None = None
    geometry_notes: tuple[str, ...] = ()
    info: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the image."""
        return (int(self.image.shape[0]), int(self.image.shape[1]))

    def with_frame(self, index: int) -> Angiogram:
        """The same run with frame ``index`` (0-based) as the image; reason "explicit"."""
        index = _check_frame_index(index, self.n_frames, self.path)
        image = self.image if self.frames is None else self.frames[index]
        return replace(self, image=image, frame_index=index, frame_reason="explicit")


def _check_frame_index(index: object, n_frames: int, path: str) -> int:
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
        raise LoadError(f"{path}: frame must be an integer index, got {index!r}")
    if not 0 <= int(index) < n_frames:
        raise LoadError(
            f"{path}: frame {int(index)} is out of range; the file has {n_frames} "
            f"frame{'s' if n_frames != 1 else ''} (0-based: 0..{n_frames - 1})"
        )
    return int(index)


def arclength(points: FloatArray) -> FloatArray:
    """Cumulative polyline length (N,) from the first of N points (N, D), starting at 0."""
    steps = np.linalg.norm(np.diff(points, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


@dataclass(frozen=True, eq=False)
class Centerline2D:
    """A vessel centerline traced in one view, proximal to distal.

    Attributes
    ----------
    points_px : (N, 2) subpixel (col, row), roughly uniform arc-length spacing.
    radius_px : (N,) lumen radius in pixels (half the projected diameter).
    brightness : (N,) image value on the centerline (raw units; lower = more
        contrast for MONOCHROME2), used by CBOCD eq. (7).
    clicks_px : (K, 2) the snapped clicks the trace passes through.
    reliability : (N,) confidence in (0, 1] of the profile fit behind each
        point's centre and radius (1 = one clean tube; low where another
        vessel overlaps or touches); all ones when not given.
    intensity_mapping : "lin" or "log": how the stored values were taken to
        relate to attenuation (None when not recorded).
    intensity_reason : one line saying why that mapping (tag, override, or
        what the vessel profiles showed), or None.
    intensity_power : Box-Cox power of the stored values the radius fit used
        (0 = -log, values linear in intensity; 1 = linear in attenuation), or None.
    blur_px : Gaussian blur (px) of the radius model the fit used, or None.
    depth : (N,) the profile fit's depth: absorption per px of chord of the fitted
        circle template (:mod:`recon.trace.profile_fit`), the densitometric signal of
        :mod:`recon.lumen.densitometry`; None when not measured.
    catheters_px : centre lines (M_i, 2), field edge first, of the catheter tubes found
        in the image (:mod:`recon.trace.guide_catheter`), which the trace did not follow.
    """

    points_px: FloatArray
    radius_px: FloatArray
    brightness: FloatArray
    clicks_px: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    reliability: FloatArray | None = None
    intensity_mapping: str | None = None
    intensity_reason: str | None = None
    intensity_power: float | None = None
    blur_px: float | None = None
    depth: FloatArray | None = None
    catheters_px: tuple[FloatArray, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.points_px)
        if self.points_px.shape != (n, 2) or n < 2:
            raise ValueError(f"points_px must be (N>=2, 2), got {self.points_px.shape}")
        if self.reliability is None:
            object.__setattr__(self, "reliability", np.ones(n))
        for name in ("radius_px", "brightness", "reliability"):
            if getattr(self, name).shape != (n,):
                raise ValueError(f"{name} must be ({n},), got {getattr(self, name).shape}")
        if self.depth is not None and np.shape(self.depth) != (n,):
            raise ValueError(f"depth must be ({n},), got {np.shape(self.depth)}")

    @property
    def arclength_px(self) -> FloatArray:
        """Cumulative arc length (N,) in pixels from the proximal end."""
        return arclength(self.points_px)

    @property
    def length_px(self) -> float:
        return float(self.arclength_px[-1])

    @property
    def tangents(self) -> FloatArray:
        """Unit tangents (N, 2) by central differences."""
        t = np.gradient(self.points_px, axis=0)
        return t / np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)

    @property
    def normals(self) -> FloatArray:
        """Unit normals (N, 2): tangents turned by +90 degrees in (col, row)."""
        t = self.tangents
        return np.column_stack([-t[:, 1], t[:, 0]])

    def resample(self, n: int) -> Centerline2D:
        """The same curve at ``n`` points of uniform arc length (cubic spline, sec. 3.3.1)."""
        if n < 2:
            raise ValueError("n must be at least 2")
        s = self.arclength_px
        keep = np.concatenate([[True], np.diff(s) > 1e-9])
        s, pts = s[keep], self.points_px[keep]
        k = min(3, len(s) - 1)
        s_new = np.linspace(0.0, s[-1], n)
        pts_new = make_interp_spline(s, pts, k=k)(s_new)
        return Centerline2D(
            points_px=pts_new,
            radius_px=np.interp(s_new, s, self.radius_px[keep]),
            brightness=np.interp(s_new, s, self.brightness[keep]),
            clicks_px=self.clicks_px,
            reliability=np.interp(s_new, s, np.asarray(self.reliability)[keep]),
            depth=None if self.depth is None else np.interp(s_new, s, self.depth[keep]),
            catheters_px=self.catheters_px,
        )


@dataclass(frozen=True, eq=False)
class Matching:
    """Point correspondence between the two traced centerlines.

    Attributes
    ----------
    method : "match1" .. "match4".
    points_a_px, points_b_px : (M, 2) matched pixels, proximal to distal.
    index_a, index_b : (M,) indices into the (possibly resampled) centerlines
        ``centerline_a`` / ``centerline_b`` used for matching.
    centerline_a, centerline_b : the centerlines indexed by index_a/index_b.
    standard_view : "a" or "b", the longer trace (sec. 3.3.1).
    deviation_a_px, deviation_b_px : (K, 2) deviation pairs (sec. 3.4.2)
        whose epipolar distance exceeded the threshold.
    max_row_min_cost_px : MAX of the row minima of COST (sec. 3.4.2).
    threshold_px : STD, the deviation threshold used.
    elapsed_ms : time of the matching.
    """

    method: str
    points_a_px: FloatArray
    points_b_px: FloatArray
    index_a: NDArray[np.int64]
    index_b: NDArray[np.int64]
    centerline_a: Centerline2D
    centerline_b: Centerline2D
    standard_view: str
    deviation_a_px: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    deviation_b_px: FloatArray = field(default_factory=lambda: np.zeros((0, 2)))
    max_row_min_cost_px: float = 0.0
    threshold_px: float = 0.0
    elapsed_ms: float = 0.0


@dataclass(frozen=True, eq=False)
class Centerline3D:
    """The reconstructed 3D centerline in view A's world frame (mm), proximal to distal.

    Attributes
    ----------
    X_world : (M, 3) points of the smoothing spline at uniform arc length.
    s_mm : (M,) arc length from the proximal end.
    tangents : (M, 3) unit tangents of the spline.
    radius_a_mm, radius_b_mm : (M,) lumen radius seen in view A / view B,
        scaled back to the vessel by eq. (11) (half the intersection-line
        lengths of sec. 3.5).
    X_raw_world : (K, 3) the triangulated matched points before smoothing.
    points_a_px, points_b_px : (K, 2) the matched pixels behind X_raw_world.
    overlap_a, overlap_b : (M,) bool, True where that view's radius could not
        be trusted (another vessel overlapping) and the other view's radius
        stands in for it (see :func:`recon.correspond.triangulation.build_centerline_3d`);
        all False when not given.
    depth_a, depth_b : (M,) each view's profile-fit depth at the matched points
        (:attr:`Centerline2D.depth`), or None.
    fill_a, fill_b : (M,) the densitometric area over each view's caliper circle,
        A / (pi r_k^2) (:func:`recon.lumen.densitometry.with_fill_ratios`), or None: then
        the sections are built from the two calipers alone.
    fit_radius_a_mm, fit_radius_b_mm : (M,) each view's own fitted radius where
        ``overlap_a``/``overlap_b`` replaced it (the two views' disagreement before
        the substitution, for the intervals), or None: as ``radius_a_mm``/``_b_mm``.
    """

    X_world: FloatArray
    s_mm: FloatArray
    tangents: FloatArray
    radius_a_mm: FloatArray
    radius_b_mm: FloatArray
    X_raw_world: FloatArray
    points_a_px: FloatArray
    points_b_px: FloatArray
    overlap_a: NDArray[np.bool_] | None = None
    overlap_b: NDArray[np.bool_] | None = None
    depth_a: FloatArray | None = None
    depth_b: FloatArray | None = None
    fill_a: FloatArray | None = None
    fill_b: FloatArray | None = None
    fit_radius_a_mm: FloatArray | None = None
    fit_radius_b_mm: FloatArray | None = None

    def __post_init__(self) -> None:
        m = len(self.X_world)
        for name in ("overlap_a", "overlap_b"):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.zeros(m, dtype=bool))
            elif np.shape(getattr(self, name)) != (m,):
                raise ValueError(f"{name} must be ({m},), got {np.shape(getattr(self, name))}")
        for name in ("depth_a", "depth_b", "fill_a", "fill_b", "fit_radius_a_mm",
                     "fit_radius_b_mm"):
            if getattr(self, name) is not None and np.shape(getattr(self, name)) != (m,):
                raise ValueError(f"{name} must be ({m},), got {np.shape(getattr(self, name))}")

    @property
    def length_mm(self) -> float:
        return float(self.s_mm[-1])

    def overlap_stretches_mm(self, view: str) -> list[list[float]]:
        """Stretches [start, end] (mm of arc) where view "a" or "b" had its radius replaced."""
        mask = self.overlap_a if view == "a" else self.overlap_b
        edges = np.diff(np.concatenate([[0], np.asarray(mask, dtype=np.int8), [0]]))
        starts, stops = np.nonzero(edges == 1)[0], np.nonzero(edges == -1)[0] - 1
        return [
            [round(float(self.s_mm[i]), 2), round(float(self.s_mm[j]), 2)]
            for i, j in zip(starts, stops, strict=True)
        ]

    @property
    def radius_mm(self) -> FloatArray:
        """Equivalent circular radius (M,) = sqrt(r_a r_b) (same area as the ellipse)."""
        return np.sqrt(self.radius_a_mm * self.radius_b_mm)
