"""Each view's vessel evidence for the 3D path: comparable between views, faint vessels kept.

The support of a pixel is the contrast-invariant ridge measure of the vesselness map
(:attr:`recon.trace.vesselness.VesselnessMap.ridge`: high on a vessel's centre line
whatever its contrast) gated by the pixel's local contrast against its own background,
in units of the local noise:

    contrast = background - image          (background: a grey closing wider than the
                                            widest vessel; vessels are dark)
    noise    = local RMS of the image minus its 1 px Gaussian smoothing
    support  = ridge x clip(contrast / (Z_FULL x noise), 0, 1)

No absolute threshold: a vessel 8 grey levels below its background on an 8-bit image
with 2 grey levels of noise scores like a well-filled one, and noise alone (whose
ridges are short and whose contrast is within the noise) scores low. The two views'
supports are thus on one scale.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage as ndi

from recon.trace.vesselness import RADIUS_PER_SIGMA, VesselnessMap

__all__ = ["ViewEvidence", "view_evidence", "Z_FULL"]

F32 = NDArray[np.float32]

#: Local contrast (in noise units) at which the gate is fully open.
Z_FULL = 4.0
#: Window (px) of the local noise estimate.
NOISE_WINDOW_PX = 31
#: The background closing is this many times the largest vessel radius wide (at least).
CLOSING_PER_RADIUS = 2.5


@dataclass(frozen=True, eq=False)
class ViewEvidence:
    """One view's vessel evidence.

    Attributes
    ----------
    support : (H, W) float32 in [0, 1], the vessel-centre support (module docstring).
    support_coarse : (H, W) float32, ``support`` max-filtered over the coarse search's
        voxel footprint (so that a voxel centre between two pixels of a thin vessel
        still sees it).
    radius_px : (H, W) float32, the lumen radius (px) of the strongest ridge scale.
    valid : (H, W) bool, inside the collimated field.
    """

    support: F32
    support_coarse: F32
    radius_px: F32
    valid: NDArray[np.bool_]


def view_evidence(image: ArrayLike, vmap: VesselnessMap, coarse_px: float = 3.0) -> ViewEvidence:
    """The vessel evidence of one image (H, W) (MONOCHROME2, vessels dark) from its
    vesselness map; ``coarse_px`` is the coarse search's voxel size in this view (px)."""
    img = np.asarray(image, dtype=np.float32)
    ridge = (vmap.ridge if vmap.ridge is not None else vmap.response).astype(np.float32)
    radius = (RADIUS_PER_SIGMA * vmap.scale_px).astype(np.float32)
    r_max = float(RADIUS_PER_SIGMA * max(vmap.sigmas_px))
    size = int(2 * np.ceil(CLOSING_PER_RADIUS * r_max) + 1)
    field = vmap.valid
    fill = float(np.median(img[field])) if np.any(field) else float(np.median(img))
    work = np.where(field, img, fill).astype(np.float32)
    background = ndi.minimum_filter(ndi.maximum_filter(work, size=size), size=size)
    contrast = np.maximum(background - work, 0.0)
    residual = work - ndi.gaussian_filter(work, 1.0)
    noise = np.sqrt(np.maximum(ndi.uniform_filter(residual * residual, size=NOISE_WINDOW_PX), 0.0))
    noise = np.maximum(noise, 1e-3 * max(float(np.ptp(work)), 1e-6))
    gate = np.clip(contrast / (Z_FULL * noise), 0.0, 1.0)
    support = np.where(field, ridge * gate, 0.0).astype(np.float32)
    k = max(int(round(coarse_px)), 1)
    coarse = ndi.maximum_filter(support, size=k) if k > 1 else support
    return ViewEvidence(support=support, support_coarse=coarse.astype(np.float32),
                        radius_px=radius, valid=field)
