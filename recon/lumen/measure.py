"""Quantitative coronary analysis (QCA) on the 3D lumen.

The lumen is described along the 3D centerline's arc length s (free of
foreshortening) by the cross-section areas of sec. 3.5; each area gives an
equivalent circular diameter d(s) = 2 sqrt(A / pi).

Definitions used here (documented because QCA packages differ):

- Smoothing: d(s) and A(s) are lightly smoothed by a Savitzky-Golay filter
  (cubic, window ``smooth_mm``, 2 mm by default) that leaves a smooth minimum
  unbiased.
- Reference diameter: a robust straight-line fit of d(s) (the tapering
  "interpolated reference" of QCA). Points whose relative deviation from the
  fit is below -delta (narrowed) or above +2 delta are excluded and the fit
  is repeated until it settles; delta = clip(2.5 sigma, 5 %, 15 %), sigma
  the robust (MAD) relative scatter of the kept points. The lesion found
  below is excluded as a whole from the final fit.
- Lesion: located at the peak of the relative deficit 1 - d / ref. Each of
  its edges is placed at twice the distance from the peak to where the
  deficit falls to half its peak value. For a raised-cosine narrowing
  (the phantom's r = r_ref (1 - p (1 + cos(2 pi (s - s0) / L)) / 2)) this is
  exactly s0 +- L / 2, and unlike a fixed threshold it does not depend on
  the severity; for other shapes it is the extent of the equivalent cosine.
  A peak deficit below delta is no lesion (length 0).
- MLD / MLA: the minima of the smoothed diameter / area inside the lesion
  (over the whole segment when there is no lesion). % diameter stenosis =
  100 (1 - MLD / ref(s_MLD)), % area stenosis = 100 (1 - MLA / ref_area(s_MLD))
  with ref_area = pi ref^2 / 4.
- Segment length: the 3D arc length s[-1] - s[0].
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

__all__ = ["Measurements", "LumenProfile", "lumen_profile", "measure_lumen"]

_DELTA_MIN = 0.05  # smallest relative deviation treated as disease
_DELTA_MAX = 0.15
_MAX_ITER = 30


@dataclass(frozen=True)
class Measurements:
    """3D QCA results; lengths in mm along the 3D centerline, areas in mm^2.

    Attributes
    ----------
    mld_mm : minimal lumen diameter (equivalent circular diameter).
    mld_s_mm : arc length of the MLD.
    reference_diameter_mm : interpolated reference diameter at the MLD.
    diameter_stenosis_pct : 100 (1 - MLD / reference).
    area_stenosis_pct : 100 (1 - MLA / reference area).
    lesion_start_s_mm, lesion_end_s_mm : lesion edges (equal to mld_s_mm when
        no lesion is found).
    lesion_length_mm : lesion_end - lesion_start (0 when no lesion).
    segment_length_mm : 3D arc length of the analysed segment.
    mla_mm2 : minimal lumen area.
    reference_area_mm2 : pi reference^2 / 4 at the MLD.
    """

    mld_mm: float
    mld_s_mm: float
    reference_diameter_mm: float
    diameter_stenosis_pct: float
    area_stenosis_pct: float
    lesion_start_s_mm: float
    lesion_end_s_mm: float
    lesion_length_mm: float
    segment_length_mm: float
    mla_mm2: float
    reference_area_mm2: float

    @property
    def has_lesion(self) -> bool:
        """True when a lesion was found (its length is positive)."""
        return self.lesion_length_mm > 0.0

    def to_dict(self) -> dict[str, float | bool]:
        """JSON-ready dict of the fields (plus ``has_lesion``)."""
        out: dict[str, float | bool] = {f.name: float(getattr(self, f.name))
                                        for f in fields(self)}
        out["has_lesion"] = self.has_lesion
        return out


@dataclass(frozen=True, eq=False)
class LumenProfile:
    """Lumen size along the 3D centerline.

    Attributes
    ----------
    s_mm : (M,) arc length, increasing.
    diameter_mm : (M,) equivalent circular diameter 2 sqrt(A / pi) (unsmoothed).
    area_mm2 : (M,) cross-section area (unsmoothed).
    reference_diameter_mm : (M,) interpolated healthy reference diameter.
    diameter_smooth_mm : (M,) the smoothed diameter the measurements use.
    area_smooth_mm2 : (M,) the smoothed area.
    threshold_rel : the disease threshold delta of the reference fit: a
        relative deficit below it is not a lesion.
    """

    s_mm: FloatArray
    diameter_mm: FloatArray
    area_mm2: FloatArray
    reference_diameter_mm: FloatArray
    diameter_smooth_mm: FloatArray
    area_smooth_mm2: FloatArray
    threshold_rel: float = _DELTA_MIN

    def smooth_radius_at(self, s_mm: ArrayLike) -> FloatArray:
        """The smoothed lumen radius (mm) at arc lengths ``s_mm`` (held constant beyond
        the profile's ends): half of ``diameter_smooth_mm``, interpolated."""
        return np.interp(np.asarray(s_mm, dtype=float), self.s_mm, self.diameter_smooth_mm) / 2.0

    @property
    def relative_deficit(self) -> FloatArray:
        """(M,) 1 - smoothed diameter / reference (positive where narrowed)."""
        return 1.0 - self.diameter_smooth_mm / self.reference_diameter_mm


def _smooth(s_mm: FloatArray, values: FloatArray, smooth_mm: float) -> FloatArray:
    """Savitzky-Golay (cubic) smoothing over ~smooth_mm of arc length."""
    n = len(values)
    step = float(np.median(np.diff(s_mm))) if n > 1 else 1.0
    window = int(round(smooth_mm / max(step, 1e-9))) | 1  # odd
    window = min(window, n if n % 2 else n - 1)
    if window < 5:
        return values.copy()
    return savgol_cubic(values, window)


def savgol_cubic(values: FloatArray, window: int) -> FloatArray:
    """Savitzky-Golay smoothing of (N,) values with a cubic over an odd ``window`` <= N.

    Each output is the least-squares cubic through the ``window`` samples centred
    on it, evaluated at its centre; within half a window of an end, the cubic
    through the first (last) ``window`` samples evaluated there (the "interp"
    edges of ``scipy.signal.savgol_filter``, which this equals; written out so
    that measuring does not import scipy.signal and scipy.stats).
    """
    values = np.asarray(values, dtype=float)
    half = window // 2
    hat = _savgol_hat(window)
    out = np.empty_like(values)
    out[half:len(values) - half] = np.lib.stride_tricks.sliding_window_view(
        values, window) @ hat[half]
    out[:half] = hat[:half] @ values[:window]
    out[len(values) - half:] = hat[window - half:] @ values[-window:]
    return out


@functools.lru_cache(maxsize=64)
def _savgol_hat(window: int) -> FloatArray:
    """(window, window) read-only matrix taking a window's samples to the values of their
    least-squares cubic (one per window length: the intervals' draws share it)."""
    z = np.arange(window, dtype=float) - window // 2
    vander = z[:, None] ** np.arange(4)  # (window, 4)
    hat = vander @ np.linalg.pinv(vander)
    hat.setflags(write=False)
    return hat


def _lesion_extent(s_mm: FloatArray, deficit: FloatArray, peak: int) -> tuple[float, float]:
    """Lesion edges (mm): twice the peak-to-half-maximum distance on each side."""
    half = 0.5 * deficit[peak]
    below = deficit < half
    left = np.flatnonzero(below[:peak])
    right = np.flatnonzero(below[peak + 1 :]) + peak + 1
    s_peak = s_mm[peak]
    if left.size:
        i = left[-1]  # deficit[i] < half <= deficit[i + 1]
        frac = (half - deficit[i]) / max(deficit[i + 1] - deficit[i], 1e-12)
        start = s_peak - 2.0 * (s_peak - (s_mm[i] + frac * (s_mm[i + 1] - s_mm[i])))
    else:
        start = s_mm[0]
    if right.size:
        i = right[0]  # deficit[i - 1] >= half > deficit[i]
        frac = (deficit[i - 1] - half) / max(deficit[i - 1] - deficit[i], 1e-12)
        end = s_peak + 2.0 * (s_mm[i - 1] + frac * (s_mm[i] - s_mm[i - 1]) - s_peak)
    else:
        end = s_mm[-1]
    return float(max(start, s_mm[0])), float(min(end, s_mm[-1]))


def _fit_line(s: FloatArray, d: FloatArray, keep: NDArray[np.bool_], degree: int) -> FloatArray:
    deg = degree if np.count_nonzero(keep) > 2 * (degree + 1) else 0
    coeffs = np.polyfit(s[keep], d[keep], deg)
    return np.polyval(coeffs, s)


def _reference(
    s_mm: FloatArray, d_mm: FloatArray, degree: int
) -> tuple[FloatArray, float, int | None]:
    """Robust reference line (M,), the disease threshold delta and the lesion peak index."""
    n = len(s_mm)
    keep = np.ones(n, dtype=bool)
    min_keep = max(3, int(0.3 * n))
    ref = _fit_line(s_mm, d_mm, keep, degree)
    delta = _DELTA_MIN
    for _ in range(_MAX_ITER):
        rel = d_mm / ref - 1.0
        kept = rel[keep]
        sigma = 1.4826 * float(np.median(np.abs(kept - np.median(kept))))
        delta = float(np.clip(2.5 * sigma, _DELTA_MIN, _DELTA_MAX))
        new_keep = (rel > -delta) & (rel < 2.0 * delta)
        if np.count_nonzero(new_keep) < min_keep or np.array_equal(new_keep, keep):
            break
        keep = new_keep
        ref = _fit_line(s_mm, d_mm, keep, degree)

    deficit = 1.0 - d_mm / ref
    peak = int(np.argmax(deficit))
    if deficit[peak] < delta:
        return ref, delta, None
    # Exclude the whole lesion from the final fit (its shoulders too), twice to settle.
    for _ in range(2):
        start, end = _lesion_extent(s_mm, deficit, peak)
        final_keep = keep & ((s_mm < start) | (s_mm > end))
        if np.count_nonzero(final_keep) < min_keep:
            break
        ref = _fit_line(s_mm, d_mm, final_keep, degree)
        deficit = 1.0 - d_mm / ref
        peak = int(np.argmax(deficit))
    return ref, delta, peak if deficit[peak] >= delta else None


def lumen_profile(
    s_mm: ArrayLike, area_mm2: ArrayLike, *, smooth_mm: float = 2.0, degree: int = 1
) -> LumenProfile:
    """Equivalent diameters and the interpolated reference along the vessel.

    Parameters
    ----------
    s_mm : (M,) increasing arc length of the 3D centerline, roughly uniform.
    area_mm2 : (M,) lumen cross-section areas (e.g. ``CrossSections.area_mm2``).
    smooth_mm : Savitzky-Golay window in mm (0 disables smoothing).
    degree : degree of the reference fit (1: linear taper).

    Returns
    -------
    LumenProfile
    """
    s = np.asarray(s_mm, dtype=float).ravel()
    area = np.asarray(area_mm2, dtype=float).ravel()
    if s.shape != area.shape or len(s) < 3:
        raise ValueError(
            f"s_mm and area_mm2 must be equal-length (M>=3,) arrays, got {s.shape}, {area.shape}"
        )
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(area))):
        raise ValueError("s_mm and area_mm2 must be finite")
    if np.any(np.diff(s) <= 0):
        raise ValueError("s_mm must be strictly increasing")
    if np.any(area <= 0):
        raise ValueError("area_mm2 must be positive")
    diameter = 2.0 * np.sqrt(area / np.pi)
    d_smooth = _smooth(s, diameter, smooth_mm) if smooth_mm > 0 else diameter.copy()
    a_smooth = _smooth(s, area, smooth_mm) if smooth_mm > 0 else area.copy()
    d_smooth = np.maximum(d_smooth, 1e-6)
    a_smooth = np.maximum(a_smooth, 1e-12)
    ref, delta, _ = _reference(s, d_smooth, degree)
    ref = np.maximum(ref, d_smooth.max() * 1e-3)
    return LumenProfile(
        s_mm=s,
        diameter_mm=diameter,
        area_mm2=area,
        reference_diameter_mm=ref,
        diameter_smooth_mm=d_smooth,
        area_smooth_mm2=a_smooth,
        threshold_rel=delta,
    )


END_MARGIN_MM = 2.0


def measure_lumen(profile: LumenProfile) -> Measurements:
    """3D QCA: MLD, reference, % stenosis, lesion extent (definitions in the module doc).

    Parameters
    ----------
    profile : from :func:`lumen_profile`.

    Returns
    -------
    Measurements
    """
    s = profile.s_mm
    d = profile.diameter_smooth_mm
    ref = profile.reference_diameter_mm
    deficit = 1.0 - d / ref
    # The clicked ends lie on healthy vessel; the first and last END_MARGIN_MM are
    # where a trace starts or fades, so the lesion's peak is not sought there
    # (unless the segment is too short to leave anything).
    search = (s >= s[0] + END_MARGIN_MM) & (s <= s[-1] - END_MARGIN_MM)
    if not np.any(search):
        search[:] = True
    peak = int(np.flatnonzero(search)[np.argmax(deficit[search])])
    if deficit[peak] >= profile.threshold_rel:
        start, end = _lesion_extent(s, deficit, peak)
        inside = (s >= start) & (s <= end)
        inside[peak] = True
    else:
        start = end = None
        inside = np.ones(len(s), dtype=bool)
    idx = np.flatnonzero(inside)
    i_mld = int(idx[np.argmin(d[idx])])
    mla = float(np.min(profile.area_smooth_mm2[idx]))
    mld = float(d[i_mld])
    s_mld = float(s[i_mld])
    ref_mld = float(ref[i_mld])
    ref_area = float(np.pi * ref_mld**2 / 4.0)
    if start is None:
        start = end = s_mld
    return Measurements(
        mld_mm=mld,
        mld_s_mm=s_mld,
        reference_diameter_mm=ref_mld,
        diameter_stenosis_pct=float(100.0 * (1.0 - mld / ref_mld)),
        area_stenosis_pct=float(100.0 * (1.0 - mla / ref_area)),
        lesion_start_s_mm=float(start),
        lesion_end_s_mm=float(end),
        lesion_length_mm=float(end - start),
        segment_length_mm=float(s[-1] - s[0]),
        mla_mm2=mla,
        reference_area_mm2=ref_area,
    )
