"""A straight vessel with an eccentric (elliptic) stenosis, rendered into one view.

The main phantom's lumens are chains of truncated cones (circular sections), so
they cannot show what an elliptic section does to the two views' widths and
attenuation. This phantom is one straight tube: round (``ref_radius_mm``) away
from the lesion; over ``lesion_length_mm`` its section narrows smoothly (a
raised cosine) to an ellipse with semi-axes ``major_mm`` along ``major_dir`` and
``minor_mm`` across it. The iodine path length of each ray is the
midpoint-rule integral of the inside test along the ray (``n_steps`` samples
over the stretch where the ray passes within the tube's largest radius), a few
rays per pixel; counts follow Beer-Lambert with the plain renderer's photon
level, quantum noise and detector blur (:mod:`recon.synth.render`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from recon.geometry import ViewGeometry
from recon.synth.render import BACKGROUND_LEVEL, DETECTOR_BLUR_PX, MAX_VALUE, PHOTONS_PER_PIXEL

__all__ = ["EllipticTube", "tube_path_length", "render_tube"]

FloatArray = NDArray[np.float64]

_CHUNK_RAYS = 8192


@dataclass(frozen=True)
class EllipticTube:
    """A straight tube with one elliptic stenosis (world mm).

    centre_world : (3,) the lesion's centre; direction : (3,) unit axis;
    major_dir : (3,) unit, perpendicular to ``direction``: the lesion ellipse's
    major axis; ref_radius_mm : the round lumen away from the lesion;
    major_mm, minor_mm : the lesion's semi-axes at its centre;
    lesion_length_mm : length of the narrowing; half_length_mm : the tube runs
    +- this far from the centre; mu_per_mm : iodine attenuation.
    """

    centre_world: FloatArray
    direction: FloatArray
    major_dir: FloatArray
    ref_radius_mm: float
    major_mm: float
    minor_mm: float
    lesion_length_mm: float = 8.0
    half_length_mm: float = 18.0
    mu_per_mm: float = 0.1

    @property
    def area_mm2(self) -> float:
        """The lesion's true section area at its centre."""
        return float(np.pi * self.major_mm * self.minor_mm)

    def semi_axes(self, z_mm: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Semi-axes (along major_dir, across it) at axial positions z_mm (any shape)."""
        u = np.clip(np.abs(z_mm) / (0.5 * self.lesion_length_mm), 0.0, 1.0)
        g = 0.5 * (1.0 + np.cos(np.pi * u))
        return (self.ref_radius_mm + (self.major_mm - self.ref_radius_mm) * g,
                self.ref_radius_mm + (self.minor_mm - self.ref_radius_mm) * g)

    def axis_points(self, n: int = 64) -> FloatArray:
        """(n, 3) points along the axis from -half_length to +half_length."""
        z = np.linspace(-self.half_length_mm, self.half_length_mm, n)
        return self.centre_world[None, :] + z[:, None] * self.direction[None, :]


def _ray_lengths(tube: EllipticTube, S: FloatArray, d: FloatArray, n_steps: int) -> FloatArray:
    """Path length (R,) mm of rays from S (3,) along unit d (R, 3) inside the tube."""
    T = tube.direction
    e1 = tube.major_dir
    e2 = np.cross(T, e1)
    w0 = S - tube.centre_world
    b = d @ T
    denom = np.maximum(1.0 - b**2, 1e-6)
    t_star = (b * (w0 @ T) - d @ w0) / denom
    r_max = max(tube.ref_radius_mm, tube.major_mm, tube.minor_mm) + 0.05
    half = r_max / np.sqrt(denom)
    frac = (np.arange(n_steps) + 0.5) / n_steps * 2.0 - 1.0
    t = t_star[:, None] + half[:, None] * frac[None, :]
    z = (w0 @ T) + t * b[:, None]
    x = (w0 @ e1) + t * (d @ e1)[:, None]
    y = (w0 @ e2) + t * (d @ e2)[:, None]
    A, B = tube.semi_axes(z)
    inside = ((x / A) ** 2 + (y / B) ** 2 <= 1.0) & (np.abs(z) <= tube.half_length_mm)
    return inside.sum(axis=1) * (2.0 * half / n_steps)


def tube_path_length(view: ViewGeometry, tube: EllipticTube, *, supersample: int = 2,
                     n_steps: int = 320) -> FloatArray:
    """Iodine path length (H, W) mm per pixel (mean over supersample^2 rays)."""
    uv = view.project(tube.axis_points())
    pad = 4.0 * tube.ref_radius_mm / view.pixel_mm_at_isocenter + 6.0
    c0 = int(max(np.floor(uv[:, 0].min() - pad), 0))
    c1 = int(min(np.ceil(uv[:, 0].max() + pad), view.cols - 1))
    r0 = int(max(np.floor(uv[:, 1].min() - pad), 0))
    r1 = int(min(np.ceil(uv[:, 1].max() + pad), view.rows - 1))
    out = np.zeros((view.rows, view.cols))
    if c1 <= c0 or r1 <= r0:
        return out
    ss = supersample
    sub = (np.arange(ss) + 0.5) / ss - 0.5
    cols = (np.arange(c0, c1 + 1)[:, None] + sub[None, :]).ravel()
    rows = (np.arange(r0, r1 + 1)[:, None] + sub[None, :]).ravel()
    cc, rr = np.meshgrid(cols, rows)
    px = np.column_stack([cc.ravel(), rr.ravel()])
    lengths = np.empty(len(px))
    for k in range(0, len(px), _CHUNK_RAYS):
        d = view.ray_directions(px[k : k + _CHUNK_RAYS])
        lengths[k : k + _CHUNK_RAYS] = _ray_lengths(tube, view.source_world, d, n_steps)
    block = lengths.reshape(r1 - r0 + 1, ss, c1 - c0 + 1, ss).mean(axis=(1, 3))
    out[r0 : r1 + 1, c0 : c1 + 1] = block
    return out


def render_tube(rng: np.random.Generator, view: ViewGeometry, tube: EllipticTube) -> NDArray:
    """12-bit image (H, W) float32 of the tube (MONOCHROME2, vessels dark) over a
    gently sloping background, with quantum noise and detector blur."""
    ss = 2
    length = tube_path_length(view, tube, supersample=ss)
    rows, cols = np.mgrid[0 : view.rows, 0 : view.cols] / max(view.rows, view.cols)
    slope = rng.uniform(-0.15, 0.15, 2)
    background = 0.25 + slope[0] * rows + slope[1] * cols
    expected = PHOTONS_PER_PIXEL * np.exp(-background - tube.mu_per_mm * length)
    counts = ndimage.gaussian_filter(rng.poisson(expected).astype(float), DETECTOR_BLUR_PX)
    value = counts * (BACKGROUND_LEVEL / PHOTONS_PER_PIXEL)
    return np.clip(np.round(value), 0, MAX_VALUE).astype(np.float32)
