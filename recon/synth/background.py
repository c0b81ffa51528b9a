"""Background structures of an imaging chain, as line integrals in the detector plane.

Everything here is sized in millimetres at the detector, so a 1024 x 1024
detector of 0.154 mm pixels sees the same anatomy as a 512 x 512 one of
0.39 mm. The plain phantom's background (:func:`recon.synth.render.
_background_attenuation`, sized in pixels of 0.390625 mm) is the model: a
smooth random field (correlation lengths 23, 10 and 4 mm) and a diaphragm
dome; chains add ribs (bands with a cortical shell, denser at their edges)
and the edge of the patient table (a blurred straight step).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.special import erf

from recon.geometry import ViewGeometry
from recon.synth.render import _smooth_field

__all__ = ["background_attenuation", "collimator_mask", "rib_attenuation", "table_attenuation"]

FloatArray = NDArray[np.float64]

FIELD_SIGMAS_MM = ((23.4, 0.10), (9.8, 0.05), (3.9, 0.02))  # (correlation length, amplitude)
RIB_COUNT = (3, 6)
RIB_WIDTH_MM = (8.0, 14.0)  # projected band width
RIB_SHELL_MM = (1.0, 2.0)  # cortical shell thickness
RIB_PEAK = (0.04, 0.10)  # line integral at the band's edge (the densest part)
RIB_SPACING_MM = (18.0, 30.0)
TABLE_STEP = (0.05, 0.15)  # extra line integral beyond the table edge
TABLE_EDGE_BLUR_MM = (1.0, 3.0)


def _grid_mm(view: ViewGeometry, spacing_mm: float) -> tuple[FloatArray, FloatArray]:
    """(x, y) detector coordinates (H, W) in mm from the image centre."""
    rows, cols = view.rows, view.cols
    y = (np.arange(rows, dtype=float) - (rows - 1) / 2) * spacing_mm
    x = (np.arange(cols, dtype=float) - (cols - 1) / 2) * spacing_mm
    return np.broadcast_to(x[None, :], (rows, cols)), np.broadcast_to(y[:, None], (rows, cols))


def background_attenuation(
    rng: np.random.Generator, view: ViewGeometry, spacing_mm: float, structures: Sequence[str]
) -> FloatArray:
    """Line integral (H, W) of the anatomy: smooth field plus the chain's ``structures``.

    ``structures`` may hold "diaphragm", "ribs" and "table" (the catheter is
    a 3D object, rendered with the vessels). Every structure always takes
    its random numbers, so a chain's draws do not depend on which are shown.
    """
    shape = (view.rows, view.cols)
    att = rng.uniform(-0.05, 0.05) * np.ones(shape)
    for sigma_mm, amp in FIELD_SIGMAS_MM:
        att += amp * rng.uniform(0.6, 1.2) * _smooth_field(rng, shape, sigma_mm / spacing_mm)
    x, y = _grid_mm(view, spacing_mm)
    dia = _diaphragm(rng, x, y)
    ribs = rib_attenuation(rng, x, y)
    table = table_attenuation(rng, x, y)
    if "diaphragm" in structures:
        att += dia
    if "ribs" in structures:
        att += ribs
    if "table" in structures:
        att += table
    return att


def _diaphragm(rng: np.random.Generator, x: FloatArray, y: FloatArray) -> FloatArray:
    """A dome (the inside of a large circle) entering from the lower part, soft edge."""
    half_h = float(y.max())
    radius = rng.uniform(117.0, 195.0)
    reach = rng.uniform(16.0, 59.0)  # how far the dome comes into the image
    angle = rng.uniform(-0.6, 0.6)
    cx = rng.uniform(-59.0, 59.0) + np.sin(angle) * radius
    cy = half_h - reach + np.cos(angle) * radius
    dist = np.hypot(y - cy, x - cx) - radius
    return rng.uniform(0.25, 0.45) / (1.0 + np.exp(dist / rng.uniform(1.2, 2.3)))


def rib_attenuation(rng: np.random.Generator, x: FloatArray, y: FloatArray) -> FloatArray:
    """Ribs (H, W): 3-6 gently curved parallel bands, each a hollow elliptic bone section.

    Across a band of half-width a (the section's depth semi-axis 0.6 a) the
    line integral is the outer chord minus 0.7 times the inner chord (the
    marrow is 0.3 as dense as the cortical shell), scaled so the edge peak
    is :data:`RIB_PEAK`.
    """
    n = int(rng.integers(RIB_COUNT[0], RIB_COUNT[1] + 1))
    theta = rng.uniform(-0.6, 0.6)  # band direction against the image's x axis
    curve = rng.uniform(-1.0, 1.0) * 2e-3  # 1/mm
    spacing = rng.uniform(*RIB_SPACING_MM)
    first = rng.uniform(-0.5, 0.5) * spacing - 0.5 * (n - 1) * spacing
    width = rng.uniform(*RIB_WIDTH_MM, n)
    shell = rng.uniform(*RIB_SHELL_MM, n)
    peak = rng.uniform(*RIB_PEAK, n)
    u = np.cos(theta) * x + np.sin(theta) * y
    v = -np.sin(theta) * x + np.cos(theta) * y
    att = np.zeros_like(x)
    for k in range(n):
        axis_v = first + k * spacing + curve * u**2
        d = (v - axis_v) / np.sqrt(1.0 + (2 * curve * u) ** 2)
        a = width[k] / 2
        att += peak[k] * _shell_profile(d, a, shell[k])
    return att


def _shell_profile(d: FloatArray, a: float, shell: float) -> FloatArray:
    """Hollow-ellipse chord profile at distance d (mm) from the axis, scaled to a peak of 1."""
    inner = max(a - shell, 0.1)

    def profile(dist: FloatArray) -> FloatArray:
        out = 1.2 * a * np.sqrt(np.clip(1.0 - (dist / a) ** 2, 0.0, None))
        return out - 0.7 * 1.2 * inner * np.sqrt(np.clip(1.0 - (dist / inner) ** 2, 0.0, None))

    peak = float(profile(np.linspace(0.0, a, 201)).max())
    return profile(d) / max(peak, 1e-9)


def table_attenuation(rng: np.random.Generator, x: FloatArray, y: FloatArray) -> FloatArray:
    """The table edge (H, W): a blurred straight step near one image side."""
    side = int(rng.integers(4))
    tilt = rng.uniform(-0.17, 0.17)
    half = float(max(x.max(), y.max()))
    pos = half * rng.uniform(0.6, 0.9)
    step = rng.uniform(*TABLE_STEP)
    blur = rng.uniform(*TABLE_EDGE_BLUR_MM)
    normal = {0: (1.0, 0.0), 1: (-1.0, 0.0), 2: (0.0, 1.0), 3: (0.0, -1.0)}[side]
    nx = normal[0] * np.cos(tilt) - normal[1] * np.sin(tilt)
    ny = normal[0] * np.sin(tilt) + normal[1] * np.cos(tilt)
    d = nx * x + ny * y - pos
    return step * 0.5 * (1.0 + erf(d / (np.sqrt(2.0) * blur)))


def collimator_mask(rng: np.random.Generator, view: ViewGeometry, spacing_mm: float) -> FloatArray:
    """Mask (H, W): 1 inside the collimator, 0.01 leakage in a 1-3.5 mm border."""
    rows, cols = view.rows, view.cols
    top, left = (np.round(rng.uniform(2.0, 3.5, 2) / spacing_mm)).astype(int)
    bottom, right = (np.round(rng.uniform(1.2, 3.0, 2) / spacing_mm)).astype(int)
    mask = np.full((rows, cols), 0.01)
    mask[top : rows - bottom, left : cols - right] = 1.0
    return mask
