"""Elliptic lumen cross-sections along the 3D centerline (sec. 3.5 of the paper).

Each point X_i of the smoothed 3D centerline carries an ellipse in the plane
pi_i whose normal n_i is the spline tangent. Each view k contributes one
line through X_i in pi_i, the intersection of pi_i with the projection plane
pi_{k,i} through the X-ray source and the projected vessel diameter; its
half-length is the view's lumen radius already scaled to the vessel by
eq. (11). The longer line is the major axis; the minor semi-axis follows
from putting an endpoint of the shorter line on the ellipse.

:func:`elliptic_cross_sections` builds them for one centerline (the surface,
:mod:`recon.lumen.surface`); :func:`section_areas` gives the areas of many
centerlines of one length at once, each with its own view B (the intervals'
draws, :mod:`recon.pose.uncertainty`): every step but the axes' signs is a row's
own arithmetic, so the rows of the draws stacked give each draw's own bits.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from recon.geometry import ViewGeometry
from recon.lumen.densitometry import densitometric_sections
from recon.types import Centerline3D

FloatArray = NDArray[np.float64]

__all__ = [
    "CrossSections",
    "elliptic_cross_sections",
    "section_areas",
    "section_points",
    "intersection_directions",
]


# Below this sine of the angle between the two intersection lines the minor
# semi-axis is not observable from them; between the two bounds the solved
# value is blended with the shorter half-length (no jump).
_SIN_PARALLEL_LO = np.sin(np.deg2rad(10.0))
_SIN_PARALLEL_HI = np.sin(np.deg2rad(25.0))
_MIN_RADIUS_MM = 0.05

@dataclass(frozen=True, eq=False)
class CrossSections:
    """Elliptic lumen cross-sections along the 3D centerline (sec. 3.5).

    Attributes
    ----------
    centers : (M, 3) ellipse centres X_i, world mm.
    normals : (M, 3) unit plane normals n_i (the spline tangents).
    major_axis, minor_axis : (M, 3) unit in-plane axes; ``minor = normal x major``.
    major_mm, minor_mm : (M,) semi-axes in mm, ``major_mm >= minor_mm``.
    area_mm2 : (M,) ellipse areas pi * major * minor.
    """

    centers: FloatArray
    normals: FloatArray
    major_axis: FloatArray
    minor_axis: FloatArray
    major_mm: FloatArray
    minor_mm: FloatArray
    area_mm2: FloatArray

    def __len__(self) -> int:
        return len(self.centers)


def _unit(v: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Rows of v (N, 3) normalised, and their norms (N,)."""
    norm = np.linalg.norm(v, axis=1)
    return v / np.maximum(norm, 1e-300)[:, None], norm


def _check_centerline(cl3d: Centerline3D) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    X = np.asarray(cl3d.X_world, dtype=float)
    m = len(X)
    if X.shape != (m, 3) or m < 2:
        raise ValueError(f"Centerline3D.X_world must be (M>=2, 3), got {X.shape}")
    T = np.asarray(cl3d.tangents, dtype=float)
    r_a = np.asarray(cl3d.radius_a_mm, dtype=float)
    r_b = np.asarray(cl3d.radius_b_mm, dtype=float)
    if T.shape != (m, 3) or r_a.shape != (m,) or r_b.shape != (m,):
        raise ValueError(
            f"Centerline3D arrays disagree: X_world {X.shape}, tangents {T.shape}, "
            f"radius_a_mm {r_a.shape}, radius_b_mm {r_b.shape}"
        )
    if not (np.all(np.isfinite(X)) and np.all(np.isfinite(T))):
        raise ValueError("Centerline3D has non-finite points or tangents")
    if not (np.all(np.isfinite(r_a)) and np.all(np.isfinite(r_b))):
        raise ValueError("Centerline3D has non-finite radii")
    T, t_norm = _unit(T)
    if np.any(t_norm < 1e-9):
        raise ValueError("Centerline3D has zero-length tangents")
    r_a = np.maximum(r_a, _MIN_RADIUS_MM)
    r_b = np.maximum(r_b, _MIN_RADIUS_MM)
    return X, T, r_a, r_b


def intersection_directions(
    X_world: FloatArray, normals: FloatArray, view: ViewGeometry
) -> FloatArray:
    """Unit directions (M, 3) of the lines pi_i ∩ pi_{k,i} for one view k.

    pi_{k,i} is the plane through the source that contains the vessel
    diameter projected at X_i: it holds the ray r through X_i and the image
    normal w of the projected centerline lifted to 3D. The paper writes
    l = n x a with a = r x w. Since w is the back-projection of the normal
    of the plane (r, n), a is parallel to the tangent's component across
    the ray, and n x a = -(n . r) (n x r) up to second-order perspective
    terms: the paper's line is the direction of the cross-section plane
    perpendicular to the ray, but its length vanishes with n . r, i.e. for
    the most common vessel, perpendicular to the ray. We therefore compute
    the same line in its well-conditioned form ``unit(r x n)``. A vessel
    running along the ray (fully foreshortened) falls back to the view's
    column axis made perpendicular to n.

    Parameters
    ----------
    X_world : (M, 3) centerline points, world mm.
    normals : (M, 3) unit tangents n_i.
    view : the view k.

    Returns
    -------
    (M, 3) unit vectors, each perpendicular to its n_i.
    """
    return _intersection_lines(X_world, normals, [view])


def _intersection_lines(
    X_world: FloatArray, normals: FloatArray, views: Sequence[ViewGeometry]
) -> FloatArray:
    """:func:`intersection_directions` (N, 3) of n stacked blocks of N / n rows, block k
    seen by ``views[k]``: each row's own arithmetic, the fallback per block."""
    rows = len(X_world) // len(views)
    source = (views[0].source_world if all(v is views[0] for v in views)
              else np.repeat(np.stack([v.source_world for v in views]), rows, axis=0))
    ray, _ = _unit(X_world - source)
    line, norm = _unit(np.cross(ray, normals))
    bad = norm < 1e-6
    for k in np.unique(np.flatnonzero(bad) // rows):  # a block with a row along its ray
        block = slice(k * rows, (k + 1) * rows)
        _along_ray(line[block], bad[block], normals[block], views[k])
    return line


def _along_ray(line: FloatArray, bad: NDArray[np.bool_], normals: FloatArray,
               view: ViewGeometry) -> None:
    """Lines (N, 3), in place, at the ``bad`` (N,) rows, whose vessel runs along the ray:
    the view's column axis made perpendicular to the normal (N, 3), else its row axis."""
    for axis in view.R_view_from_world[:2]:  # column axis u, then row axis v
        alt = axis[None, :] - (normals[bad] @ axis)[:, None] * normals[bad]
        alt_unit, alt_norm = _unit(alt)
        ok = alt_norm > 1e-6
        idx = np.flatnonzero(bad)[ok]
        line[idx] = alt_unit[ok]
        bad[idx] = False


def _consistent_signs(major_dir: FloatArray) -> FloatArray:
    """Axes (M, 3) with signs flipped so that neighbours point the same way."""
    flips = np.sign(np.einsum("ij,ij->i", major_dir[1:], major_dir[:-1]))
    flips[flips == 0] = 1.0
    return major_dir * np.concatenate([[1.0], np.cumprod(flips)])[:, None]


def _consistent_signs_each(major_dir: FloatArray, rows: int) -> FloatArray:
    """:func:`_consistent_signs` of each block of ``rows`` rows of axes (N, 3)."""
    if len(major_dir) == rows:
        return _consistent_signs(major_dir)
    return np.concatenate([_consistent_signs(major_dir[k : k + rows])
                           for k in range(0, len(major_dir), rows)])


def _ellipses(
    cl3d: Centerline3D, T: FloatArray, r_a: FloatArray, r_b: FloatArray, l_a: FloatArray,
    l_b: FloatArray, rows: int,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Major and minor axes (N, 3) and semi-axes (N,), (N,) of the sections of
    :func:`elliptic_cross_sections` from the unit tangents T (N, 3), the radii (N,) and
    the intersection lines (N, 3); ``cl3d`` (N points) gives the fill ratios and the
    overlaps. N may hold several vessels of ``rows`` points each: only the axes' signs
    look along a vessel."""
    a_is_major = r_a >= r_b
    major_dir = np.where(a_is_major[:, None], l_a, l_b)
    short_dir = np.where(a_is_major[:, None], l_b, l_a)
    major_mm = np.maximum(r_a, r_b)
    short_mm = np.minimum(r_a, r_b)

    # Consistent axis signs along the vessel (an ellipse axis is defined up to sign).
    major_dir = _consistent_signs_each(major_dir, rows)
    minor_dir, _ = _unit(np.cross(T, major_dir))

    # Endpoint of the shorter intersection line in the (major, minor) frame.
    cos_t = np.einsum("ij,ij->i", short_dir, major_dir)
    sin_t = np.abs(np.einsum("ij,ij->i", short_dir, minor_dir))
    x = short_mm * cos_t
    y = short_mm * sin_t
    denom = 1.0 - (x / major_mm) ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        b_solved = np.where(denom > 1e-9, y / np.sqrt(np.maximum(denom, 1e-9)), short_mm)
    b_solved = np.clip(b_solved, _MIN_RADIUS_MM, major_mm)
    weight = np.clip((sin_t - _SIN_PARALLEL_LO) / (_SIN_PARALLEL_HI - _SIN_PARALLEL_LO), 0, 1)
    weight = np.where(denom > 1e-9, weight, 0.0)
    minor_mm = weight * b_solved + (1.0 - weight) * short_mm

    blended = densitometric_sections(cl3d, T, l_a, l_b, r_a, r_b, major_dir, major_mm,
                                     minor_mm, weight)
    if blended is not None:  # the densitometric area where the calipers disagree
        major_dir, major_mm, minor_mm = blended
        major_dir = _consistent_signs_each(major_dir, rows)
        minor_dir, _ = _unit(np.cross(T, major_dir))

    return major_dir, minor_dir, major_mm, minor_mm


def section_areas(
    centerlines: Sequence[Centerline3D], view_a: ViewGeometry, views_b: Sequence[ViewGeometry]
) -> FloatArray:
    """Areas (n, M) mm^2 of the sections of n centerlines of M points each, centerline k
    seen from ``view_a`` and ``views_b[k]``: row k is
    ``elliptic_cross_sections(centerlines[k], view_a, views_b[k]).area_mm2`` to the bit,
    computed on the n centerlines' points as one stack (the intervals' draws)."""
    n = len(centerlines)
    if n == 0 or len(views_b) != n:
        raise ValueError(f"section_areas needs one view B per centerline, got {n} "
                         f"centerlines and {len(views_b)} views")
    m = len(centerlines[0].X_world)
    if m < 2 or any(len(c.X_world) != m for c in centerlines):
        raise ValueError("section_areas needs centerlines of one length M >= 2")
    stacked = _stacked(centerlines)
    X, T, r_a, r_b = _check_centerline(stacked)
    l_a = _intersection_lines(X, T, [view_a] * n)
    l_b = _intersection_lines(X, T, views_b)
    _, _, major_mm, minor_mm = _ellipses(stacked, T, r_a, r_b, l_a, l_b, m)
    return (np.pi * major_mm * minor_mm).reshape(n, m)


def _stacked(centerlines: Sequence[Centerline3D]) -> Centerline3D:
    """One Centerline3D whose per-point arrays are the centerlines' (each (M, ...))
    one after another ((n M, ...)); the first one's other fields."""
    changes = {}
    for name in _PER_POINT:
        values = [getattr(c, name) for c in centerlines]
        missing = [v is None for v in values]
        if any(missing) and not all(missing):
            raise ValueError(f"{name} is None on some centerlines and not on others")
        if not any(missing):
            changes[name] = np.concatenate(values)
    return replace(centerlines[0], **changes)


#: The fields of a Centerline3D with one value per point.
_PER_POINT = ("X_world", "s_mm", "tangents", "radius_a_mm", "radius_b_mm", "overlap_a",
              "overlap_b", "depth_a", "depth_b", "fill_a", "fill_b", "fit_radius_a_mm",
              "fit_radius_b_mm")


def elliptic_cross_sections(
    cl3d: Centerline3D, view_a: ViewGeometry, view_b: ViewGeometry
) -> CrossSections:
    """Elliptic cross-sections of sec. 3.5 at every centerline point, vectorised.

    Parameters
    ----------
    cl3d : 3D centerline with (M,) radii ``radius_a_mm``, ``radius_b_mm``
        (eq. (11) already applied: half-lengths of the intersection lines).
    view_a, view_b : the two views (view B calibrated).

    Returns
    -------
    CrossSections with M ellipses.

    Notes
    -----
    With l_long (half-length a) the major axis and p = r_short l_short the
    endpoint of the shorter line, written (x, y) in the (major, minor)
    frame, the ellipse x^2/a^2 + y^2/b^2 = 1 gives
    b = |y| / sqrt(1 - x^2/a^2) <= a. When the two lines are nearly
    parallel (angle below 10 degrees) b is not observable and falls back to
    r_short; between 10 and 25 degrees the two values are blended linearly
    in the sine of the angle.

    That construction treats the shorter half-length as a point of the ellipse; it is
    the ellipse's support (caliper), so it is exact for circles only. Where ``cl3d``
    has densitometric fill ratios (:func:`recon.lumen.densitometry.with_fill_ratios`) and
    the two calipers disagree (:func:`recon.lumen.densitometry.densitometric_weight`), the
    section becomes the ellipse with both calipers and the densitometric area
    (:func:`recon.lumen.densitometry.blend_sections`), blended in as the calipers part.
    """
    X, T, r_a, r_b = _check_centerline(cl3d)
    l_a = intersection_directions(X, T, view_a)  # l_{a,i} = n_i x a_{a,i}
    l_b = intersection_directions(X, T, view_b)
    major_dir, minor_dir, major_mm, minor_mm = _ellipses(cl3d, T, r_a, r_b, l_a, l_b, len(X))
    return CrossSections(
        centers=X,
        normals=T,
        major_axis=major_dir,
        minor_axis=minor_dir,
        major_mm=major_mm,
        minor_mm=minor_mm,
        area_mm2=np.pi * major_mm * minor_mm,
    )


# ------------------------------------------------------------ point cloud
def section_points(sections: CrossSections, n_angles: int = 24) -> FloatArray:
    """Points at equal angles on every ellipse plus two half-ellipsoid caps.

    Parameters
    ----------
    sections : M cross-sections.
    n_angles : points per ellipse.

    Returns
    -------
    (M * n_angles + 2 * (n_rings * n_angles + 1), 3) world mm, with
    ``n_rings = max(2, n_angles // 4)`` latitude rings per cap; the cap's
    third semi-axis is sqrt(major * minor) (a hemisphere for a circle).
    """
    if n_angles < 3:
        raise ValueError(f"n_angles must be at least 3, got {n_angles}")
    phi = 2.0 * np.pi * np.arange(n_angles) / n_angles
    cos_p, sin_p = np.cos(phi), np.sin(phi)
    a_off = sections.major_mm[:, None] * cos_p[None, :]  # (M, n_angles)
    b_off = sections.minor_mm[:, None] * sin_p[None, :]
    ring = (
        a_off[..., None] * sections.major_axis[:, None, :]
        + b_off[..., None] * sections.minor_axis[:, None, :]
    )  # (M, n_angles, 3) offsets from the centres
    points = [(sections.centers[:, None, :] + ring).reshape(-1, 3)]
    n_rings = max(2, n_angles // 4)
    theta = 0.5 * np.pi * np.arange(1, n_rings + 1) / (n_rings + 1)  # latitude above the rim
    for end, outward in ((0, -1.0), (-1, 1.0)):
        c = np.sqrt(sections.major_mm[end] * sections.minor_mm[end])
        rim = ring[end]  # (n_angles, 3)
        cap = (
            sections.centers[end]
            + np.cos(theta)[:, None, None] * rim[None]
            + (outward * c * np.sin(theta))[:, None, None] * sections.normals[end]
        )
        pole = sections.centers[end] + outward * c * sections.normals[end]
        points += [cap.reshape(-1, 3), pole[None]]
    return np.concatenate(points)


