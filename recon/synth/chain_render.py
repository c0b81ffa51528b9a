"""Rendering one view through an imaging chain (:mod:`recon.synth.chains`).

The physics is the plain renderer's (:mod:`recon.synth.render`: exact
Beer-Lambert line integrals through the union of truncated cones), with
the chain's detector, background, guiding catheter, scatter / glare,
dose, blur and display mapping::

    primary  = N0 exp(-background) exp(-iodine - catheter - lead) collimator
    expected = primary + k G_wide(primary),  k = f / (1 - f)   (scatter / glare)
    counts   = G_blur(Poisson(expected))
    stored   = display(counts / N0)            (then a JPEG encode / decode, if any)

In a chain's faint view the iodine is scaled by the factor that puts the
vessels' noise-free stored contrast at the drawn grey levels (found on the
noise-free images, before the noise is drawn, so the random draws of the
view are those of an ordinary one).

Supersampling keeps the sub-pixel at most 0.2 mm wide (2 x 2 rays per
pixel above 0.2 mm, one ray at or below it); with one ray per pixel the
pixel's box aperture is folded into the Gaussian blur (variance 1/12 px^2),
so blur_px is the detector's blur beyond its pixel aperture either way.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from recon.geometry import ViewGeometry
from recon.synth.anatomy import Catheter, Lead
from recon.synth.background import background_attenuation, collimator_mask
from recon.synth.chains import ChainDraw, display_values, jpeg_roundtrip
from recon.synth.render import (
    MU_DISTAL_FRACTION,
    MU_PROXIMAL_PER_MM,
    PHOTONS_PER_PIXEL,
    _attenuation_subpixels,
    _block_mean,
    _cone_chain,
    vessel_attenuations,
)

__all__ = ["render_chain_view", "supersample_for", "REFERENCE_PIXEL_MM"]

FloatArray = NDArray[np.float64]

REFERENCE_PIXEL_MM = 0.390625  # the plain phantom's pixel, where N0 = PHOTONS_PER_PIXEL
MAX_SUBPIXEL_MM = 0.2
CATHETER_CONTRAST = (1.2, 1.6)  # catheter lumen / vessel attenuation (undiluted contrast)
CATHETER_WALL = 0.25  # catheter wall / vessel attenuation (polymer with a steel braid)
CATHETER_FIELD_MARGIN = 0.05  # the catheter is rendered up to 5 % of the size past the edge


def supersample_for(spacing_mm: float) -> int:
    """Rays per pixel along each axis that keep the sub-pixel at most 0.2 mm (1 or 2)."""
    return 2 if spacing_mm > MAX_SUBPIXEL_MM + 1e-9 else 1


def _catheter_in_view(view: ViewGeometry, X: FloatArray) -> FloatArray:
    """The catheter from its tip up to where it leaves the (slightly enlarged) image."""
    p = view.project(X)
    depth = view.depth_mm(X)
    mx, my = CATHETER_FIELD_MARGIN * view.cols, CATHETER_FIELD_MARGIN * view.rows
    inside = ((p[:, 0] > -mx) & (p[:, 0] < view.cols - 1 + mx) & (p[:, 1] > -my)
              & (p[:, 1] < view.rows - 1 + my) & (depth > 0))
    out = np.flatnonzero(~inside)
    end = int(out[0]) if len(out) else len(X)
    return X[: max(end + 1, 2)]


def _lead_in_view(view: ViewGeometry, X: FloatArray) -> FloatArray:
    """The lead's stretch from its first to its last point inside the enlarged image."""
    p = view.project(X)
    mx, my = CATHETER_FIELD_MARGIN * view.cols, CATHETER_FIELD_MARGIN * view.rows
    inside = np.flatnonzero((p[:, 0] > -mx) & (p[:, 0] < view.cols - 1 + mx) & (p[:, 1] > -my)
                            & (p[:, 1] < view.rows - 1 + my) & (view.depth_mm(X) > 0))
    if len(inside) < 2:
        return X[:2]
    return X[inside[0] : inside[-1] + 1]


def _wide_blur(img: FloatArray, sigma_px: float) -> FloatArray:
    """Gaussian blur of a wide kernel, computed on a grid coarsened by ~sigma / 4."""
    f = max(1, int(sigma_px / 4))
    h, w = img.shape
    small = cv2.resize(img, (max(w // f, 1), max(h // f, 1)), interpolation=cv2.INTER_AREA)
    small = ndimage.gaussian_filter(small, sigma_px / f, mode="nearest")
    return cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)


def render_chain_view(
    rng: np.random.Generator,
    view: ViewGeometry,
    vessels: Sequence[tuple[FloatArray, FloatArray]],
    draw: ChainDraw,
    *,
    catheter: Catheter | None = None,
    fade: tuple[float, float] = (MU_DISTAL_FRACTION, 1.0),
    lead: Lead | None = None,
    contrast_levels: float | None = None,
    contrast_X_world: FloatArray | None = None,
) -> NDArray[np.float32]:
    """One stored image (H, W) float32 of the tree in ``view`` through the chain ``draw``.

    ``vessels``: (centerline (M, 3) world mm, radius (M,) mm), index 0 the
    main vessel, proximal first; ``catheter``: rendered when the chain's
    background has "catheter"; ``fade``: (distal fraction, power) of the
    contrast fade (:func:`recon.synth.render.vessel_attenuations`). ``view`` must have the
    chain's detector (rows, cols, pixel spacing). ``lead``: rendered when the
    background has "lead". ``contrast_levels``: the vessels' iodine is scaled
    down (never up) until their noise-free contrast, the stored value without
    the vessels less the value with them, has this median (grey levels) at the
    projections of ``contrast_X_world`` (P, 3) inside the image
    (:func:`_faint_scale`); the catheter and the lead keep theirs. A chain with
    a JPEG quality stores the values through :func:`recon.synth.chains.jpeg_roundtrip`.
    """
    spacing = float(draw.pixel_spacing_mm)
    ss = supersample_for(spacing)
    mu0 = rng.uniform(*MU_PROXIMAL_PER_MM)
    cath_scale = rng.uniform(*CATHETER_CONTRAST)
    prims = _cone_chain(vessels, vessel_attenuations(vessels, mu0, *fade))
    att_sub, _ = _attenuation_subpixels(view, prims, ss)
    others = []  # the catheter's and the lead's line integrals (H ss, W ss)
    if catheter is not None and "catheter" in draw.background:
        Xc = _catheter_in_view(view, catheter.X_world)
        wall, lumen = CATHETER_WALL * mu0, cath_scale * mu0
        for radius, mu in ((catheter.outer_radius_mm, wall),
                           (catheter.inner_radius_mm, lumen - wall)):
            tube = _cone_chain([(Xc, np.full(len(Xc), radius))], [mu])
            others.append(_attenuation_subpixels(view, tube, ss)[0])
    if lead is not None and "lead" in draw.background:
        Xl = _lead_in_view(view, lead.X_world)
        tube = _cone_chain([(Xl, np.full(len(Xl), lead.radius_mm))], [lead.mu_per_mm])
        others.append(_attenuation_subpixels(view, tube, ss)[0])
    background = background_attenuation(rng, view, spacing, draw.background)
    collimator = collimator_mask(rng, view, spacing)
    n0 = PHOTONS_PER_PIXEL * (spacing / REFERENCE_PIXEL_MM) ** 2 / draw.noise_factor**2
    k = draw.scatter_fraction / (1.0 - draw.scatter_fraction)
    sigma = np.sqrt(draw.blur_px**2 + (1.0 / 12.0 if ss == 1 else 0.0))

    def expected(att: FloatArray) -> FloatArray:
        primary = n0 * np.exp(-background) * _block_mean(np.exp(-att), ss) * collimator
        return primary + k * _wide_blur(primary, draw.scatter_sigma_mm / spacing)

    if contrast_levels is not None:
        fixed = np.sum(others, axis=0) if others else np.zeros_like(att_sub)

        def stored(scale: float) -> FloatArray:
            blurred = ndimage.gaussian_filter(expected(scale * att_sub + fixed), sigma)
            return display_values(blurred / n0, draw, exact=True)

        p = view.project(np.asarray(contrast_X_world, dtype=float))
        att_sub = _faint_scale(stored, p, contrast_levels) * att_sub
    for att in others:  # in place, in this order: the six chains' images stay bit-identical
        att_sub += att
    counts = rng.poisson(expected(att_sub)).astype(float)
    counts = ndimage.gaussian_filter(counts, sigma)
    values = display_values(counts / n0, draw)
    if draw.jpeg_quality is not None:
        values = jpeg_roundtrip(values, draw.jpeg_quality)
    return values


def _faint_scale(stored, p: FloatArray, levels: float, iterations: int = 20) -> float:
    """The iodine scale in (0, 1] that gives the contrast ``levels`` (grey levels).

    ``stored(scale)`` is the noise-free image (H, W) with the vessels' iodine
    scaled; the contrast is the median over the points ``p`` (P, 2) px
    inside the image of ``stored(0) - stored(scale)`` (bilinear), which
    grows with the scale, nearly in proportion. Regula falsi (Illinois) on
    the scale to 0.05 grey levels; 1 when the full iodine gives no more
    than ``levels``.
    """
    base = stored(0.0)
    h, w = base.shape
    ok = (p[:, 0] >= 0) & (p[:, 0] <= w - 1) & (p[:, 1] >= 0) & (p[:, 1] <= h - 1)
    coords = p[ok][:, ::-1].T

    def miss(scale: float) -> float:
        diff = base - stored(scale)
        return float(np.median(ndimage.map_coordinates(diff, coords, order=1))) - levels

    if not ok.any():
        return 1.0
    lo, f_lo, hi, f_hi = 0.0, -levels, 1.0, miss(1.0)
    if f_hi <= 0.0:
        return 1.0
    side = 0
    for _ in range(iterations):
        mid = (lo * f_hi - hi * f_lo) / (f_hi - f_lo)
        f_mid = miss(mid)
        if abs(f_mid) < 0.05:
            return mid
        if f_mid < 0.0:
            lo, f_lo = mid, f_mid
            f_hi = f_hi / 2 if side == -1 else f_hi
            side = -1
        else:
            hi, f_hi = mid, f_mid
            f_lo = f_lo / 2 if side == 1 else f_lo
            side = 1
    return mid
