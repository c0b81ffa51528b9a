"""Multiscale dark-ridge measure of one angiogram, with scales in millimetres.

For every Gaussian scale sigma the sigma^2-normalised Hessian gives the two
eigenvalues |l1| <= |l2| and the across-vessel direction (Frangi et al.,
"Multiscale vessel enhancement filtering", MICCAI 1998; dark vessels: l2 > 0).
Three factors per scale:

- blob term exp(-Rb^2 / 2 beta^2), Rb = l1 / l2 (Frangi eq. (13)): a line, not a blob;
- edge term exp(-Rg^2 / 2 gamma^2), Rg = sigma |dL/dn| / (sigma^2 l2): a ridge centre
  has no gradient across it, the inner side of a wide vessel's edge has
  (Koller et al., "Multiscale detection of curvilinear structures", ICCV 1995);
- structure term 1 - exp(-S^2 / 2 c^2), S = sqrt(l1^2 + l2^2) (Frangi eq. (15)), with c
  proportional to a low percentile of S over the field at that scale (a robust
  estimate of the background's Hessian norm), not to the image maximum: a vessel a few times
  above the background texture saturates whatever its contrast, so a faint
  narrowing scores like normal lumen.

The scale of a pixel is the one with the strongest scale-normalised ridge
centre (blob x edge x S, Lindeberg's sigma^2 normalisation). At that scale
``ridge`` = blob x structure (no edge term: where a branch leaves or two vessels
touch, the gradient across is not zero, and the route must not see a gap
there), ``strength`` = blob x edge x S / c marks ridge centres for snapping, and
``response`` is the classic per-image-normalised Frangi measure (c from the
strongest vessel) kept for display.

Scales come from a range of lumen radii in mm and the pixel size at the vessel
(``pixel_mm`` = detector spacing x SOD / SID). Scales above ~1.5 px are computed
on a Gaussian pyramid level (Burt & Adelson 1983, ``cv2.pyrDown``) and
interpolated back, so large vessels on fine detectors stay cheap.

Pixels are (col, row), 0-based; images are MONOCHROME2 (vessels dark).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage as ndi

__all__ = [
    "VesselnessMap",
    "compute_vesselness",
    "sigmas_for_pixel",
    "DEFAULT_SIGMAS_PX",
    "RADIUS_RANGE_MM",
    "RADIUS_PER_SIGMA",
]

F32 = NDArray[np.float32]

#: Scales (px) used when the pixel size at the vessel is unknown (0.39 mm detector
#: pixels at magnification 1.35: lumen radii ~1-8 px).
DEFAULT_SIGMAS_PX: tuple[float, ...] = (1.0, 1.5, 2.0, 3.0, 4.0)
#: Lumen radii (mm) the scales must cover when ``pixel_mm`` is given.
RADIUS_RANGE_MM: tuple[float, float] = (0.25, 3.0)
#: Radius (px) of a blurred cylinder whose sigma^2-normalised second derivative
#: at the centre peaks at sigma = 1 px (numerically, for radii 2-8 px).
RADIUS_PER_SIGMA = 1.17
_SCALE_RATIO = np.sqrt(2.0)
_MIN_SIGMA_PX = 1.0
#: Frangi's beta (blob term).
_BETA = 0.5
#: Width of the edge term (ratio of the gradient across to the curvature across).
_GAMMA = 0.5
#: c = this x the background's typical Hessian norm at each scale, taken as
#: _BG_SCALE x its 30th percentile over the field (the median of a field of noise;
#: unlike the median, it holds when a wide vessel covers half the field at a
#: large scale).
_KAPPA = 3.0
_BG_PERCENTILE = 30.0
_BG_SCALE = 1.4
#: A scale is computed on the coarsest pyramid level where it is still this many
#: level pixels.
_LEVEL_SIGMA_PX = 1.5
#: Rows per strip of the per-scale terms (their temporaries then fit in a core's cache).
_STRIP_ROWS = 32


@dataclass(frozen=True, eq=False)
class VesselnessMap:
    """Multiscale dark-ridge response of one image, computed once and reused.

    Attributes
    ----------
    response : (H, W) float32 in [0, 1], zero outside ``valid``: Frangi's measure
        with c from the image's strongest vessel, normalised per image (for display:
        a faint vessel scores low). The tracing uses ``ridge`` and ``strength``.
    scale_px : (H, W) float32, the Gaussian sigma (px) of the strongest ridge
        (lumen radius ~ ``RADIUS_PER_SIGMA`` x scale).
    valid : (H, W) bool, inside the collimated field and away from the image edge.
    direction_rad : (H, W) float32 in [0, pi), the vessel's direction (angle of
        the (col, row) tangent), or None.
    strength : (H, W) float32 >= 0, the ridge's signal-to-background ratio at its
        scale (blob x edge x S / c, unbounded), or None.
    sigmas_px : the scales used.
    pixel_mm : pixel size at the vessel (mm) the scales came from, or None.
    junction : (H, W) float32 in [0, 1], max over scales of structure x clip(l1 / l2,
        0, 1): high at the centre of a crossing or a junction (a dark blob, not a
        line), or None.
    ridge : (H, W) float32 in [0, 1], contrast-invariant: blob x structure with c
        from the background's Hessian norm (a faint vessel scores like a strong
        one; no edge term, so it stays high where a branch leaves or two vessels
        touch); the route's cost, band and checks use it. None: use ``response``.
    """

    response: F32
    scale_px: F32
    valid: NDArray[np.bool_]
    direction_rad: F32 | None = None
    strength: F32 | None = None
    sigmas_px: tuple[float, ...] = DEFAULT_SIGMAS_PX
    pixel_mm: float | None = None
    junction: F32 | None = None
    ridge: F32 | None = None

    @property
    def shape(self) -> tuple[int, int]:
        return self.response.shape  # type: ignore[return-value]

    def radius_px_at(self, points_px: ArrayLike) -> NDArray[np.float64]:
        """Lumen radius (N,) px implied by the best scale at points (N, 2) (col, row)."""
        p = np.asarray(points_px, dtype=float).reshape(-1, 2)
        s = ndi.map_coordinates(self.scale_px, [p[:, 1], p[:, 0]], order=0, mode="nearest")
        return RADIUS_PER_SIGMA * s.astype(float)


def sigmas_for_pixel(
    pixel_mm: float | None, radius_range_mm: tuple[float, float] = RADIUS_RANGE_MM
) -> tuple[float, ...]:
    """Hessian scales (px) covering lumen radii ``radius_range_mm`` at ``pixel_mm``.

    sigma = radius / RADIUS_PER_SIGMA, at least 1 px, in steps of sqrt(2);
    :data:`DEFAULT_SIGMAS_PX` when ``pixel_mm`` is None.
    """
    if pixel_mm is None:
        return DEFAULT_SIGMAS_PX
    if not (np.isfinite(pixel_mm) and pixel_mm > 0):
        raise ValueError(f"pixel_mm must be positive, got {pixel_mm!r}")
    r_lo, r_hi = (float(v) for v in radius_range_mm)
    if not 0 < r_lo <= r_hi:
        raise ValueError(f"radius_range_mm must be 0 < lo <= hi, got {radius_range_mm!r}")
    lo = max(_MIN_SIGMA_PX, r_lo / pixel_mm / RADIUS_PER_SIGMA)
    hi = max(lo, r_hi / pixel_mm / RADIUS_PER_SIGMA)
    n = int(np.ceil(np.log(hi / lo) / np.log(_SCALE_RATIO) - 1e-9)) + 1
    return tuple(float(s) for s in np.geomspace(lo, hi, max(n, 1)))


# --------------------------------------------------------------- the field
def field_mask(image: F32, margin_px: float) -> NDArray[np.bool_]:
    """Collimated field (H, W) bool, eroded by ``margin_px`` and away from the image edge.

    The black collimator border is the near-constant dark band touching the image
    edge. When the outer frame is much darker than the image median, the field is
    the convex hull of the largest bright region (vessels touching the border are
    filled back in); otherwise the whole image is the field.
    """
    return _distance_inside(_raw_field(image)) > margin_px


def _distance_inside(field: NDArray[np.bool_]) -> NDArray[np.float32]:
    """Euclidean distance (H, W) of each field pixel to the nearest non-field pixel
    or image edge (0 outside the field)."""
    f = field.astype(np.uint8)
    f[0, :] = f[-1, :] = f[:, 0] = f[:, -1] = 0
    return cv2.distanceTransform(f, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def _raw_field(image: F32) -> NDArray[np.bool_]:
    h, w = image.shape
    frame = np.concatenate([image[:2].ravel(), image[-2:].ravel(),
                            image[:, :2].ravel(), image[:, -2:].ravel()])
    lo = float(np.median(frame))
    sub = image[::4, ::4]
    mid = float(np.median(sub))
    p1, p99 = np.percentile(sub, [1.0, 99.0])
    field = np.ones((h, w), dtype=bool)
    if mid - lo > 0.3 * max(float(p99 - p1), 1e-12):
        bright = (image > lo + 0.5 * (mid - lo)).astype(np.uint8)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(bright, connectivity=8)
        if n > 1:
            k = 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))
            field = _convex_fill(labels == k)
    return field


def _convex_fill(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Convex hull (H, W) bool of a mask (cv2 on the outer contour's points)."""
    contours, _ = cv2.findContours(mask.astype(np.uint8), cv2.RETR_EXTERNAL,
                                   cv2.CHAIN_APPROX_SIMPLE)
    hull = cv2.convexHull(np.concatenate(contours))
    out = np.zeros(mask.shape, dtype=np.uint8)
    cv2.fillConvexPoly(out, hull, 1)
    return out.astype(bool)


def _fill_outside(image: F32, field: NDArray[np.bool_]) -> F32:
    """The image (H, W) with the pixels outside ``field`` (eroded 2 px) replaced by a
    smooth extension of the field (normalised convolution, Knutsson & Westin 1993:
    near the edge at 6 px, farther out at 1/16 of the image size), so that large
    scales do not see the collimator edge."""
    inner = cv2.erode(field.astype(np.uint8), np.ones((5, 5), np.uint8)).astype(bool)
    if inner.all() or not inner.any():
        return image
    m = inner.astype(np.float32)
    h, w = image.shape
    ext = np.full(image.shape, float(np.median(image[inner][::7])), np.float32)
    for sigma, shrink in ((max(h, w) / 16.0, 8), (6.0, 1)):
        small = (max(w // shrink, 1), max(h // shrink, 1))
        num = cv2.resize(image * m, small, interpolation=cv2.INTER_AREA)
        den = cv2.resize(m, small, interpolation=cv2.INTER_AREA)
        num = cv2.GaussianBlur(num, (0, 0), sigma / shrink)
        den = cv2.GaussianBlur(den, (0, 0), sigma / shrink)
        if shrink > 1:
            num = cv2.resize(num, (w, h), interpolation=cv2.INTER_LINEAR)
            den = cv2.resize(den, (w, h), interpolation=cv2.INTER_LINEAR)
        ok = den > 0.02
        ext = np.where(ok, num / np.maximum(den, 1e-6), ext)
    return np.where(inner, image, ext).astype(np.float32)


# ---------------------------------------------------------- one scale's terms
def _padded_smooth(level: F32, residual_px: float) -> F32:
    """The level (h, w) blurred by ``residual_px`` and edge-padded by one pixel (h + 2, w + 2)."""
    smooth = cv2.GaussianBlur(level, (0, 0), residual_px, borderType=cv2.BORDER_REFLECT)
    return np.pad(smooth, 1, mode="edge")


def _derivatives(p: F32, sigma_level_px: float, step: int = 1) -> tuple[F32, ...]:
    """Scale-normalised hxx, hyy, hxy (d2/dcol2, d2/drow2, d2/dcol drow) and gx, gy by
    central differences at every ``step``-th row and column of the padded ``p``'s inner
    pixels (all (h, w) float32 for ``step`` 1)."""
    i, o = slice(1, -1, step), slice(0, -2, step)  # the pixel, the one before
    n = slice(2, None, step)  # the one after
    c, n_, s_, w_, e_ = p[i, i], p[o, i], p[n, i], p[i, o], p[i, n]
    s2 = np.float32(sigma_level_px**2)
    c2 = 2.0 * c
    hxx = (e_ - c2 + w_) * s2
    hyy = (s_ - c2 + n_) * s2
    hxy = 0.25 * (p[n, n] - p[n, o] - p[o, n] + p[o, o]) * s2
    gx = 0.5 * (e_ - w_) * np.float32(sigma_level_px)
    gy = 0.5 * (s_ - n_) * np.float32(sigma_level_px)
    return hxx, hyy, hxy, gx, gy


def _eigen(hxx: F32, hyy: F32, hxy: F32) -> tuple[F32, F32, F32, F32]:
    """(dxy, disc, l1, l2) of the Hessians: |l1| <= |l2|, dxy = (hxx - hyy) / 2 and
    disc = half the eigenvalues' difference."""
    half_tr = 0.5 * (hxx + hyy)
    dxy = 0.5 * (hxx - hyy)
    disc = np.sqrt(dxy * dxy + hxy * hxy)
    e_hi, e_lo = half_tr + disc, half_tr - disc  # algebraic: e_hi >= e_lo
    l2 = e_lo.copy()
    _select_into(l2, e_hi, _mask32(np.abs(e_hi) >= np.abs(e_lo)))
    l1 = 2.0 * half_tr - l2
    return dxy, disc, l1, l2


def _s_norm_sub(p: F32, sigma_level_px: float) -> F32:
    """S (sigma^2-normalised Hessian norm) at every other row and column of the level."""
    hxx, hyy, hxy, _, _ = _derivatives(p, sigma_level_px, step=2)
    _, _, l1, l2 = _eigen(hxx, hyy, hxy)
    return np.sqrt(l1 * l1 + l2 * l2)


def _ridge_terms(p: F32, sigma_level_px: float) -> tuple[F32, ...]:
    """Per-pixel ridge terms of one scale on rows of one pyramid level, from the padded
    smoothed level ``p`` (:func:`_padded_smooth`; all (h, w) float32, h = rows of ``p`` - 2).

    Returns the blob term, the edge term, the dark-blob ratio clip(l1 / l2, 0, 1)
    (1 at the centre of a crossing or a junction), S (sigma^2-normalised Hessian
    norm) and the vessel direction's cos 2theta, sin 2theta (theta = angle of the
    (col, row) tangent).
    """
    hxx, hyy, hxy, gx, gy = _derivatives(p, sigma_level_px)
    dxy, disc, l1, l2 = _eigen(hxx, hyy, hxy)
    f32 = np.float32
    # Across-vessel direction = eigenvector of e_hi (the dark ridge's l2 > 0).
    r = np.maximum(disc, f32(1e-20))
    cos2a, sin2a = dxy / r, hxy / r  # angle 2*alpha of the across direction
    # cos alpha, |sin alpha| = sqrt((1 +- cos 2alpha) / 2); the terms below are computed
    # in place (the same float32 operations, fewer temporaries)
    cos_a = np.add(cos2a, f32(1.0))
    cos_a *= f32(0.5)
    _clip01(cos_a)
    np.sqrt(cos_a, out=cos_a)
    sin_a = np.subtract(f32(1.0), cos2a)
    sin_a *= f32(0.5)
    _clip01(sin_a)
    np.sqrt(sin_a, out=sin_a)
    sin_a *= np.sign(sin2a + f32(1e-30))
    grad_across = gx * cos_a
    grad_across += gy * sin_a
    np.abs(grad_across, out=grad_across)
    pos = _mask32(l2 > 0)
    l2_safe = np.full_like(l2, 1.0)
    _select_into(l2_safe, l2, pos)  # l2 where l2 > 0, else 1
    ratio = l1 / l2_safe
    rb2 = np.square(ratio)
    rg2 = np.divide(grad_across, l2_safe, out=grad_across)
    np.square(rg2, out=rg2)
    blob = _where_pos_exp(pos, rb2, f32(2 * _BETA**2))
    edge = _where_pos_exp(pos, rg2, f32(2 * _GAMMA**2))
    dark_blob = _clip01(ratio)
    _zero_outside(dark_blob, pos)  # 1: l1 = l2 > 0
    s_norm = np.square(l1)
    s_norm += np.square(l2)
    np.sqrt(s_norm, out=s_norm)
    # tangent = across + 90 deg: 2*theta = 2*alpha + 180 deg.
    np.negative(cos2a, out=cos2a)
    np.negative(sin2a, out=sin2a)
    return blob, edge, dark_blob, s_norm, cos2a, sin2a


def _clip01(x: F32) -> F32:
    """x (float32) clipped to [0, 1] in place."""
    return np.clip(x, 0.0, 1.0, out=x)


def _where_pos_exp(pos: NDArray[np.uint32], sq: F32, two_w2: np.float32) -> F32:
    """exp(-sq / two_w2) where ``pos`` (:func:`_mask32`), else 0 (float32; ``sq`` is
    overwritten)."""
    np.negative(sq, out=sq)
    sq /= two_w2
    np.exp(sq, out=sq)
    return _zero_outside(sq, pos)


def _zero_outside(x: F32, mask: NDArray[np.uint32]) -> F32:
    """x (float32) set to +0 where ``mask`` (:func:`_mask32`) is clear, in place."""
    v = x.view(np.uint32)
    np.bitwise_and(v, mask, out=v)
    return x


def _best_over_scales(shape: tuple[int, int], scales: list[tuple[F32, float, float, float]],
                      up: list[F32] | None) -> list[F32]:
    """One level's layers (best, log sigma, ridge, ratio, cos2, sin2, blob, S, then the
    junction measure; each (h, w)): per pixel the strongest of the level's scales
    (``scales``: padded smoothed level, sigma in level px, sigma px, c) and of the
    coarser levels' layers ``up`` (already at this level's size), ties to the first.

    Computed in strips of :data:`_STRIP_ROWS` rows, the same arithmetic per pixel: a
    strip's temporaries stay in the processor's cache where a dozen whole-image
    temporaries per scale would stream through memory.
    """
    out = [np.empty(shape, np.float32) for _ in range(9)]
    for r0 in range(0, shape[0], _STRIP_ROWS):
        r1 = min(r0 + _STRIP_ROWS, shape[0])
        dst = [a[r0:r1] for a in out]  # the strip's layers, updated in place
        first = True
        for p, s_lv, s, c in scales:
            blob, edge, dark_blob, s_norm, c2t, s2t = _ridge_terms(p[r0:r1 + 2], s_lv)
            strength = np.multiply(blob, edge, out=edge)
            strength *= s_norm
            # struct = 1 - exp(-min(S / c, 1e3)^2 / 2), in place
            struct = s_norm * np.float32(1.0 / c)
            np.minimum(struct, 1e3, out=struct)
            np.square(struct, out=struct)
            np.negative(struct, out=struct)
            struct /= np.float32(2.0)
            np.exp(struct, out=struct)
            np.subtract(np.float32(1.0), struct, out=struct)
            layer = [strength, np.log(s), blob * struct, strength * np.float32(1.0 / c), c2t,
                     s2t, blob, s_norm]
            jb = np.multiply(dark_blob, struct, out=dark_blob)
            _keep_stronger(dst, layer, jb, first)
            first = False
        if up is not None:
            u = [a[r0:r1] for a in up]
            _keep_stronger(dst, u[:8], u[8], first)
            first = False
        assert not first
    return out


def _upsample2(arr: F32, shape: tuple[int, int]) -> F32:
    """Bilinear map of one pyramid level to the next finer one (h, w) (coarse pixel j
    <-> fine pixel 2j, the ``cv2.pyrDown`` convention)."""
    m = np.array([[0.5, 0.0, 0.0], [0.0, 0.5, 0.0]], dtype=np.float64)
    return cv2.warpAffine(arr, m, (shape[1], shape[0]), flags=cv2.INTER_LINEAR
                          | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)


def _keep_stronger(dst: list[F32], layer: list, junction: F32, first: bool) -> None:
    """Per pixel, the layers ``dst`` (list of (h, w) arrays, strength first; updated in
    place) or ``layer`` (arrays or scalars) if that is stronger, ties to ``dst``; the
    junction measure ``dst[8]`` the larger of its own and ``junction``. ``first``:
    ``dst`` holds nothing yet and takes ``layer``."""
    if first:
        for d, y in zip(dst, [*layer, junction], strict=True):
            d[...] = y
        return
    take = _mask32(layer[0] > dst[0])
    for d, y in zip(dst[:8], layer, strict=True):
        _select_into(d, np.broadcast_to(np.float32(y), d.shape) if np.ndim(y) == 0 else y,
                     take)
    np.maximum(dst[8], junction, out=dst[8])


def _mask32(cond: NDArray[np.bool_]) -> NDArray[np.uint32]:
    """All 32 bits set where ``cond``, none elsewhere (for :func:`_select_into`)."""
    m = cond.astype(np.uint32)
    return np.negative(m, out=m)


def _select_into(dst: F32, src: F32, mask: NDArray[np.uint32]) -> None:
    """``dst`` (float32) takes ``src``'s values where ``mask`` (:func:`_mask32`), in place:
    np.where's result, by bit operations (a data-dependent branch per pixel, as in
    np.where and np.copyto, is several times slower on a noisy mask)."""
    d = dst.view(np.uint32)
    t = np.bitwise_xor(d, src.view(np.uint32))
    t &= mask
    d ^= t


def _level_for(sigma_px: float) -> int:
    return max(0, int(np.floor(np.log2(sigma_px / _LEVEL_SIGMA_PX) + 1e-9)))


def compute_vesselness(
    image: ArrayLike,
    *,
    pixel_mm: float | None = None,
    sigmas_px: tuple[float, ...] | None = None,
    radius_range_mm: tuple[float, float] = RADIUS_RANGE_MM,
) -> VesselnessMap:
    """Contrast-invariant multiscale vesselness for dark tubes (module docstring).

    Parameters
    ----------
    image : (H, W) float, MONOCHROME2 (vessels darker than the background).
    pixel_mm : pixel size at the vessel (mm): detector spacing x SOD / SID. Sets
        the scales from ``radius_range_mm``; None: :data:`DEFAULT_SIGMAS_PX`.
    sigmas_px : explicit Gaussian scales (px); overrides ``pixel_mm``.
    radius_range_mm : lumen radii (mm) to cover when ``pixel_mm`` is given.

    Returns
    -------
    VesselnessMap: response (H, W) in [0, 1] (zero outside the collimated field),
    best scale (H, W), field mask (H, W), direction (H, W), strength (H, W).
    """
    img = np.asarray(image, dtype=np.float32)
    if img.ndim != 2 or min(img.shape) < 8:
        raise ValueError(f"image must be (H, W) with H, W >= 8, got shape {img.shape}")
    if not np.all(np.isfinite(img)):
        raise ValueError("image contains NaN or infinite values")
    sig = sigmas_for_pixel(pixel_mm, radius_range_mm) if sigmas_px is None else sigmas_px
    sigmas = np.asarray(sig, dtype=float)
    if sigmas.ndim != 1 or len(sigmas) == 0 or np.any(sigmas <= 0):
        raise ValueError(f"sigmas_px must be positive, got {sig!r}")
    sigmas = np.sort(sigmas)
    raw = _raw_field(img)
    valid = _distance_inside(raw) > 2.0 * min(float(sigmas.max()), 4.0) + 1.0
    filled = _fill_outside(img, raw)

    # Each scale on its pyramid level; per level the best scale (blob x edge x S,
    # scale-normalised) is kept, then the levels are merged coarse to fine.
    level_of = [_level_for(float(v)) for v in sigmas]
    n_lv = max(level_of) + 1
    levels, acc_blur = [filled], [0.0]  # accumulated pyramid blur (level px)
    while len(levels) < n_lv:
        levels.append(cv2.pyrDown(levels[-1]))
        acc_blur.append(float(np.sqrt(acc_blur[-1] ** 2 + 1.0) / 2.0))
    # c is never below 1e-4 of the field's value range (a noise-free image).
    inside = img[::4, ::4][valid[::4, ::4]] if np.any(valid[::4, ::4]) else img.ravel()
    p_lo, p_hi = np.percentile(inside, [0.5, 99.5]) if inside.size else (0.0, 1.0)
    c_floor = max(1e-4 * float(p_hi - p_lo), 1e-20)
    merged: list[F32] | None = None  # best, log sigma, ridge, ratio, cos2, sin2, blob, S, jb
    for lv in range(n_lv - 1, -1, -1):
        lvl = levels[lv]
        field_sub = valid[:: 2 << lv, :: 2 << lv][: (lvl.shape[0] + 1) // 2,
                                                 : (lvl.shape[1] + 1) // 2]
        scales = []
        for s in sigmas[[i for i, v in enumerate(level_of) if v == lv]]:
            s_lv = float(s) / (1 << lv)
            residual = float(np.sqrt(max(s_lv**2 - acc_blur[lv] ** 2, 0.09)))
            p = _padded_smooth(lvl, residual)
            ref = _s_norm_sub(p, s_lv)[field_sub]
            c = max(_KAPPA * _BG_SCALE * float(np.percentile(ref, _BG_PERCENTILE))
                    if ref.size else 0.0, c_floor)
            scales.append((p, s_lv, float(s), c))
        up = None if merged is None else [_upsample2(a, lvl.shape) for a in merged]
        merged = _best_over_scales(lvl.shape, scales, up)
    assert merged is not None
    _, log_s, ridge, snr, cos2, sin2, blob, s_norm, merged_jb = merged
    scale = np.exp(log_s).astype(np.float32)
    # The display response: Frangi's structure constant from the image's strongest
    # Hessian norm (half of it), normalised by the 99.9th percentile (as before the
    # contrast-invariant measure; vessels as strong as the strongest score ~1).
    s_in = s_norm[valid] if np.any(valid) else s_norm.ravel()
    c_img = max(0.5 * float(s_in.max()) if s_in.size else 0.0, c_floor)
    resp = blob * (1.0 - np.exp(-0.5 * (s_norm * np.float32(1.0 / c_img)) ** 2))
    in_field = _mask32(valid)
    _zero_outside(resp, in_field)
    norm = float(np.percentile(resp[valid], 99.9)) if np.any(valid) else 0.0
    resp = np.clip(resp / norm, 0.0, 1.0) if norm > 0 else np.clip(resp, 0.0, 1.0)
    direction = (0.5 * np.arctan2(sin2, cos2)) % np.pi
    # the merged layers are this call's own arrays: masked in place
    return VesselnessMap(
        response=resp.astype(np.float32, copy=False),
        scale_px=scale,
        valid=valid,
        direction_rad=direction.astype(np.float32, copy=False),
        strength=_zero_outside(snr, in_field),
        junction=_zero_outside(merged_jb, in_field),
        ridge=_zero_outside(_clip01(ridge), in_field),
        sigmas_px=tuple(float(v) for v in sigmas),
        pixel_mm=None if pixel_mm is None else float(pixel_mm),
    )
