"""How an image's stored values relate to X-ray attenuation, per image.

The profile fit needs the absorption (the line integral of attenuation, up to
an affine map). Stored values are either linear in X-ray intensity (DICOM
PixelIntensityRelationship (0028,1040) "LIN": absorption = -log value), linear in
attenuation ("LOG": absorption = -value), or display-processed ("DISP", and the
non-standard "DRM" seen in real files: neither, exactly).

Both mappings are members of the Box-Cox family (Box & Cox, "An analysis of
transformations", JRSS B 1964) applied to the stored value I normalised by the
image's median: ``a_lambda(I) = -(I^lambda - 1) / lambda`` (lambda = 0: -log I, "lin";
lambda = 1: -I, "log").

:func:`resolve_mapping` decides "lin" or "log" for an image: the user's choice,
else the tag when it is LIN or LOG, else the quantum noise: the variance of
Poisson-limited values grows with the level when they are linear in intensity
and falls with it when they are linear in attenuation (var(c ln N) = c^2 / N);
this does not depend on the detector blur. When the background's levels span
too little for that, the vessel profiles decide (the Box-Cox profile likelihood:
residuals of the blurred-cylinder fits of ``a_lambda(I) / G^(lambda - 1)``, G = the
samples' geometric mean, comparable across lambda).

A profile's shape cannot tell a curved mapping from a wrong blur (a 0.1 px
blur error moves the best power by ~1), so the radius fit uses the mapping's
power; only for display-processed files, whose mapping is neither, does a
trace estimate the power (:func:`best_power`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recon.trace.profile_fit import parabola_vertex_offset

__all__ = [
    "IntensityMapping",
    "ValueScale",
    "resolve_mapping",
    "best_power",
    "best_blur",
    "best_enhancement",
    "tag_mapping",
    "noise_trend",
    "NoiseTrend",
    "is_display_processed",
    "absorption",
    "normalised_absorption",
    "geometric_mean",
    "POWER_OF",
    "INTENSITY_CHOICES",
]

FloatArray = NDArray[np.float64]

#: Box-Cox power of each mapping.
POWER_OF = {"lin": 0.0, "log": 1.0}
INTENSITY_CHOICES = ("auto", "lin", "log")
#: Powers searched along a trace (the fit's minimum is refined by a parabola).
POWER_GRID = (-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0)
#: Relative RSS penalty per unit^2 of power away from the mapping's (a weak prior:
#: it decides only where the profiles cannot, e.g. a faint vessel).
_PRIOR = 0.01
#: The vessel profiles decide only when one mapping's residual is this fraction above the
#: other's (a blur error alone moves them by tens of %).
_TIE = 0.5


@dataclass(frozen=True)
class IntensityMapping:
    """The chosen relation of stored values to attenuation.

    mapping : "lin" (values linear in X-ray intensity) or "log" (linear in attenuation).
    reason : one line saying why (override, tag, or what the profiles showed).
    log_gain : for "log", stored units per unit of ln(intensity) when the quantum
        noise told it (var = gain^2 / N falls as exp(-value / gain)), else None.
    """

    mapping: str
    reason: str
    log_gain: float | None = None


@dataclass(frozen=True)
class ValueScale:
    """Normalisation of stored values before the Box-Cox map: I_n = (I - offset) / ref,
    floored at ``floor`` (so zeros of a clipped 8-bit display do not diverge)."""

    offset: float
    ref: float
    floor: float

    @classmethod
    def of(cls, image: ArrayLike) -> ValueScale:
        img = np.asarray(image, dtype=float)
        sub = img[::4, ::4] if img.ndim == 2 and min(img.shape) >= 16 else img
        lo, med = float(np.min(img)), float(np.median(sub))
        span = max(float(np.max(img)) - lo, 1e-12)
        offset = 0.0 if lo >= 0 and med > 0 else lo - 0.01 * span
        ref = max(med - offset, 1e-12)
        return cls(offset=offset, ref=ref, floor=0.01)


def absorption(values: ArrayLike, power: float, scale: ValueScale) -> FloatArray:
    """Absorption ``a_lambda`` (same shape as ``values``) of stored values (module docstring)."""
    x = np.maximum((np.asarray(values, dtype=float) - scale.offset) / scale.ref, scale.floor)
    if abs(power) < 1e-9:
        return -np.log(x)
    return -(x**power - 1.0) / power


def geometric_mean(values: ArrayLike, scale: ValueScale) -> float:
    """Geometric mean G of the normalised values (the samples a fit will use)."""
    x = np.maximum((np.asarray(values, dtype=float) - scale.offset) / scale.ref, scale.floor)
    return float(np.exp(np.mean(np.log(x))))


def normalised_absorption(
    values: FloatArray, power: float, scale: ValueScale, geo_mean: float
) -> FloatArray:
    """``a_lambda(values) / G^(lambda - 1)``, G = ``geo_mean`` of the fitted samples
    (the Box-Cox normalisation that makes residuals comparable across powers)."""
    return absorption(values, power, scale) / geo_mean ** (power - 1.0)


def _aggregate(per_profile: list[FloatArray]) -> FloatArray:
    """Geometric mean of each power's residual variances over the profiles fitted at
    every power (each profile one vote: a few profiles crossed by another vessel
    do not decide). Returns (P,), inf when fewer than 5 profiles are common."""
    stack = np.vstack([np.asarray(r, dtype=float).reshape(-1) for r in per_profile])
    common = np.all(np.isfinite(stack) & (stack > 0), axis=0)
    if np.count_nonzero(common) < 5:
        return np.full(len(per_profile), np.inf)
    return np.exp(np.mean(np.log(stack[:, common]), axis=1))


def best_power(
    rss_of_power: Callable[[float], FloatArray], prior_power: float,
    grid: tuple[float, ...] = POWER_GRID,
) -> tuple[float, dict[float, float]]:
    """The Box-Cox power minimising the profiles' residuals (times a prior around
    ``prior_power``), on ``grid`` refined by a parabola.

    Parameters
    ----------
    rss_of_power : power -> residual variances (M,) of M profile fits (inf: no fit).
    prior_power : the mapping's power (0 lin, 1 log).

    Returns the power and the aggregated residual at every grid power.
    """
    powers = np.asarray(grid, dtype=float)
    rss = _aggregate([rss_of_power(float(p)) for p in powers])
    crit = rss * (1.0 + _PRIOR * (powers - prior_power) ** 2)
    if not np.all(np.isfinite(crit)):
        return float(prior_power), dict(zip(powers.tolist(), rss.tolist(), strict=True))
    k = int(np.argmin(crit))
    p = float(powers[k])
    if 0 < k < len(powers) - 1:
        f0, f1, f2 = crit[k - 1], crit[k], crit[k + 1]
        den = f0 - 2.0 * f1 + f2
        if den > 0:
            p += float(np.clip(0.5 * (f0 - f2) / den, -0.5, 0.5)) * float(powers[k + 1] - p)
    return p, dict(zip(powers.tolist(), rss.tolist(), strict=True))


#: Blur factors (x the nominal blur) searched along a trace.
BLUR_FACTORS = (0.6, 0.75, 0.9, 1.1, 1.35, 1.7, 2.2)
#: The blur search goes past the grid's top while the residual still falls there, one
#: step of the grid's last ratio at a time, at most this many steps, up to this blur.
#: Not below the grid: the lowest factor is already about the pixel aperture's own
#: blur (sigma sqrt(1/12) px), and on an edge-enhanced display a blur below it only
#: trades off against the enhancement (the fitted blur fell to 0.27 px for a true 0.62).
_BLUR_EXTRA_STEPS = 4
_BLUR_MAX_PX = 5.0
#: Step in ln blur of the final refinement around the grid's parabola vertex.
_BLUR_FINE_STEP = 0.08


def best_blur(
    rss_of_blur: Callable[[float], FloatArray], nominal_px: float,
    factors: tuple[float, ...] = BLUR_FACTORS,
) -> tuple[float, dict[float, float]]:
    """The model's Gaussian blur (px) minimising the profiles' residuals: a grid of
    ``factors`` x ``nominal_px``, refined by a parabola in log blur.

    A minimum at the grid's last blur is not a minimum: the grid is extended upwards
    (the last ratio, at most :data:`_BLUR_EXTRA_STEPS` steps, up to
    :data:`_BLUR_MAX_PX`) until the residual rises again, so that the parabola has a
    point on each side. The grid's first blur is a floor.

    Parameters
    ----------
    rss_of_blur : blur (px) -> residual variances (M,) of M profile fits (inf: no fit).
    nominal_px : the expected blur.

    Returns the blur and the aggregated residual at every blur evaluated.
    """
    blurs = [float(nominal_px) * float(f) for f in factors]
    per_blur = [rss_of_blur(b) for b in blurs]
    rss = _aggregate(per_blur)
    if not np.all(np.isfinite(rss)):
        return float(nominal_px), dict(zip(blurs, rss.tolist(), strict=True))
    for _ in range(_BLUR_EXTRA_STEPS):
        nxt = blurs[-1] * blurs[-1] / blurs[-2]
        if int(np.argmin(rss)) != len(blurs) - 1 or nxt > _BLUR_MAX_PX:
            break
        blurs.append(nxt)
        per_blur.append(rss_of_blur(nxt))
        extended = _aggregate(per_blur)
        if not np.all(np.isfinite(extended)):  # the new blur fits too few profiles
            blurs.pop()
            per_blur.pop()
            break
        rss = extended
    table = dict(zip(blurs, rss.tolist(), strict=True))
    k = int(np.argmin(rss))
    log_b = np.log(np.asarray(blurs))
    b = float(log_b[k])
    if 0 < k < len(blurs) - 1:
        f0, f1, f2 = rss[k - 1], rss[k], rss[k + 1]
        h0, h1 = log_b[k] - log_b[k - 1], log_b[k + 1] - log_b[k]
        # vertex of the parabola through three unevenly spaced points
        num = h0**2 * (f2 - f1) - h1**2 * (f0 - f1)
        den = h0 * (f2 - f1) + h1 * (f0 - f1)
        if den > 0 and np.isfinite(num / den):
            b += float(np.clip(-0.5 * num / den, -h0, h1))
        b = _refined_log_blur(rss_of_blur, b, table)
    return float(np.exp(b)), table


def _refined_log_blur(rss_of_blur: Callable[[float], FloatArray], log_b: float,
                      table: dict[float, float]) -> float:
    """ln blur refined by a parabola through three blurs :data:`_BLUR_FINE_STEP` apart
    in ln blur around ``log_b``: the grid's steps (~25 %) are too coarse for a parabola
    (the residual is not quadratic over them, and the vertex lands several % off the
    minimum); the new vertex stays within one step. Adds the three residuals to
    ``table``; ``log_b`` unchanged when they are not convex or fit too few profiles."""
    h = _BLUR_FINE_STEP
    blurs = [float(np.exp(log_b + d)) for d in (-h, 0.0, h)]
    f0, f1, f2 = _aggregate([rss_of_blur(b) for b in blurs])
    if not np.all(np.isfinite([f0, f1, f2])):
        return log_b
    table.update(zip(blurs, (float(f0), float(f1), float(f2)), strict=True))
    return log_b + h * float(parabola_vertex_offset(f0, f1, f2, limit=1.0))


#: Edge-enhancement gains and sigmas (px) searched along a trace of a display-processed
#: image (unsharp masks of ~1-3 mm at the detector: 2-20 px at 0.15-0.4 mm pixels).
ENHANCE_GAINS = (0.5, 0.75, 1.0, 1.5, 2.0, 3.0)
ENHANCE_SIGMAS_PX = (2.0, 2.8, 4.0, 5.6, 8.0, 11.0, 16.0)
#: An enhancement is kept only when it lowers the profiles' residual by this fraction
#: (two more parameters shared by the whole trace).
_ENHANCE_GAIN_MIN = 0.05


def best_enhancement(
    rss_of_enhance: Callable[[tuple[float, float]], FloatArray],
    gains: tuple[float, ...] = ENHANCE_GAINS, sigmas_px: tuple[float, ...] = ENHANCE_SIGMAS_PX,
) -> tuple[float, float]:
    """The edge enhancement (gain, sigma px) of an unsharp mask ``y + g (y - G_s * y)``
    that best explains a trace's profiles (:mod:`recon.trace.profile_fit`), on a grid; (0, 0)
    when none lowers the aggregated residual by :data:`_ENHANCE_GAIN_MIN`.

    rss_of_enhance : (gain, sigma px) -> residual variances (M,) (inf: no fit).
    """
    grid = [(0.0, 0.0)] + [(g, s) for g in gains for s in sigmas_px]
    rss = _aggregate([rss_of_enhance(e) for e in grid])
    if not np.isfinite(rss[0]):
        return 0.0, 0.0
    k = int(np.argmin(np.where(np.isfinite(rss), rss, np.inf)))
    if k == 0 or rss[k] > (1.0 - _ENHANCE_GAIN_MIN) * rss[0]:
        return 0.0, 0.0
    return grid[k]


def tag_mapping(relationship: str | None) -> str | None:
    """"lin" or "log" when the PixelIntensityRelationship says LIN or LOG, else None."""
    tag = (relationship or "").strip().upper()
    return {"LIN": "lin", "LOG": "log"}.get(tag)


def is_display_processed(relationship: str | None) -> bool:
    """True when the tag is present but neither LIN nor LOG (DISP, DRM, ...)."""
    tag = (relationship or "").strip().upper()
    return bool(tag) and tag not in ("LIN", "LOG")


@dataclass(frozen=True)
class NoiseTrend:
    """How the background's noise variance changes with its level.

    change : change of ln(variance) from the 5th to the 95th percentile level
        (fitted line through the binned medians).
    t_value : that slope over its standard error.
    n_bins : level bins used.
    slope : d ln(variance) / d level (per stored unit).
    """

    change: float
    t_value: float
    n_bins: int
    slope: float = 0.0


def noise_trend(image: ArrayLike, vesselness=None) -> NoiseTrend | None:
    """Noise variance against level over the flat background of an image.

    High-pass residual (image - Gaussian 1.5 px) squared and smoothed (4 px) is
    the local variance; the local mean (4 px) the level. Pixels on or near a
    vessel (response >= 0.2, dilated 4 px), outside the field or on the steeper
    half of the background's gradients are left out. Levels are cut into 10
    quantile bins; ln(median variance) is fitted linearly against the median
    level. None when fewer than 5 bins have 20 pixels (of every other row and
    column).
    """
    import cv2

    from recon.trace.vesselness import compute_vesselness

    img = np.asarray(image, dtype=np.float32)
    vmap = compute_vesselness(img) if vesselness is None else vesselness
    hp = img - cv2.GaussianBlur(img, (0, 0), 1.5)
    var = cv2.GaussianBlur(hp * hp, (0, 0), 4.0)
    mean = cv2.GaussianBlur(img, (0, 0), 4.0)
    grad = np.hypot(cv2.Sobel(mean, cv2.CV_32F, 1, 0), cv2.Sobel(mean, cv2.CV_32F, 0, 1)) / 8
    ridge = vmap.response if vmap.ridge is None else vmap.ridge
    near_vessel = cv2.dilate((ridge > 0.2).astype(np.uint8), np.ones((9, 9), np.uint8))
    ok = vmap.valid & (near_vessel == 0)
    if np.count_nonzero(ok) < 500:
        return None
    ok &= grad <= np.percentile(grad[ok][::4], 50.0)
    ok[1::2, :] = False  # every other row and column: neighbours carry the same
    ok[:, 1::2] = False  # smoothed values
    m, v = mean[ok].astype(float), var[ok].astype(float)
    edges = np.quantile(m, np.linspace(0.05, 0.95, 11))
    idx = np.digitize(m, edges)
    mm, vv = [], []
    for k in range(1, len(edges)):  # 10 bins
        sel = idx == k
        if np.count_nonzero(sel) >= 20:
            mm.append(float(np.median(m[sel])))
            vv.append(float(np.median(v[sel])))
    if len(mm) < 5 or min(vv) <= 0 or np.ptp(mm) <= 0:
        return None
    x, y = np.asarray(mm), np.log(np.asarray(vv))
    a = np.column_stack([np.ones_like(x), x])
    coef, *_ = np.linalg.lstsq(a, y, rcond=None)
    resid = y - a @ coef
    dof = max(len(x) - 2, 1)
    se = np.sqrt(max(float(resid @ resid) / dof, 1e-30) / max(float(np.sum((x - x.mean()) ** 2)),
                                                              1e-30))
    span = float(edges[-1] - edges[0])
    return NoiseTrend(change=float(coef[1]) * span, t_value=float(coef[1] / se), n_bins=len(x),
                      slope=float(coef[1]))


#: The noise trend decides when ln(variance) changes by at least this much over the
#: background's levels and the slope is this many standard errors from zero.
_TREND_MIN_CHANGE = 0.15
_TREND_MIN_T = 4.0


def _log_gain(image: ArrayLike, vesselness) -> float | None:
    """Stored units per unit of ln(intensity) of values linear in attenuation, from a
    clearly falling noise trend (var = gain^2 / N), or None."""
    trend = noise_trend(image, vesselness)
    if trend is None or trend.slope >= 0 or abs(trend.t_value) < _TREND_MIN_T \
            or abs(trend.change) < _TREND_MIN_CHANGE:
        return None
    return -1.0 / trend.slope


def resolve_mapping(
    image: ArrayLike,
    relationship: str | None,
    override: str = "auto",
    *,
    rss_of_power: Callable[[float], FloatArray] | None = None,
    vesselness=None,
    blur_px: float = 0.7,
) -> IntensityMapping:
    """Decide "lin" or "log" for one image (module docstring).

    Parameters
    ----------
    image : (H, W) stored values, MONOCHROME2 (the whole image: the noise trend
        needs its background).
    relationship : PixelIntensityRelationship (0028,1040) of the file, or None.
    override : "lin", "log" (the user's choice) or "auto".
    rss_of_power : optional callable giving the Jacobian-normalised residual
        variances (M,) of M vessel profile fits at a Box-Cox power (a trace supplies
        its own profiles); None: profiles at the strongest ridge pixels.
    vesselness : the image's VesselnessMap (computed with default scales when None).
    blur_px : detector blur (px) of the profile model.

    Returns
    -------
    IntensityMapping with the mapping and a one-line reason.
    """
    choice = (override or "auto").strip().lower()
    if choice not in INTENSITY_CHOICES:
        raise ValueError(f"intensity must be one of {', '.join(INTENSITY_CHOICES)}, "
                         f"got {override!r}")
    tag = (relationship or "").strip().upper() or None
    if choice != "auto":
        return IntensityMapping(choice, f"set by the user ({choice})",
                                log_gain=_log_gain(image, vesselness) if choice == "log" else None)
    by_tag = tag_mapping(relationship)
    if by_tag is not None:
        return IntensityMapping(by_tag, f"PixelIntensityRelationship is {tag}",
                                log_gain=_log_gain(image, vesselness) if by_tag == "log" else None)
    said = f"PixelIntensityRelationship is {tag}" if tag else "no PixelIntensityRelationship"
    img = np.asarray(image, dtype=float)
    if vesselness is None:
        from recon.trace.vesselness import compute_vesselness

        vesselness = compute_vesselness(img)
    trend = noise_trend(img, vesselness)
    if (trend is not None and abs(trend.change) >= _TREND_MIN_CHANGE
            and abs(trend.t_value) >= _TREND_MIN_T):
        mapping = "lin" if trend.change > 0 else "log"
        how = "grows" if trend.change > 0 else "falls"
        what = "X-ray intensity" if mapping == "lin" else "attenuation"
        return IntensityMapping(
            mapping, f"{said}; the background's noise variance {how} with its level "
            f"(ln var changes by {trend.change:+.2f}, t = {trend.t_value:.1f}): values "
            f"linear in {what}",
            log_gain=None if mapping == "lin" else -1.0 / trend.slope)
    if rss_of_power is None:
        rss_of_power = _ridge_rss(img, vesselness, blur_px)
    if rss_of_power is None:
        return IntensityMapping("lin", f"{said}, the noise does not tell and no vessel "
                                "profiles to compare; lin assumed")
    rss_lin, rss_log = _aggregate([rss_of_power(0.0), rss_of_power(1.0)])
    if not (np.isfinite(rss_lin) and np.isfinite(rss_log)):
        return IntensityMapping("lin", f"{said}, the noise does not tell and the profiles "
                                "could not be fitted; lin assumed")
    rel = (rss_lin - rss_log) / max(min(rss_lin, rss_log), 1e-300)
    if abs(rel) < _TIE:
        return IntensityMapping(
            "lin", f"{said}; neither the noise nor the vessel profiles tell the mappings "
            f"apart (residuals {rss_lin:.3g} lin, {rss_log:.3g} log); lin assumed")
    mapping = "log" if rel > 0 else "lin"
    what = "attenuation" if mapping == "log" else "X-ray intensity"
    return IntensityMapping(
        mapping, f"{said}; the noise does not tell, vessel profiles fit values linear in "
        f"{what} better (residuals {rss_lin:.3g} lin, {rss_log:.3g} log)")


def _ridge_rss(image: FloatArray, vesselness, blur_px: float,
               n_max: int = 400) -> Callable[[float], FloatArray] | None:
    """RSS-of-power callable on profiles across the strongest ridge pixels of an image."""
    from recon.trace.profile_fit import fit_along, half_width_for, sample_profiles
    from recon.trace.vesselness import RADIUS_PER_SIGMA, compute_vesselness

    vmap = compute_vesselness(image) if vesselness is None else vesselness
    if vmap.strength is None or vmap.direction_rad is None:
        return None
    sel = ((vmap.response if vmap.ridge is None else vmap.ridge) >= 0.5) & vmap.valid
    rows, cols = np.nonzero(sel)
    if len(rows) < 20:
        return None
    order = np.argsort(-vmap.strength[rows, cols])[: 4 * n_max]
    order = order[:: max(len(order) // n_max, 1)]
    rows, cols = rows[order], cols[order]
    pts = np.column_stack([cols, rows]).astype(float)
    th = vmap.direction_rad[rows, cols].astype(float)
    normals = np.column_stack([-np.sin(th), np.cos(th)])
    radius = RADIUS_PER_SIGMA * vmap.scale_px[rows, cols].astype(float)
    scale = ValueScale.of(image)
    reach = np.linspace(-1.0, 1.0, 41) * half_width_for(float(np.median(radius)))
    g = geometric_mean(sample_profiles(image, pts, normals, reach), scale)

    def rss(power: float) -> float:
        fit = fit_along(image, pts, normals, radius, blur_px, 0.25,
                        transform=lambda p: normalised_absorption(p, power, scale, g))
        return np.where(fit.ok, fit.rss, np.inf)

    return rss
