"""The phantom's X-ray renderer.

Beer-Lambert: counts = N0 * background(x, y) * exp(-sum mu L), where L is
the iodine path length through the lumen computed exactly for a chain of
truncated cones (union of the per-cone ray intervals, so consecutive cones
are not double counted and true crossings add up), supersampled per pixel;
a smooth random anatomical background, a diaphragm edge, a collimator
border, Poisson quantum noise, detector blur, 12-bit output (MONOCHROME2:
vessels dark).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from recon.geometry import ViewGeometry
from recon.synth.tree import SAMPLE_STEP_MM

__all__ = ["path_length_image", "render_view", "vessel_attenuations", "SUPERSAMPLE",
           "MAX_VALUE"]

FloatArray = NDArray[np.float64]

SUPERSAMPLE = 2  # rays per pixel along each axis
CONE_MAX_LENGTH_MM = 0.4  # truncated-cone chain: longest cone
CONE_MAX_DR_MM = 0.02  # largest radius change within one cone
CONE_MAX_TURN_RAD = 0.01  # largest bend between consecutive cones
MU_PROXIMAL_PER_MM = (0.085, 0.11)  # iodine attenuation; 3 mm vessel darkens ~25 %
MU_DISTAL_FRACTION = 0.7  # contrast fades ~30 % from proximal to distal
PHOTONS_PER_PIXEL = 2500.0  # unattenuated counts (Poisson)
DETECTOR_BLUR_PX = 0.7
BACKGROUND_LEVEL = 2600.0  # 12-bit value of unattenuated background
MAX_VALUE = 4095


@dataclass(frozen=True)
class _Primitives:
    """Truncated cones (K) and spheres (J) whose union is the lumen, with attenuation."""

    A: FloatArray  # (K, 3) cone start
    B: FloatArray  # (K, 3) cone end
    ra: FloatArray  # (K,) radius at A
    rb: FloatArray  # (K,) radius at B
    mu_cone: FloatArray  # (K,) attenuation per mm
    C: FloatArray  # (J, 3) sphere centres (vessel end caps)
    rs: FloatArray  # (J,) sphere radii
    mu_sphere: FloatArray  # (J,)


def _cone_chain(
    vessels: Sequence[tuple[ArrayLike, ArrayLike]], mus: Sequence[ArrayLike]
) -> _Primitives:
    """Cut each sampled tube into truncated cones (short where it bends or narrows).

    Break points are kept where the accumulated length, radius change or
    bend exceeds :data:`CONE_MAX_LENGTH_MM`, :data:`CONE_MAX_DR_MM` or
    :data:`CONE_MAX_TURN_RAD`; the ends get spherical caps.
    """
    parts: dict[str, list] = {k: [] for k in ("A", "B", "ra", "rb", "mu", "C", "rs", "mus")}
    for (X, r), mu in zip(vessels, mus, strict=True):
        X = np.asarray(X, dtype=float).reshape(-1, 3)
        r = np.asarray(r, dtype=float).reshape(-1)
        mu = np.broadcast_to(np.asarray(mu, dtype=float), r.shape)
        if len(X) != len(r):
            raise ValueError(f"centerline has {len(X)} points but {len(r)} radii")
        if len(X) < 2:
            continue
        steps = np.diff(X, axis=0)
        seg_len = np.linalg.norm(steps, axis=1)
        tang = steps / np.maximum(seg_len[:, None], 1e-12)
        turn = np.arccos(np.clip(np.sum(tang[1:] * tang[:-1], axis=1), -1.0, 1.0))
        cost = np.concatenate([[0.0], np.cumsum(seg_len)]) / CONE_MAX_LENGTH_MM
        cost += np.concatenate([[0.0], np.cumsum(np.abs(np.diff(r)))]) / CONE_MAX_DR_MM
        cost += np.concatenate([[0.0, 0.0], np.cumsum(turn)]) / CONE_MAX_TURN_RAD
        keep = np.flatnonzero(np.diff(np.floor(cost)) > 0) + 1
        idx = np.unique(np.concatenate([[0], keep, [len(X) - 1]]))
        parts["A"].append(X[idx[:-1]])
        parts["B"].append(X[idx[1:]])
        parts["ra"].append(r[idx[:-1]])
        parts["rb"].append(r[idx[1:]])
        parts["mu"].append(0.5 * (mu[idx[:-1]] + mu[idx[1:]]))
        parts["C"].append(X[[0, -1]])
        parts["rs"].append(r[[0, -1]])
        parts["mus"].append(mu[[0, -1]])

    def cat(key: str, width: int | None) -> FloatArray:
        if not parts[key]:
            return np.zeros((0, width) if width else (0,))
        return np.concatenate(parts[key])

    return _Primitives(
        A=cat("A", 3),
        B=cat("B", 3),
        ra=cat("ra", None),
        rb=cat("rb", None),
        mu_cone=cat("mu", None),
        C=cat("C", 3),
        rs=cat("rs", None),
        mu_sphere=cat("mus", None),
    )


def _pixel_pairs(
    view: ViewGeometry, P0: FloatArray, P1: FloatArray, rmax: FloatArray, ss: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """All (primitive, subpixel) pairs of each primitive's projected bounding box.

    Returns the primitive index (N,) and the flat subpixel index (N,) in the
    (H ss, W ss) grid whose subpixel (m, n) is centred at pixel
    ((n + 0.5) / ss - 0.5, (m + 0.5) / ss - 0.5).
    """
    H, W = view.rows * ss, view.cols * ss
    p0, p1 = view.project(P0), view.project(P1)
    depth = np.minimum(view.depth_mm(P0), view.depth_mm(P1)) - rmax
    spacing = min(view.pixel_spacing_mm)
    r_px = rmax * view.sid_mm / np.maximum(depth, 1e-6) / spacing + 1.0
    lo = np.minimum(p0, p1) - r_px[:, None]
    hi = np.maximum(p0, p1) + r_px[:, None]
    m_lo = np.ceil((lo + 0.5) * ss - 0.5).astype(np.int64)
    m_hi = np.floor((hi + 0.5) * ss - 0.5).astype(np.int64)
    m_lo = np.maximum(m_lo, 0)
    m_hi = np.minimum(m_hi, np.array([W - 1, H - 1]))
    size = np.maximum(m_hi - m_lo + 1, 0)  # (K, 2) columns, rows
    count = size[:, 0] * size[:, 1]
    prim = np.repeat(np.arange(len(P0)), count)
    local = np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)
    w = size[prim, 0]
    col = m_lo[prim, 0] + local % np.maximum(w, 1)
    row = m_lo[prim, 1] + local // np.maximum(w, 1)
    return prim, row * W + col


def _footprint_keep(
    view: ViewGeometry, P0: FloatArray, P1: FloatArray, rmax: FloatArray, ss: int,
    prim: NDArray[np.int64], flat: NDArray[np.int64],
) -> NDArray[np.bool_]:
    """Which (primitive, subpixel) pairs can hit: a conservative test in the image plane.

    Every point of a truncated cone lies within ``rmax`` of its axis, so its
    image lies within the bounding box's margin ``r_px`` of the projected axis
    segment; along the axis, the end discs (perpendicular to the axis) reach
    past the projected segment's ends by only ``r_px |cos|`` (cos of the angle
    between the axis and the ray), widened here by 5 % and 1 px for
    perspective. Pairs outside cannot hit, so dropping them changes no result
    (the hits keep their order); it only saves the ray-cone arithmetic.
    """
    W = view.cols * ss
    p0, p1 = view.project(P0), view.project(P1)
    depth = np.minimum(view.depth_mm(P0), view.depth_mm(P1)) - rmax
    spacing = min(view.pixel_spacing_mm)
    r_px = rmax * view.sid_mm / np.maximum(depth, 1e-6) / spacing + 1.0
    seg = p1 - p0
    length = np.linalg.norm(seg, axis=1)
    e2 = seg / np.maximum(length, 1e-9)[:, None]
    axis3 = P1 - P0
    axis3 = axis3 / np.maximum(np.linalg.norm(axis3, axis=1), 1e-12)[:, None]
    ray = 0.5 * (P0 + P1) - view.source_world
    ray /= np.linalg.norm(ray, axis=1)[:, None]
    cos = np.abs(np.einsum("ij,ij->i", axis3, ray))
    cos = np.where(length > 1e-9, cos, 1.0)
    end_margin = r_px * (cos + 0.05) + 1.0
    col = (flat % W + 0.5) / ss - 0.5 - p0[prim, 0]
    row = (flat // W + 0.5) / ss - 0.5 - p0[prim, 1]
    along = col * e2[prim, 0] + row * e2[prim, 1]
    across = np.abs(col * e2[prim, 1] - row * e2[prim, 0])
    inside = (along >= -end_margin[prim]) & (along <= length[prim] + end_margin[prim])
    capsule = np.hypot(np.maximum(-along, 0.0) + np.maximum(along - length[prim], 0.0), across)
    return inside & (across <= r_px[prim]) & (capsule <= r_px[prim] + 1.0)


def _subpixel_rays(view: ViewGeometry, flat: NDArray[np.int64], ss: int) -> FloatArray:
    """Unit world directions (N, 3) of the rays through flat subpixel indices."""
    W = view.cols * ss
    sr, sc = view.pixel_spacing_mm
    cx, cy = view.centre_px
    xn = ((flat % W + 0.5) / ss - 0.5 - cx) * (sc / view.sid_mm)
    yn = ((flat // W + 0.5) / ss - 0.5 - cy) * (sr / view.sid_mm)
    R = view.R_view_from_world  # rows u, v, d: orthonormal, so |(xn, yn, 1) R| = sqrt(...)
    inv = 1.0 / np.sqrt(1.0 + xn**2 + yn**2)
    return (xn * inv)[:, None] * R[0] + (yn * inv)[:, None] * R[1] + inv[:, None] * R[2]


def _cone_intervals(
    S: FloatArray, w: FloatArray, A: FloatArray, B: FloatArray, ra: FloatArray, rb: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Entry and exit distances (N,) of rays S + t w through truncated cones (inf if missed).

    A point is inside when its axial coordinate y in [0, h] and its distance
    from the axis is at most ra + (rb - ra) y / h; along the ray this is the
    quadratic a t^2 + 2 b t + c <= 0 clipped to the slab. Distances are
    computed from the ray point closest to A for precision.
    """
    axis = B - A
    h = np.linalg.norm(axis, axis=1)
    e = axis / np.maximum(h, 1e-12)[:, None]
    k = (rb - ra) / np.maximum(h, 1e-12)
    t0 = np.einsum("ij,ij->i", w, A - S)
    oa = S + t0[:, None] * w - A
    y0 = np.einsum("ij,ij->i", oa, e)
    wy = np.einsum("ij,ij->i", w, e)
    wo = np.einsum("ij,ij->i", w, oa)
    rho0 = ra + k * y0
    a = 1.0 - wy**2 * (1.0 + k**2)
    b = wo - y0 * wy - k * wy * rho0
    c = np.einsum("ij,ij->i", oa, oa) - y0**2 - rho0**2
    disc = b**2 - a * c
    sq = np.sqrt(np.maximum(disc, 0.0))
    inf = np.inf
    with np.errstate(divide="ignore", invalid="ignore"):
        # The slab 0 <= y0 + t wy <= h.
        along = np.abs(wy) > 1e-12
        s1 = np.where(along, -y0 / wy, np.where((y0 >= 0) & (y0 <= h), -inf, inf))
        s2 = np.where(along, (h - y0) / wy, np.where((y0 >= 0) & (y0 <= h), inf, -inf))
        ts_lo, ts_hi = np.minimum(s1, s2), np.maximum(s1, s2)
        # The quadratic's solution set: up to two intervals [l1, h1], [l2, h2].
        pos = a > 1e-12
        neg = a < -1e-12
        lin = ~(pos | neg)
        r_1 = (-b - sq) / a
        r_2 = (-b + sq) / a
        r_lo, r_hi = np.minimum(r_1, r_2), np.maximum(r_1, r_2)
        t_lin = -c / (2.0 * b)
        l1 = np.full_like(a, inf)
        h1 = np.full_like(a, -inf)
        l2 = np.full_like(a, inf)
        h2 = np.full_like(a, -inf)
        m = pos & (disc >= 0)
        l1[m], h1[m] = r_lo[m], r_hi[m]
        m = neg & (disc < 0)
        l1[m], h1[m] = -inf, inf
        m = neg & (disc >= 0)
        l1[m], h1[m] = -inf, r_lo[m]
        l2[m], h2[m] = r_hi[m], inf
        m = lin & (b > 0)
        l1[m], h1[m] = -inf, t_lin[m]
        m = lin & (b < 0)
        l1[m], h1[m] = t_lin[m], inf
        m = lin & (b == 0) & (c <= 0)
        l1[m], h1[m] = -inf, inf
    i1_lo, i1_hi = np.maximum(l1, ts_lo), np.minimum(h1, ts_hi)
    i2_lo, i2_hi = np.maximum(l2, ts_lo), np.minimum(h2, ts_hi)
    ok1, ok2 = i1_hi > i1_lo, i2_hi > i2_lo
    t_in = np.minimum(np.where(ok1, i1_lo, inf), np.where(ok2, i2_lo, inf))
    t_out = np.maximum(np.where(ok1, i1_hi, -inf), np.where(ok2, i2_hi, -inf))
    return t0 + t_in, t0 + t_out


def _sphere_intervals(
    S: FloatArray, w: FloatArray, C: FloatArray, r: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """Entry and exit distances (N,) of rays S + t w through spheres (inf if missed)."""
    t0 = np.einsum("ij,ij->i", w, C - S)
    oc = S + t0[:, None] * w - C
    h = r**2 - np.einsum("ij,ij->i", oc, oc)
    sq = np.sqrt(np.maximum(h, 0.0))
    hit = h > 0
    return np.where(hit, t0 - sq, np.inf), np.where(hit, t0 + sq, -np.inf)


_CHUNK_PAIRS = 1_000_000


def _attenuation_subpixels(
    view: ViewGeometry, prims: _Primitives, ss: int
) -> tuple[FloatArray, FloatArray]:
    """Line integrals of mu and path lengths (H ss, W ss) through the union of primitives.

    Each ray's intervals through all primitives are sorted by (subpixel,
    entry) and merged with a running maximum of the exit: a piece of ray
    inside several overlapping primitives counts once (attributed to the
    first), disjoint pieces (vessels crossing) add up.
    """
    S = view.source_world
    pix_parts, tin_parts, tout_parts, mu_parts = [], [], [], []
    n_cone = len(prims.A)
    P0 = np.vstack([prims.A, prims.C])
    P1 = np.vstack([prims.B, prims.C])
    rmax = np.concatenate([np.maximum(prims.ra, prims.rb), prims.rs])
    mu_all = np.concatenate([prims.mu_cone, prims.mu_sphere])
    prim, flat = _pixel_pairs(view, P0, P1, rmax, ss)
    keep = _footprint_keep(view, P0, P1, rmax, ss, prim, flat)
    prim, flat = prim[keep], flat[keep]
    for start in range(0, len(prim), _CHUNK_PAIRS):
        p = prim[start : start + _CHUNK_PAIRS]
        f = flat[start : start + _CHUNK_PAIRS]
        w = _subpixel_rays(view, f, ss)
        t_in = np.empty(len(p))
        t_out = np.empty(len(p))
        cone = p < n_cone
        pc = p[cone]
        t_in[cone], t_out[cone] = _cone_intervals(
            S, w[cone], prims.A[pc], prims.B[pc], prims.ra[pc], prims.rb[pc]
        )
        ps = p[~cone] - n_cone
        t_in[~cone], t_out[~cone] = _sphere_intervals(S, w[~cone], prims.C[ps], prims.rs[ps])
        hit = t_out > t_in
        pix_parts.append(f[hit])
        tin_parts.append(t_in[hit])
        tout_parts.append(t_out[hit])
        mu_parts.append(mu_all[p[hit]])
    size = view.rows * ss * view.cols * ss
    if not pix_parts or sum(len(x) for x in pix_parts) == 0:
        zero = np.zeros((view.rows * ss, view.cols * ss))
        return zero, zero.copy()
    pix = np.concatenate(pix_parts)
    t_in = np.concatenate(tin_parts)
    t_out = np.concatenate(tout_parts)
    mu = np.concatenate(mu_parts)
    order = np.lexsort((t_in, pix))
    pix, t_in, t_out, mu = pix[order], t_in[order], t_out[order], mu[order]
    # Segmented running maximum of the exits: offset each subpixel's group so
    # that a plain cumulative maximum never carries over from the previous one.
    t_min = float(t_in.min())
    span = float(t_out.max() - t_min) + 1.0
    key = (t_out - t_min) + pix * span
    run = np.maximum.accumulate(key)
    prev = np.concatenate([[-np.inf], run[:-1] - pix[1:] * span + t_min])
    piece = np.maximum(t_out - np.maximum(t_in, prev), 0.0)
    shape = (view.rows * ss, view.cols * ss)
    att = np.bincount(pix, weights=mu * piece, minlength=size).reshape(shape)
    length = np.bincount(pix, weights=piece, minlength=size).reshape(shape)
    return att, length


def _block_mean(arr: FloatArray, ss: int) -> FloatArray:
    H, W = arr.shape[0] // ss, arr.shape[1] // ss
    return arr.reshape(H, ss, W, ss).mean(axis=(1, 3))


def path_length_image(
    view: ViewGeometry,
    vessels: Sequence[tuple[ArrayLike, ArrayLike]],
    *,
    supersample: int = 1,
) -> FloatArray:
    """Iodine path length (H, W) in mm through the union of tubes, per pixel.

    Parameters
    ----------
    view : the projecting geometry.
    vessels : sequence of (centerline (M, 3) world mm, radius (M,) mm); each
        tube is a chain of truncated cones with spherical end caps.
    supersample : rays per pixel along each axis; the result is their mean.

    Returns
    -------
    (H, W) float64 path length in mm (overlaps counted once, crossings add).
    """
    prims = _cone_chain(vessels, [1.0] * len(vessels))
    _, length = _attenuation_subpixels(view, prims, supersample)
    return _block_mean(length, supersample)


def vessel_attenuations(
    vessels: Sequence[tuple[FloatArray, FloatArray]], mu0: float,
    distal_fraction: float = MU_DISTAL_FRACTION, power: float = 1.0,
) -> list[FloatArray]:
    """Attenuation per mm (M,) along each vessel: the plain fade, generalised.

    The main vessel (index 0) fades as ``mu0 (1 - fade frac^power)`` with
    ``fade = 1 - distal_fraction`` and ``frac`` its arc fraction; another
    vessel starts at the value of the nearest main-vessel point and fades
    half as much along itself. ``power = 1`` and ``distal_fraction = 0.7``
    give the plain phantom's values (to rounding).
    """
    fade = 1.0 - distal_fraction
    main_X = np.asarray(vessels[0][0])
    main_len = max((len(main_X) - 1) * SAMPLE_STEP_MM, 1e-9)
    mus = []
    for k, (X, _) in enumerate(vessels):
        frac = np.arange(len(X)) / max(len(X) - 1, 1)
        if k == 0:
            mus.append(mu0 * (1.0 - fade * frac**power))
        else:
            s_origin = np.argmin(np.linalg.norm(main_X - X[0], axis=1)) * SAMPLE_STEP_MM
            start = 1.0 - fade * (s_origin / main_len) ** power
            mus.append(mu0 * start * (1.0 - 0.5 * fade * frac**power))
    return mus


def _smooth_field(rng: np.random.Generator, shape: tuple[int, int], sigma_px: float) -> FloatArray:
    """Zero-mean, unit-sd Gaussian random field (H, W) of correlation length ~sigma_px."""
    step = max(sigma_px / 3.0, 1.0)
    coarse = (int(np.ceil(shape[0] / step)) + 8, int(np.ceil(shape[1] / step)) + 8)
    noise = ndimage.gaussian_filter(rng.normal(size=coarse), sigma_px / step, mode="wrap")
    size = (int(round(coarse[1] * step)), int(round(coarse[0] * step)))  # (W, H) for cv2
    big = cv2.resize(noise, size, interpolation=cv2.INTER_CUBIC)
    off = int(4 * step)
    zoomed = big[off : off + shape[0], off : off + shape[1]]
    return (zoomed - zoomed.mean()) / max(zoomed.std(), 1e-12)


def _background_attenuation(rng: np.random.Generator, view: ViewGeometry) -> FloatArray:
    """Smooth anatomy (H, W) as a line integral: random field plus a diaphragm edge."""
    shape = (view.rows, view.cols)
    att = rng.uniform(-0.05, 0.05) * np.ones(shape)
    for sigma, amp in ((60.0, 0.10), (25.0, 0.05), (10.0, 0.02)):
        att += amp * rng.uniform(0.6, 1.2) * _smooth_field(rng, shape, sigma)
    # Diaphragm: the inside of a large circle entering from the lower part.
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(float)
    radius = rng.uniform(300.0, 500.0)
    reach = rng.uniform(40.0, 150.0)  # how far the dome comes into the image
    angle = rng.uniform(-0.6, 0.6)  # tilt of the dome's approach from the bottom
    centre_c = shape[1] / 2 + rng.uniform(-150, 150) + np.sin(angle) * radius
    centre_r = shape[0] - reach + np.cos(angle) * radius
    dist = np.hypot(rows - centre_r, cols - centre_c) - radius
    att += rng.uniform(0.25, 0.45) / (1.0 + np.exp(dist / rng.uniform(3.0, 6.0)))
    return att


def _collimator(rng: np.random.Generator, view: ViewGeometry) -> FloatArray:
    """Mask (H, W): 1 inside the collimator, a small leakage in the black border."""
    rows, cols = view.rows, view.cols
    top, left = rng.integers(5, 9, 2)
    bottom, right = rows - rng.integers(4, 8), cols - rng.integers(3, 7)
    mask = np.full((rows, cols), 0.01)
    mask[top:bottom, left:right] = 1.0
    return mask


def render_view(
    rng: np.random.Generator,
    view: ViewGeometry,
    vessels: Sequence[tuple[FloatArray, FloatArray]],
    n_frames: int,
    fade_curve: tuple[float, float] | None = None,
) -> tuple[NDArray[np.float32], int]:
    """Render ``n_frames`` images (F, H, W) of the tree in ``view`` and the truth frame index.

    ``vessels`` are (centerline (M, 3) world mm, radius (M,) mm) sampled
    every :data:`SAMPLE_STEP_MM`, index 0 the main vessel, proximal first.
    ``fade_curve``: (distal fraction, power) of a contrast fade other than
    the plain one (:func:`vessel_attenuations`), or None.
    """
    ss = SUPERSAMPLE
    mu0 = rng.uniform(*MU_PROXIMAL_PER_MM)
    fade = 1.0 - MU_DISTAL_FRACTION
    main_X = vessels[0][0]
    main_len = max((len(main_X) - 1) * SAMPLE_STEP_MM, 1e-9)
    if fade_curve is not None:
        mus = vessel_attenuations(vessels, mu0, *fade_curve)
    else:
        mus = []
        for k, (X, _) in enumerate(vessels):
            frac = np.arange(len(X)) / max(len(X) - 1, 1)
            if k == 0:  # contrast fades by `fade` from proximal to distal
                mus.append(mu0 * (1.0 - fade * frac))
            else:  # a branch starts at its origin's value and fades more slowly
                s_origin = np.argmin(np.linalg.norm(main_X - X[0], axis=1)) * SAMPLE_STEP_MM
                mus.append(mu0 * (1.0 - fade * s_origin / main_len) * (1.0 - 0.5 * fade * frac))
    prims = _cone_chain(vessels, mus)
    att_sub, _ = _attenuation_subpixels(view, prims, ss)
    background = _background_attenuation(rng, view)
    collimator = _collimator(rng, view)
    frame_index = n_frames - 1 - n_frames // 4
    period = rng.uniform(6.0, 12.0)
    drift = rng.normal(size=2)
    drift *= rng.uniform(0.8, 2.0) / np.linalg.norm(drift)
    frames = np.empty((n_frames, view.rows, view.cols), dtype=np.float32)
    for f in range(n_frames):
        if n_frames == 1:
            contrast, phase = 1.0, 0.0
        else:
            contrast = min(1.0, 0.2 + 0.8 * (f + 1) / (frame_index + 1))
            phase = np.sin(2 * np.pi * (f - frame_index) / period)
        vessel_t = _block_mean(np.exp(-contrast * att_sub), ss)
        if phase != 0.0:
            vessel_t = ndimage.shift(vessel_t, drift[::-1] * phase, order=1, mode="nearest")
        expected = PHOTONS_PER_PIXEL * np.exp(-background) * vessel_t * collimator
        counts = rng.poisson(expected).astype(float)
        blur = DETECTOR_BLUR_PX * (1.0 + 0.5 * abs(phase))
        counts = ndimage.gaussian_filter(counts, blur)
        value = counts * (BACKGROUND_LEVEL / PHOTONS_PER_PIXEL)
        frames[f] = np.clip(np.round(value), 0, MAX_VALUE)
    return frames, frame_index

