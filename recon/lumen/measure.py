"""Quantitative coronary analysis (QCA) on the 3D lumen.

The lumen is described along the 3D centerline's arc length s (free of
foreshortening) by the cross-section areas of sec. 3.5; each area gives an
equivalent circular diameter d(s) = 2 sqrt(A / pi).

Definitions used here (documented because QCA packages differ):

- Smoothing: d(s) and A(s) are lightly smoothed by a Savitzky-Golay filter
  (cubic, window ``smooth_mm``, 2 mm by default) that leaves a smooth minimum
  unbiased.
- Trusted stretch: the first and last :data:`END_ZONE_MM` of a segment (at most
  :data:`END_ZONE_FRACTION` of its length each) are where a clicked end lies, a
  trace starts or a contrast column fades; a branch measured from its carina has,
  instead of the proximal end zone, its ostium zone (where the parent's lumen lies
  within the 2D radius fits' reach, :func:`recon.lumen.lesions.ostium_zone_end_s_mm`).
  The rest of the segment is the trusted stretch.
- Reference diameter: a robust straight-line fit of d(s) over the trusted stretch
  (the tapering "interpolated reference" of QCA), extended over the zones. Points
  whose relative deviation from the fit is below -delta (narrowed) or above
  +2 delta are excluded and the fit is repeated until it settles;
  delta = clip(2.5 sigma, 5 %, 15 %), sigma the robust (MAD) relative scatter of
  the kept points. Every narrowing found below is excluded as a whole from the
  final fit.
- Narrowings: peeled off the relative deficit 1 - d / ref, deepest first. Each
  is located at a peak of the deficit of at least delta; its edges are placed at
  twice the distance from the peak to where the deficit falls to half its peak
  value (for a raised-cosine narrowing, the phantom's
  r = r_ref (1 - p (1 + cos(2 pi (s - s0) / L)) / 2), exactly s0 +- L / 2, and
  unlike a fixed threshold independent of the severity; for other shapes the
  extent of the equivalent cosine). A peak is a narrowing of its own only when
  the deficit falls below half its peak value before reaching a deeper one's
  peak (otherwise it is that narrowing's shoulder); edges that would overlap a
  deeper narrowing's stop at it.
- Lesion: a narrowing of at least :data:`MIN_LESION_DS_PCT` % diameter stenosis
  (and of a deficit at least delta) whose peak lies in the trusted stretch, or,
  peaking inside a zone, whose narrowing the trusted profile supports: its core
  reaches into the trusted stretch (its own extent reaches the zone's inner edge, and
  the deficit there is still at least half its peak value, and at least delta; a
  deeper neighbour's deficit at the edge does not support it). A narrowing confined
  to a zone is reported as unsupported, not as a lesion.
- Tandem narrowings: lesions separated by less than :data:`TANDEM_GAP_RVD` reference
  diameters (the gap between one's end and the next one's start, the reference there
  the mean of their two) are one lesion, as the SYNTAX score counts them (Sianos et
  al., EuroIntervention 2005;1:219-227: lesions within 3 vessel reference diameters
  of each other are scored as one). The lesion spans its narrowings; its MLD, MLA,
  reference and % stenoses are those of its most severe narrowing
  (:func:`lesions_of`). Two minima of one diseased stretch, or a shoulder that the
  click noise lifts above or below the floor, are thus not separate lesions that
  come and go (issue 46).
- MLD / MLA: the minima of the smoothed diameter / area inside a narrowing. The
  measurements (:class:`Measurements`) are the most severe lesion's (by % diameter
  stenosis); with no lesion, the minima over the trusted stretch. % diameter
  stenosis = 100 (1 - MLD / ref(s_MLD)), % area stenosis =
  100 (1 - MLA / ref_area(s_MLD)) with ref_area = pi ref^2 / 4.
- Segment length: the 3D arc length s[-1] - s[0].

:data:`MIN_LESION_DS_PCT` is 25 %: the lower bound of a "mild" stenosis in the
CAD-RADS 2.0 grading (Cury et al., JACC Cardiovasc Imaging 2022; 1-24 % is
"minimal"), so a luminal irregularity near the disease threshold is not a lesion
that comes and goes with the click noise.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, fields, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]

__all__ = [
    "Measurements",
    "LumenProfile",
    "Narrowing",
    "lumen_profile",
    "measure_lumen",
    "narrowings",
    "lesions_of",
    "tandem_groups",
    "END_ZONE_MM",
    "TANDEM_GAP_RVD",
    "MIN_LESION_DS_PCT",
]

_DELTA_MIN = 0.05  # smallest relative deviation treated as disease
_DELTA_MAX = 0.15
_MAX_ITER = 30
#: Length (mm) of the zone at each clicked end where a narrowing needs the trusted
#: profile's support to be a lesion (module docstring).
END_ZONE_MM = 5.0
#: An end zone is at most this fraction of the segment's length.
END_ZONE_FRACTION = 0.2
#: Least % diameter stenosis of a lesion (module docstring).
MIN_LESION_DS_PCT = 25.0
#: Lesions closer than this many reference diameters are one lesion (module docstring).
TANDEM_GAP_RVD = 3.0
_MIN_TRUSTED_POINTS = 12


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
        relative deficit below it is not a narrowing.
    trusted_from_s_mm, trusted_to_s_mm : the trusted stretch (module docstring);
        None: the profile's first / last arc length (no zone).
    ostium : True when the zone before ``trusted_from_s_mm`` is a branch's ostium
        (measured from its carina), not a clicked end.
    """

    s_mm: FloatArray
    diameter_mm: FloatArray
    area_mm2: FloatArray
    reference_diameter_mm: FloatArray
    diameter_smooth_mm: FloatArray
    area_smooth_mm2: FloatArray
    threshold_rel: float = _DELTA_MIN
    trusted_from_s_mm: float | None = None
    trusted_to_s_mm: float | None = None
    ostium: bool = False

    def smooth_radius_at(self, s_mm: ArrayLike) -> FloatArray:
        """The smoothed lumen radius (mm) at arc lengths ``s_mm`` (held constant beyond
        the profile's ends): half of ``diameter_smooth_mm``, interpolated."""
        return np.interp(np.asarray(s_mm, dtype=float), self.s_mm, self.diameter_smooth_mm) / 2.0

    @property
    def relative_deficit(self) -> FloatArray:
        """(M,) 1 - smoothed diameter / reference (positive where narrowed)."""
        return 1.0 - self.diameter_smooth_mm / self.reference_diameter_mm

    @property
    def trusted_range_mm(self) -> tuple[float, float]:
        """(first, last) arc length of the trusted stretch."""
        lo = self.s_mm[0] if self.trusted_from_s_mm is None else self.trusted_from_s_mm
        hi = self.s_mm[-1] if self.trusted_to_s_mm is None else self.trusted_to_s_mm
        return float(lo), float(hi)

    @property
    def trusted(self) -> NDArray[np.bool_]:
        """(M,) True on the trusted stretch."""
        lo, hi = self.trusted_range_mm
        return (self.s_mm >= lo) & (self.s_mm <= hi)


@dataclass(frozen=True)
class Narrowing:
    """One narrowing of the lumen profile (module docstring); mm along the 3D centerline.

    Attributes
    ----------
    peak_s_mm : arc length of the deficit's peak.
    start_s_mm, end_s_mm : its edges; length_mm = end - start.
    mld_mm, mld_s_mm : least smoothed diameter inside it and where.
    reference_diameter_mm : the reference at the MLD.
    diameter_stenosis_pct, area_stenosis_pct : as :class:`Measurements`.
    mla_mm2, reference_area_mm2 : least smoothed area inside it; pi ref^2 / 4.
    zone : "" (peak in the trusted stretch), "ostium", "proximal end" or "distal end".
    supported : True when it is a lesion (module docstring).
    """

    peak_s_mm: float
    start_s_mm: float
    end_s_mm: float
    length_mm: float
    mld_mm: float
    mld_s_mm: float
    reference_diameter_mm: float
    diameter_stenosis_pct: float
    area_stenosis_pct: float
    mla_mm2: float
    reference_area_mm2: float
    zone: str
    supported: bool

    def measurements(self, segment_length_mm: float) -> Measurements:
        """This narrowing as the segment's :class:`Measurements`."""
        return Measurements(
            mld_mm=self.mld_mm, mld_s_mm=self.mld_s_mm,
            reference_diameter_mm=self.reference_diameter_mm,
            diameter_stenosis_pct=self.diameter_stenosis_pct,
            area_stenosis_pct=self.area_stenosis_pct,
            lesion_start_s_mm=self.start_s_mm, lesion_end_s_mm=self.end_s_mm,
            lesion_length_mm=self.length_mm, segment_length_mm=segment_length_mm,
            mla_mm2=self.mla_mm2, reference_area_mm2=self.reference_area_mm2,
        )

    def to_dict(self) -> dict[str, float | str | bool]:
        """JSON-ready dict of the fields."""
        return {f.name: (getattr(self, f.name) if f.name in ("zone", "supported")
                         else float(getattr(self, f.name))) for f in fields(self)}


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


def _half_run(deficit: FloatArray, peak: int) -> tuple[int, int]:
    """[i, j) of the contiguous run around ``peak`` where the deficit is at least half
    its peak value."""
    low = deficit < 0.5 * deficit[peak]
    left = np.flatnonzero(low[:peak])
    right = np.flatnonzero(low[peak + 1:])
    return (int(left[-1]) + 1 if left.size else 0,
            int(right[0]) + peak + 1 if right.size else len(deficit))


def _peel(s_mm: FloatArray, deficit: FloatArray, delta: float) -> list[tuple[int, float, float]]:
    """Every narrowing (peak index, start mm, end mm), deepest first (module docstring)."""
    claimed = np.zeros(len(s_mm), dtype=bool)
    found: list[tuple[int, float, float]] = []
    while not claimed.all():
        peak = int(np.argmax(np.where(claimed, -np.inf, deficit)))
        if deficit[peak] < delta:
            break
        i, j = _half_run(deficit, peak)
        start, end = _lesion_extent(s_mm, deficit, peak)
        claimed |= (s_mm >= start) & (s_mm <= end)
        claimed[i:j] = True
        claimed[peak] = True
        if any(i <= p < j for p, _, _ in found):
            continue  # the shoulder of a deeper narrowing
        for p, a, b in found:  # stop at a deeper neighbour's edge
            if p < peak:
                start = max(start, b)
            else:
                end = min(end, a)
        found.append((peak, start, max(end, start)))
    return found


def _fit_line(s: FloatArray, d: FloatArray, keep: NDArray[np.bool_], degree: int) -> FloatArray:
    deg = degree if np.count_nonzero(keep) > 2 * (degree + 1) else 0
    coeffs = np.polyfit(s[keep], d[keep], deg)
    return np.polyval(coeffs, s)


def _reference(
    s_mm: FloatArray, d_mm: FloatArray, degree: int, trusted: NDArray[np.bool_]
) -> tuple[FloatArray, float]:
    """Robust reference line (M,) fitted on the trusted points, and the disease
    threshold delta."""
    n = len(s_mm)
    if np.count_nonzero(trusted) < _MIN_TRUSTED_POINTS:
        trusted = np.ones(n, dtype=bool)
    keep = trusted.copy()
    min_keep = max(3, int(0.3 * np.count_nonzero(trusted)))
    ref = _fit_line(s_mm, d_mm, keep, degree)
    delta = _DELTA_MIN
    for _ in range(_MAX_ITER):
        rel = d_mm / ref - 1.0
        kept = rel[keep]
        sigma = 1.4826 * float(np.median(np.abs(kept - np.median(kept))))
        delta = float(np.clip(2.5 * sigma, _DELTA_MIN, _DELTA_MAX))
        new_keep = trusted & (rel > -delta) & (rel < 2.0 * delta)
        if np.count_nonzero(new_keep) < min_keep or np.array_equal(new_keep, keep):
            break
        keep = new_keep
        ref = _fit_line(s_mm, d_mm, keep, degree)
    # Exclude every narrowing as a whole from the final fit (its shoulders too), twice
    # to settle.
    for _ in range(2):
        deficit = 1.0 - d_mm / ref
        found = _peel(s_mm, deficit, delta)
        if not found:
            break
        final_keep = keep.copy()
        for _, start, end in found:
            final_keep &= (s_mm < start) | (s_mm > end)
        if np.count_nonzero(final_keep) < min_keep:
            break
        ref = _fit_line(s_mm, d_mm, final_keep, degree)
    return ref, delta


def _trusted_range(s: FloatArray, end_zone_mm: float,
                   ostium_end_s_mm: float | None) -> tuple[float, float]:
    """The trusted stretch (first, last arc length) of a profile."""
    length = float(s[-1] - s[0])
    zone = min(end_zone_mm, END_ZONE_FRACTION * length)
    lo = s[0] + zone
    if ostium_end_s_mm is not None:
        lo = min(max(float(ostium_end_s_mm), float(s[0])), s[0] + 0.5 * length)
    return float(lo), float(s[-1] - zone)


def lumen_profile(
    s_mm: ArrayLike, area_mm2: ArrayLike, *, smooth_mm: float = 2.0, degree: int = 1,
    end_zone_mm: float = END_ZONE_MM, ostium_end_s_mm: float | None = None,
) -> LumenProfile:
    """Equivalent diameters and the interpolated reference along the vessel.

    Parameters
    ----------
    s_mm : (M,) increasing arc length of the 3D centerline, roughly uniform.
    area_mm2 : (M,) lumen cross-section areas (e.g. ``CrossSections.area_mm2``).
    smooth_mm : Savitzky-Golay window in mm (0 disables smoothing).
    degree : degree of the reference fit (1: linear taper).
    end_zone_mm : the zone at each clicked end (module docstring; 0: none).
    ostium_end_s_mm : a branch measured from its carina: where its ostium zone ends
        (replaces the proximal end zone; at most half the profile's length).

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
    lo, hi = _trusted_range(s, end_zone_mm, ostium_end_s_mm)
    ref, delta = _reference(s, d_smooth, degree, (s >= lo) & (s <= hi))
    ref = np.maximum(ref, d_smooth.max() * 1e-3)
    return LumenProfile(
        s_mm=s,
        diameter_mm=diameter,
        area_mm2=area,
        reference_diameter_mm=ref,
        diameter_smooth_mm=d_smooth,
        area_smooth_mm2=a_smooth,
        threshold_rel=delta,
        trusted_from_s_mm=lo,
        trusted_to_s_mm=hi,
        ostium=ostium_end_s_mm is not None,
    )


def _narrowing(profile: LumenProfile, start: float, end: float, peak: int, zone: str,
               supported: bool) -> Narrowing:
    s, d = profile.s_mm, profile.diameter_smooth_mm
    inside = (s >= start) & (s <= end)
    inside[peak] = True
    idx = np.flatnonzero(inside)
    i_mld = int(idx[np.argmin(d[idx])])
    return _figures(profile, i_mld, float(np.min(profile.area_smooth_mm2[idx])), start, end,
                    float(s[peak]), zone, supported)


def _figures(profile: LumenProfile, i_mld: int, mla: float, start: float, end: float,
             peak_s: float, zone: str, supported: bool) -> Narrowing:
    mld = float(profile.diameter_smooth_mm[i_mld])
    ref_mld = float(profile.reference_diameter_mm[i_mld])
    ref_area = float(np.pi * ref_mld**2 / 4.0)
    return Narrowing(
        peak_s_mm=peak_s, start_s_mm=float(start), end_s_mm=float(end),
        length_mm=float(end - start), mld_mm=mld, mld_s_mm=float(profile.s_mm[i_mld]),
        reference_diameter_mm=ref_mld, diameter_stenosis_pct=float(100.0 * (1.0 - mld / ref_mld)),
        area_stenosis_pct=float(100.0 * (1.0 - mla / ref_area)), mla_mm2=mla,
        reference_area_mm2=ref_area, zone=zone, supported=supported,
    )


def narrowings(profile: LumenProfile, min_ds_pct: float = MIN_LESION_DS_PCT
               ) -> tuple[Narrowing, ...]:
    """Every narrowing of the profile of at least ``min_ds_pct`` % diameter stenosis,
    proximal to distal, each marked ``supported`` (a lesion) or not (module docstring)."""
    s = profile.s_mm
    deficit = profile.relative_deficit
    delta = profile.threshold_rel
    lo, hi = profile.trusted_range_mm
    out = []
    for peak, start, end in _peel(s, deficit, delta):
        zone = ("" if lo <= s[peak] <= hi else
                ("ostium" if profile.ostium else "proximal end") if s[peak] < lo
                else "distal end")
        edge = lo if s[peak] < lo else hi
        reaches = start <= edge <= end  # its own extent reaches the trusted stretch
        supported = not zone or (reaches and float(np.interp(edge, s, deficit)) >= max(
            delta, 0.5 * float(deficit[peak])))
        n = _narrowing(profile, start, end, peak, zone, supported)
        if n.diameter_stenosis_pct >= min_ds_pct:
            out.append(n)
    return tuple(sorted(out, key=lambda n: n.peak_s_mm))


def tandem_groups(found: tuple[Narrowing, ...] | list[Narrowing],
                  gap_rvd: float = TANDEM_GAP_RVD) -> list[tuple[Narrowing, ...]]:
    """The lesions ``found`` (proximal to distal) grouped into tandems: consecutive ones
    whose gap (next start - previous end, mm) is less than ``gap_rvd`` times the mean of
    their reference diameters share a group (module docstring)."""
    groups: list[list[Narrowing]] = []
    for n in sorted(found, key=lambda n: n.peak_s_mm):
        if groups:
            prev = groups[-1][-1]
            rvd = 0.5 * (prev.reference_diameter_mm + n.reference_diameter_mm)
            if n.start_s_mm - prev.end_s_mm < gap_rvd * rvd:
                groups[-1].append(n)
                continue
        groups.append([n])
    return [tuple(g) for g in groups]


def merge_tandem(group: tuple[Narrowing, ...]) -> Narrowing:
    """One lesion from a tandem group: its most severe narrowing's figures (MLD, MLA,
    reference, % stenoses, zone) over the group's whole extent."""
    main = max(group, key=lambda n: n.diameter_stenosis_pct)
    if len(group) == 1:
        return main
    start = min(n.start_s_mm for n in group)
    end = max(n.end_s_mm for n in group)
    return replace(main, start_s_mm=start, end_s_mm=end, length_mm=end - start,
                   zone=main.zone if all(n.zone for n in group) else "")


def lesions_of(profile: LumenProfile, min_ds_pct: float = MIN_LESION_DS_PCT
               ) -> tuple[Narrowing, ...]:
    """The lesions of the profile, proximal to distal: its supported narrowings of at least
    ``min_ds_pct`` % diameter stenosis, tandems merged (module docstring)."""
    return tuple(merge_tandem(g) for g in tandem_groups(
        [n for n in narrowings(profile, min_ds_pct) if n.supported]))


def measure_lumen(profile: LumenProfile) -> Measurements:
    """3D QCA: MLD, reference, % stenosis, lesion extent of the most severe lesion, or
    the trusted stretch's minima when there is none (definitions in the module doc).

    Parameters
    ----------
    profile : from :func:`lumen_profile`.

    Returns
    -------
    Measurements
    """
    s = profile.s_mm
    length = float(s[-1] - s[0])
    lesions = lesions_of(profile)
    if lesions:
        return max(lesions, key=lambda n: n.diameter_stenosis_pct).measurements(length)
    trusted = profile.trusted
    idx = np.flatnonzero(trusted) if trusted.any() else np.arange(len(s))
    i_mld = int(idx[np.argmin(profile.diameter_smooth_mm[idx])])
    mla = float(np.min(profile.area_smooth_mm2[idx]))
    s_mld = float(s[i_mld])
    return _figures(profile, i_mld, mla, s_mld, s_mld, s_mld, "", False).measurements(length)
