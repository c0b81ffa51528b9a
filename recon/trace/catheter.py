"""Catheter calibration: the pixel size at the guiding catheter from its French size.

As in 2D QCA, the catheter's known outer diameter (French size F: F / 3 mm)
calibrates the image. The clinician clicks once near each edge of the
catheter; the catheter's width is then fitted, not read from the clicks (one
pixel of click error would be 15 % of a 6 F catheter at 7 px): intensity
profiles along the line of the clicks, at :data:`N_PROFILES` places 1 px apart
along the catheter, are fitted with the blurred-cylinder model of
:mod:`recon.trace.profile_fit` (the tracing stage's model; centre, radius and
background per profile, the blur chosen by the least residual over
:data:`BLUR_GRID_PX`), and the width is twice the median radius. Then

    mm per pixel at the catheter = (F / 3) / width_px

and, with the catheter at the isocentre's depth (the ostium it is engaged in
is near the isocentre in a centred coronary view), the detector pixel is that
times the magnification SID / SOD.

The model is a uniformly filled tube: a contrast-filled catheter whose wall
is much fainter than its lumen reads nearer its inner diameter (on the
phantom's guide, wall at 0.25 of the lumen's attenuation, about 9 % narrow,
so the spacing about 10 % large); the page says so.

Pixels are (col, row), 0-based; images MONOCHROME2 (a contrast-filled catheter
is dark).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from recon.trace.intensity import ValueScale, absorption
from recon.trace.profile_fit import fit_along, spline_coefficients

__all__ = ["CatheterCalibration", "FRENCH_MM", "FRENCH_RANGE", "calibrate_from_catheter",
           "catheter_width_px"]

FloatArray = NDArray[np.float64]

FRENCH_MM = 1.0 / 3.0  # 1 F = 1/3 mm of outer diameter
FRENCH_RANGE = (4.0, 10.0)  # guiding and diagnostic catheters
N_PROFILES = 7  # profiles fitted, 1 px apart along the catheter
BLUR_GRID_PX = tuple(np.round(np.arange(0.4, 2.01, 0.2), 2))
MIN_WIDTH_PX = 2.0  # the clicks at least this far apart
MIN_FITTED_WIDTH_PX = 4.0  # narrower, blur and width cannot be told apart


@dataclass(frozen=True)
class CatheterCalibration:
    """The result of a catheter calibration.

    edges_px : (2, 2) the two edges found (col, row); width_px : their distance.
    french : the size given; diameter_mm : french / 3.
    mm_per_px_at_catheter : the calibration factor at the catheter's depth.
    pixel_spacing_mm : the detector pixel it implies (times SID / SOD).
    """

    edges_px: FloatArray
    width_px: float
    french: float
    diameter_mm: float
    mm_per_px_at_catheter: float
    pixel_spacing_mm: float


def catheter_width_px(image: ArrayLike, click_0_px: ArrayLike, click_1_px: ArrayLike,
                      power: float = 0.0) -> tuple[float, FloatArray]:
    """The catheter's width (px) and its two edges (2, 2) at the clicks (module doc).

    image : (H, W) stored values; click_0_px, click_1_px : (2,) (col, row), one near
    each edge; power : the Box-Cox power of :func:`recon.trace.intensity.absorption` (0 for
    values linear in intensity, 1 for values linear in attenuation). Raises ValueError
    when the clicks are closer than :data:`MIN_WIDTH_PX` or no dark tube fits there.
    """
    img = np.asarray(image, dtype=float)
    p0, p1 = np.asarray(click_0_px, float), np.asarray(click_1_px, float)
    length = float(np.linalg.norm(p1 - p0))
    if length < MIN_WIDTH_PX:
        raise ValueError(f"catheter: the two clicks are {length:.1f} px apart; click once "
                         "near each edge of the catheter")
    normal = (p1 - p0) / length
    along = np.array([-normal[1], normal[0]])
    centre = (p0 + p1) / 2
    pts = centre[None] + (np.arange(N_PROFILES) - (N_PROFILES - 1) / 2)[:, None] * along[None]
    coef = spline_coefficients(absorption(img, power, ValueScale.of(img)))
    normals = np.repeat(normal[None], N_PROFILES, axis=0)
    guess = np.full(N_PROFILES, length / 2)
    best = None
    for blur in BLUR_GRID_PX:
        fit = fit_along(coef, pts, normals, guess, float(blur), 0.05, order=3)
        good = fit.ok & np.isfinite(fit.radius_px)
        if np.count_nonzero(good) < (N_PROFILES + 1) // 2:
            continue
        rss = float(np.median(fit.rss[good]))
        if best is None or rss < best[0]:
            best = (rss, fit, good)
    if best is None:
        raise ValueError("catheter: no dark tube between the clicks; click once near each "
                         "edge of the catheter, across it")
    _, fit, good = best
    radius = float(np.median(fit.radius_px[good]))
    if 2.0 * radius < MIN_FITTED_WIDTH_PX:
        raise ValueError(f"catheter: only {2.0 * radius:.1f} px wide, too narrow to calibrate "
                         f"on (at least {MIN_FITTED_WIDTH_PX:g} px)")
    mid = centre + float(np.median(fit.shift_px[good])) * normal
    return 2.0 * radius, np.array([mid - radius * normal, mid + radius * normal])


def calibrate_from_catheter(image: ArrayLike, click_0_px: ArrayLike, click_1_px: ArrayLike,
                            french: float, sid_mm: float, sod_mm: float, power: float = 0.0
                            ) -> CatheterCalibration:
    """The calibration factor at the catheter and the detector pixel spacing (module doc).

    Raises ValueError for a French size outside :data:`FRENCH_RANGE`, a SID not above the
    SOD, or clicks on which no catheter edges are found.
    """
    french = float(french)
    if not FRENCH_RANGE[0] <= french <= FRENCH_RANGE[1]:
        raise ValueError(f"catheter: {french:g} F is not a catheter size "
                         f"({FRENCH_RANGE[0]:g}-{FRENCH_RANGE[1]:g} F)")
    if not (np.isfinite(sid_mm) and np.isfinite(sod_mm) and 0.0 < sod_mm < sid_mm):
        raise ValueError("catheter: SID and SOD are needed (SOD below SID) to turn the "
                         "catheter's scale into the detector's pixel spacing")
    width_px, edges = catheter_width_px(image, click_0_px, click_1_px, power)
    diameter_mm = french * FRENCH_MM
    at_catheter = diameter_mm / width_px
    return CatheterCalibration(edges_px=edges, width_px=width_px, french=french,
                               diameter_mm=diameter_mm, mm_per_px_at_catheter=at_catheter,
                               pixel_spacing_mm=at_catheter * sid_mm / sod_mm)
