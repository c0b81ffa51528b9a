"""Rendering one view through an imaging chain (:mod:`recon.synth.chains`).

The physics is the plain renderer's (:mod:`recon.synth.render`: exact
Beer-Lambert line integrals through the union of truncated cones), with
the chain's detector, background, guiding catheter, scatter / glare,
dose, blur and display mapping::

    primary  = N0 exp(-background) exp(-iodine) collimator
    expected = primary + k G_wide(primary),  k = f / (1 - f)   (scatter / glare)
    counts   = G_blur(Poisson(expected))
    stored   = display(counts / N0)

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
from recon.synth.anatomy import Catheter
from recon.synth.background import background_attenuation, collimator_mask
from recon.synth.chains import ChainDraw, display_values
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
) -> NDArray[np.float32]:
    """One stored image (H, W) float32 of the tree in ``view`` through the chain ``draw``.

    ``vessels``: (centerline (M, 3) world mm, radius (M,) mm), index 0 the
    main vessel, proximal first; ``catheter``: rendered when the chain's
    background has "catheter"; ``fade``: (distal fraction, power) of the
    contrast fade (:func:`recon.synth.render.vessel_attenuations`). ``view`` must have the
    chain's detector (rows, cols, pixel spacing).
    """
    spacing = float(draw.pixel_spacing_mm)
    ss = supersample_for(spacing)
    mu0 = rng.uniform(*MU_PROXIMAL_PER_MM)
    cath_scale = rng.uniform(*CATHETER_CONTRAST)
    prims = _cone_chain(vessels, vessel_attenuations(vessels, mu0, *fade))
    att_sub, _ = _attenuation_subpixels(view, prims, ss)
    if catheter is not None and "catheter" in draw.background:
        Xc = _catheter_in_view(view, catheter.X_world)
        wall, lumen = CATHETER_WALL * mu0, cath_scale * mu0
        for radius, mu in ((catheter.outer_radius_mm, wall),
                           (catheter.inner_radius_mm, lumen - wall)):
            tube = _cone_chain([(Xc, np.full(len(Xc), radius))], [mu])
            att_sub += _attenuation_subpixels(view, tube, ss)[0]
    transmission = _block_mean(np.exp(-att_sub), ss)
    background = background_attenuation(rng, view, spacing, draw.background)
    collimator = collimator_mask(rng, view, spacing)
    n0 = PHOTONS_PER_PIXEL * (spacing / REFERENCE_PIXEL_MM) ** 2 / draw.noise_factor**2
    primary = n0 * np.exp(-background) * transmission * collimator
    k = draw.scatter_fraction / (1.0 - draw.scatter_fraction)
    expected = primary + k * _wide_blur(primary, draw.scatter_sigma_mm / spacing)
    counts = rng.poisson(expected).astype(float)
    sigma = np.sqrt(draw.blur_px**2 + (1.0 / 12.0 if ss == 1 else 0.0))
    counts = ndimage.gaussian_filter(counts, sigma)
    return display_values(counts / n0, draw)
