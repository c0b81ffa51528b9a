"""Vessel surface from elliptic cross-sections (sec. 3.5 of the paper).

Each point X_i of the smoothed 3D centerline carries an ellipse in the plane
pi_i whose normal n_i is the spline tangent (:mod:`recon.lumen.sections`, whose
names this module re-exports).

The surface is an implicit one, as in the paper: a signed distance
field of the swept ellipses (plus half-ellipsoid caps at both ends, the
paper's hemispherical point clouds) sampled in a narrow band on a voxel
grid, turned into a mesh by marching cubes and repaired into a watertight,
consistently wound, outward-facing ``trimesh.Trimesh`` in mm, world frame
of view A.

The mesh draws no semi-axis thinner than :data:`MESH_MIN_SEMI_AXIS_VOXELS` voxels: a
lumen narrower than the grid can sample would otherwise fall apart into pieces at its
neck. The sections (and so every measurement) keep their own sizes.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy.ndimage import maximum_filter1d, minimum_filter1d
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes

from recon.geometry import ViewGeometry
from recon.lumen.mesh_repair import pieces, repair
from recon.lumen.sections import (
    CrossSections,
    elliptic_cross_sections,
    intersection_directions,
    section_points,
)
from recon.types import Centerline3D, arclength

FloatArray = NDArray[np.float64]

__all__ = [
    "CrossSections",
    "SurfaceResult",
    "elliptic_cross_sections",
    "build_surface",
    "section_points",
    "intersection_directions",
    "default_voxel_mm",
    "TreeSurface",
    "build_tree_surface",
]


_MAX_GRID_VOXELS = 12_000_000
#: The least semi-axis the mesh draws, in voxels (a tube this thin keeps voxel centres
#: inside it all along its axis, whatever its direction through the grid).
MESH_MIN_SEMI_AXIS_VOXELS = 1.0
_CHUNK = 400_000  # shell voxels per distance pass of the tree's union
# Shell voxels per distance pass of one vessel: a pass's dozen (N, 3) and (N,) temporaries
# stay within a core's cache (on the demo's 138 k voxels ~10 % less CPU than one pass;
# a multiple of 4096, so that each pass's rows meet BLAS's kernels as in one pass).
_SDF_CHUNK = 32_768
_MC_BLOCK = 16  # cells along each edge of a marching-cubes block
# Voxels: one grid edge's vertex as given by two blocks differs by the float32 rounding of
# skimage's block-local coordinates (< 2e-6); two distinct vertices are > 5e-5 apart
# (the field is nudged 1e-4 voxel off the level, the band is 2 voxels).
_WELD_TOL = 1e-5


@dataclass(frozen=True, eq=False)
class SurfaceResult:
    """Output of :func:`build_surface`.

    Attributes
    ----------
    mesh : watertight triangle mesh, world mm (view A's frame), outward normals.
    sections : the elliptic cross-sections the surface was built from.
    point_cloud : (P, 3) points sampled at equal angles on every ellipse plus
        the two end caps (for display).
    voxel_mm : edge of the voxel grid used by marching cubes.
    """

    mesh: trimesh.Trimesh
    sections: CrossSections
    point_cloud: FloatArray
    voxel_mm: float


# ----------------------------------------------------------- distance field
def _ellipse_sdf(x: FloatArray, y: FloatArray, a: FloatArray, b: FloatArray,
                 a2: FloatArray | None = None, b2: FloatArray | None = None,
                 inside: FloatArray | None = None) -> FloatArray:
    """First-order signed distance (N,) of in-plane points to ellipses (exact for circles).

    d = (f - 1) / |grad f| with f = sqrt(x^2/a^2 + y^2/b^2). ``a2``, ``b2`` and
    ``inside`` (N,) are a^2, b^2 and -min(a, b) when the caller has them (the same bits).
    """
    a2 = a**2 if a2 is None else a2
    b2 = b**2 if b2 is None else b2
    inside = -np.minimum(a, b) if inside is None else inside
    f = np.sqrt((x / a) ** 2 + (y / b) ** 2)
    g = np.sqrt((x / a2) ** 2 + (y / b2) ** 2)
    return np.where(g > 1e-12, (f - 1.0) * f / np.maximum(g, 1e-12), inside)


def _ellipsoid_sdf(
    x: FloatArray, y: FloatArray, h: FloatArray, a: float, b: float, c: float
) -> FloatArray:
    """First-order signed distance (N,) to the ellipsoid with semi-axes a, b, c."""
    f = np.sqrt((x / a) ** 2 + (y / b) ** 2 + (h / c) ** 2)
    g = np.sqrt((x / a**2) ** 2 + (y / b**2) ** 2 + (h / c**2) ** 2)
    return np.where(g > 1e-12, (f - 1.0) * f / np.maximum(g, 1e-12), -min(a, b, c))


def _tube_sdf(points: FloatArray, sections: CrossSections, tree: cKDTree) -> FloatArray:
    """Signed distance (N,) of points (N, 3) to the swept-ellipse tube with end caps.

    Each point is attached to its nearest point C on the centerline polyline
    (segment j..j+1, parameter tau); its in-plane coordinates relative to C
    are measured in the frames of sections j and j+1 and the two ellipse
    distances are interpolated linearly in tau. Beyond the first / last
    centre the distance is that of the half-ellipsoid cap. The segments' vectors and
    squared lengths and the sections' squared semi-axes are taken once per section
    and gathered (the same bits as per point).
    """
    X = sections.centers
    m = len(X)
    seg_all = X[1:] - X[:-1]  # (M - 1, 3)
    seg_len2_all = np.maximum(np.einsum("ij,ij->i", seg_all, seg_all), 1e-18)
    _, nearest = tree.query(points)
    best_d2 = best_seg = best_tau = None
    for cand in (np.clip(nearest - 1, 0, m - 2), np.clip(nearest, 0, m - 2)):
        seg = seg_all[cand]
        diff = points - X[cand]
        tau = np.clip(np.einsum("ij,ij->i", diff, seg) / seg_len2_all[cand], 0.0, 1.0)
        # |points - p0 - tau seg|^2 one coordinate at a time, summed in np.sum's order
        r = [diff[:, k] - tau * seg[:, k] for k in range(3)]
        d2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2]
        if best_d2 is None:  # the first candidate: every distance is below inf
            best_d2, best_seg, best_tau = d2, cand, tau
            continue
        better = d2 < best_d2
        best_seg = np.where(better, cand, best_seg)
        best_tau = np.where(better, tau, best_tau)

    j0, j1, tau = best_seg, best_seg + 1, best_tau
    q = points - ((1.0 - tau)[:, None] * X[j0] + tau[:, None] * X[j1])
    a_mm, b_mm = sections.major_mm, sections.minor_mm
    a2_mm, b2_mm, inside = a_mm**2, b_mm**2, -np.minimum(a_mm, b_mm)
    sdf = np.zeros(len(points))
    for j, w in ((j0, 1.0 - tau), (j1, tau)):
        x = np.einsum("ij,ij->i", q, sections.major_axis[j])
        y = np.einsum("ij,ij->i", q, sections.minor_axis[j])
        sdf += w * _ellipse_sdf(x, y, a_mm[j], b_mm[j], a2_mm[j], b2_mm[j], inside[j])

    # Half-ellipsoid caps beyond both ends (the paper's hemispherical point clouds).
    for end, seg_index, tau_end, outward in ((0, 0, 0.0, -1.0), (m - 1, m - 2, 1.0, 1.0)):
        at_end = np.flatnonzero((best_seg == seg_index) & (best_tau == tau_end))
        r = points[at_end] - X[end]
        h = outward * (r @ sections.normals[end])
        on_cap = at_end[h > 0]
        if on_cap.size:
            a, b = float(sections.major_mm[end]), float(sections.minor_mm[end])
            rc = r[h > 0]
            sdf[on_cap] = _ellipsoid_sdf(
                rc @ sections.major_axis[end],
                rc @ sections.minor_axis[end],
                h[h > 0],
                a,
                b,
                float(np.sqrt(a * b)),
            )
    return sdf


def _drawable(sections: CrossSections, voxel_mm: float) -> CrossSections:
    """The sections with every semi-axis at least MESH_MIN_SEMI_AXIS_VOXELS voxels (for
    the distance field only)."""
    floor = MESH_MIN_SEMI_AXIS_VOXELS * voxel_mm
    if float(sections.minor_mm.min()) >= floor:
        return sections
    major = np.maximum(sections.major_mm, floor)
    minor = np.maximum(sections.minor_mm, floor)
    return replace(sections, major_mm=major, minor_mm=minor, area_mm2=np.pi * major * minor)


def default_voxel_mm(sections: CrossSections) -> float:
    """Voxel edge (mm) used when none is given: a fifth of the thin end of the
    minor semi-axes (5th percentile), clipped to [0.15, 0.25] mm (speed)."""
    thin = float(np.percentile(sections.minor_mm, 5))
    return float(np.clip(thin / 5.0, 0.15, 0.25))


def _ball_voxels(
    base: NDArray[np.int64], radius_vox: FloatArray, shape: tuple[int, int, int]
) -> NDArray[np.int64]:
    """Flat indices of voxels within radius_vox (K,) of voxel centres base (K, 3)."""
    r_max = int(np.ceil(max(float(radius_vox.max()), 0.0)))
    off = np.arange(-r_max, r_max + 1)
    grid = np.stack(np.meshgrid(off, off, off, indexing="ij"), axis=-1).reshape(-1, 3)
    norm = np.linalg.norm(grid, axis=1)
    order = np.argsort(norm, kind="stable")
    grid, norm = grid[order], norm[order]
    counts = np.searchsorted(norm, np.maximum(radius_vox, -1.0), side="right")
    within = np.arange(int(counts.sum())) - np.repeat(np.cumsum(counts) - counts, counts)
    dims = np.asarray(shape)
    strides = np.array([shape[1] * shape[2], shape[2], 1], dtype=np.int64)
    reach = np.ceil(np.maximum(radius_vox, 0.0)).astype(np.int64)
    inside = np.all((base >= reach[:, None]) & (base + reach[:, None] < dims), axis=1)
    if np.all(inside):
        # no ball leaves the grid: flat index of the centre plus the offset's
        return np.repeat(base @ strides, counts) + (grid @ strides)[within]
    # the balls within the grid as above, the others' voxels clipped to it (the same set)
    ball_of = np.repeat(inside, counts)
    flat_in = np.repeat(base[inside] @ strides, counts[inside]) + (grid @ strides)[within[ball_of]]
    edge = ~inside
    owner = np.repeat(np.flatnonzero(edge), counts[edge])
    idx = np.clip(base[owner] + grid[within[~ball_of]], 0, dims - 1)
    return np.concatenate([flat_in, np.ravel_multi_index(idx.T, shape)])


def _shell_voxels(
    sections: CrossSections,
    shape: tuple[int, int, int],
    lo: FloatArray,
    voxel: float,
    margin: float,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Voxels near the tube wall and voxels surely deep inside it (flat indices).

    Balls around centerline samples spaced ``step``: the outer ones (local
    largest semi-axis + margin, enlarged to cover the chords between samples)
    hold every voxel within ``margin`` of the wall; the inner ones (local
    smallest semi-axis - margin) are inside the tube. Returns
    (shell = outer minus inner, inner).
    """
    X = sections.centers
    s = arclength(X)
    step = 0.5  # mm between samples
    n = max(2, int(np.ceil(s[-1] / step)) + 1)
    s_k = np.linspace(0.0, s[-1], n)
    half_step = 0.5 * s[-1] / (n - 1)
    samples = np.stack([np.interp(s_k, s, X[:, k]) for k in range(3)], axis=1)
    # Local extremes of the semi-axes over the arc length a ball can reach.
    reach = float(sections.major_mm.max()) + margin + half_step
    ds = max(float(np.median(np.diff(s))), 1e-6) if len(s) > 1 else 1.0
    size = 2 * int(np.ceil(reach / ds)) + 1
    big = np.interp(s_k, s, maximum_filter1d(sections.major_mm, size, mode="nearest"))
    small = np.interp(s_k, s, minimum_filter1d(sections.minor_mm, size, mode="nearest"))
    base = np.rint((samples - lo) / voxel).astype(np.int64)
    # Rounding the sample to a voxel moves it by up to sqrt(3)/2 voxel.
    slack = 0.87 * voxel
    r_out = (np.sqrt((big + margin) ** 2 + half_step**2) + slack) / voxel
    r_in_mm = small - margin - slack
    r_in = np.where(r_in_mm > half_step, np.sqrt(np.maximum(r_in_mm**2 - half_step**2, 0)), -1)
    shell = np.zeros(int(np.prod(shape)), dtype=bool)
    shell[_ball_voxels(base, r_out, shape)] = True
    inner = (np.unique(_ball_voxels(base[r_in > 0], r_in[r_in > 0] / voxel, shape))
             if np.any(r_in > 0) else np.zeros(0, dtype=np.int64))
    shell[inner] = False
    return np.flatnonzero(shell), inner


def _marching_cubes_on_blocks(
    shape: tuple[int, int, int], band: float, wall: NDArray[np.int64],
    wall_values: FloatArray, inner: NDArray[np.int64],
) -> tuple[FloatArray, NDArray[np.int64]]:
    """Marching cubes (skimage's Lewiner) of the 0-level of a grid of ``shape``: ``wall_values``
    at the ``wall`` voxels, -``band`` at the ``inner`` ones (flat indices), +``band`` elsewhere
    and on its outer layer. Never built whole: the blocks of :data:`_MC_BLOCK`^3 cells with a
    ``wall`` corner get their corners, those with both signs are run one by one, a vertex two
    blocks share is welded: one call's mesh (vertices (V, 3) in voxels, faces (F, 3))."""
    n_cells = np.asarray(shape) - 1
    n_blocks = -(-n_cells // _MC_BLOCK)
    occupied = np.zeros(n_blocks, dtype=bool)
    corner = np.stack(np.unravel_index(wall, shape))  # (3, N)
    block_of = [np.minimum(c // _MC_BLOCK, n - 1) for c, n in zip(corner, n_blocks, strict=True)]
    occupied[tuple(block_of)] = True
    # A voxel on a block's lower face is also a corner of the cells of the block below.
    occupied[:-1] |= occupied[1:]
    occupied[:, :-1] |= occupied[:, 1:]
    occupied[:, :, :-1] |= occupied[:, :, 1:]
    starts = np.argwhere(occupied)
    slot = np.full(n_blocks, -1, dtype=np.int64)  # each occupied block's index in corners
    slot[tuple(starts.T)] = np.arange(len(starts))
    corners = np.full((len(starts),) + (_MC_BLOCK + 1,) * 3, band, dtype=np.float32)
    side = _MC_BLOCK + 1
    block_stride = np.array([n_blocks[1] * n_blocks[2], n_blocks[2], 1])
    corner_stride = np.array([side * side, side, 1])
    slot_flat, corners_flat = slot.reshape(-1), corners.reshape(-1)
    for ijk, values in ((np.stack(np.unravel_index(inner, shape)), np.full(len(inner), -band)),
                        (corner, wall_values)):
        keep = np.logical_and.reduce((ijk > 0) & (ijk < n_cells[:, None]))  # the outer layer
        ijk, values = ijk[:, keep], np.asarray(values, dtype=np.float32)[keep]  # stays +band
        block, local = ijk // _MC_BLOCK, ijk % _MC_BLOCK
        can = (local == 0) & (block > 0)  # on a block's lower face: the block below's too
        block_flat, local_flat = block_stride @ block, corner_stride @ local
        for use_below in np.ndindex(2, 2, 2):
            below = np.asarray(use_below, dtype=bool)
            if below.any():
                sel = np.flatnonzero(np.logical_and.reduce(can[below]))
                # on the face of the block below: that block's last corner along the axis
                k = slot_flat[block_flat[sel] - block_stride @ below]
                at = k * side**3 + local_flat[sel] + corner_stride @ (below * _MC_BLOCK)
                corners_flat[at[k >= 0]] = values[sel][k >= 0]
            else:
                k = slot_flat[block_flat]
                corners_flat[(k * side**3 + local_flat)[k >= 0]] = values[k >= 0]
    verts: list[FloatArray] = []
    faces: list[NDArray[np.int64]] = []
    n_verts, on_face = 0, []
    for k, start in enumerate(starts * _MC_BLOCK):
        size = np.minimum(start + _MC_BLOCK, n_cells) + 1 - start  # corners of its cells
        sub = corners[k, :size[0], :size[1], :size[2]]
        if not sub.min() < 0.0 < sub.max():
            continue
        v, f, _, _ = marching_cubes(sub, level=0.0)
        verts.append(v.astype(np.float64) + start)
        faces.append(f.astype(np.int64) + n_verts)
        n_verts += len(v)
        on_face.append(np.any((v == 0) | (v == size - 1), axis=1))  # can be shared
    if not verts:
        raise ValueError("the distance field has no surface (no sign change on the grid)")
    all_verts, all_faces = np.concatenate(verts), np.concatenate(faces)
    # Weld: a vertex 2-4 blocks share (on a common face) takes its copies' lowest index.
    cand = np.flatnonzero(np.concatenate(on_face))
    pairs = cand[cKDTree(all_verts[cand]).query_pairs(_WELD_TOL, output_type="ndarray")]
    label = np.arange(len(all_verts))
    if len(pairs):
        np.minimum.at(label, pairs[:, 1], pairs[:, 0])
    kept = label == np.arange(len(all_verts))
    new_index = (np.cumsum(kept) - 1)[label]
    return all_verts[kept], new_index[all_faces]


def build_surface(
    cl3d: Centerline3D,
    view_a: ViewGeometry,
    view_b: ViewGeometry,
    *,
    voxel_mm: float | None = None,
    n_angles: int = 24,
) -> SurfaceResult:
    """Watertight vessel surface from the elliptic sections (sec. 3.5).

    Parameters
    ----------
    cl3d : 3D centerline (M points, roughly uniform arc length) with radii.
    view_a, view_b : the two views (view B calibrated).
    voxel_mm : voxel edge of the distance-field grid; default
        :func:`default_voxel_mm`. Enlarged if the grid would exceed 12 M voxels.
    n_angles : points per ellipse in ``point_cloud``.

    Returns
    -------
    SurfaceResult; ``mesh`` is in mm, world frame of view A, watertight,
    winding-consistent, with outward normals (positive volume).
    """
    sections = elliptic_cross_sections(cl3d, view_a, view_b)
    cloud = section_points(sections, n_angles)
    voxel = default_voxel_mm(sections) if voxel_mm is None else float(voxel_mm)
    if not (np.isfinite(voxel) and voxel > 0):
        raise ValueError(f"voxel_mm must be a positive number, got {voxel_mm!r}")

    r_max = float(sections.major_mm.max())
    pad = r_max + 3.0 * voxel
    lo = sections.centers.min(axis=0) - pad
    hi = sections.centers.max(axis=0) + pad
    n_vox = float(np.prod((hi - lo) / voxel))
    if n_vox > _MAX_GRID_VOXELS:
        voxel *= (n_vox / _MAX_GRID_VOXELS) ** (1.0 / 3.0)
        pad = r_max + 3.0 * voxel
        lo = sections.centers.min(axis=0) - pad
        hi = sections.centers.max(axis=0) + pad
    shape = tuple(int(k) for k in np.ceil((hi - lo) / voxel).astype(int) + 1)

    band = 2.0 * voxel  # exact distances within this of the wall; the rest is only a sign
    drawn = _drawable(sections, voxel)
    shell, inner = _shell_voxels(drawn, shape, lo, voxel, band)
    wall_values = np.empty(len(shell), dtype=np.float32)
    tree = cKDTree(drawn.centers)
    for start in range(0, len(shell), _SDF_CHUNK):
        ijk = np.stack(np.unravel_index(shell[start : start + _SDF_CHUNK], shape), axis=1)
        wall_values[start : start + _SDF_CHUNK] = _tube_sdf(lo + ijk * voxel, drawn, tree)
    tiny = np.float32(1e-4 * voxel)  # exact zeros nudged off the level
    wall_values[np.abs(wall_values) < tiny] = tiny
    verts, faces = _marching_cubes_on_blocks(shape, band, shell, wall_values, inner)
    mesh = trimesh.Trimesh(vertices=verts * voxel + lo, faces=faces, process=False)  # welded
    mesh = repair(mesh)
    return SurfaceResult(mesh=mesh, sections=sections, point_cloud=cloud, voxel_mm=voxel)


# ------------------------------------------------------------------ the tree
#: Voxel budget of a tree's grid (float32: 160 MB): a tree's box is large,
#: but only the narrow band around its vessels gets exact distances.
_MAX_TREE_GRID_VOXELS = 40_000_000


@dataclass(frozen=True, eq=False)
class TreeSurface:
    """The union of several vessels' surfaces (:func:`build_tree_surface`).

    Attributes
    ----------
    mesh : watertight triangle mesh of the union, world mm, outward normals.
    components : separate pieces marching cubes produced (1 for a tree
        whose branches meet; the mesh keeps the largest).
    cavities : closed surfaces marching cubes left inside the union (a
        voxel or two the sampled distance field put outside; dropped from
        the mesh, counted here).
    specks : closed surfaces enclosing less than one voxel (a voxel of the
        sampled distance field put inside beside the union, where its inner
        core and the tube's exact distance disagree at a kink; dropped, counted
        here, not counted as pieces).
    voxel_mm : grid edge used.
    grid_voxels : voxels of the (dense, float32) distance grid.
    """

    mesh: trimesh.Trimesh
    components: int
    voxel_mm: float
    grid_voxels: int
    cavities: int = 0
    specks: int = 0


def build_tree_surface(
    sections: tuple[CrossSections, ...] | list[CrossSections], *, voxel_mm: float | None = None
) -> TreeSurface:
    """One watertight surface for the union of the vessels' swept ellipses.

    The signed distance of the union is the minimum of the vessels'
    distances; each vessel writes exact distances only in its own narrow
    band (:func:`_shell_voxels`) and "inside" into its core, so voxels far
    from every vessel are never evaluated and the union has no internal
    faces. One marching-cubes pass over the shared grid then gives the mesh.

    Parameters
    ----------
    sections : each vessel's cross-sections (M_k ellipses).
    voxel_mm : grid edge; default the finest :func:`default_voxel_mm` of the
        vessels, enlarged if the grid would exceed 40 M voxels.
    """
    sections = list(sections)
    if not sections:
        raise ValueError("build_tree_surface needs at least one vessel")
    voxel = (min(default_voxel_mm(sec) for sec in sections) if voxel_mm is None
             else float(voxel_mm))
    if not (np.isfinite(voxel) and voxel > 0):
        raise ValueError(f"voxel_mm must be a positive number, got {voxel_mm!r}")
    centers = np.vstack([sec.centers for sec in sections])
    r_max = max(float(sec.major_mm.max()) for sec in sections)
    lo = centers.min(axis=0) - (r_max + 3.0 * voxel)
    hi = centers.max(axis=0) + (r_max + 3.0 * voxel)
    n_vox = float(np.prod((hi - lo) / voxel))
    if n_vox > _MAX_TREE_GRID_VOXELS:
        voxel *= (n_vox / _MAX_TREE_GRID_VOXELS) ** (1.0 / 3.0)
        lo = centers.min(axis=0) - (r_max + 3.0 * voxel)
        hi = centers.max(axis=0) + (r_max + 3.0 * voxel)
    shape = tuple(int(k) for k in np.ceil((hi - lo) / voxel).astype(int) + 1)
    band = 2.0 * voxel
    grid = np.full(int(np.prod(shape)), band, dtype=np.float32)
    for sec in (_drawable(sec, voxel) for sec in sections):
        shell, inner = _shell_voxels(sec, shape, lo, voxel, band)
        grid[inner] = np.minimum(grid[inner], -band)
        tree = cKDTree(sec.centers)
        for start in range(0, len(shell), _CHUNK):
            chunk = shell[start : start + _CHUNK]
            ijk = np.stack(np.unravel_index(chunk, shape), axis=1)
            grid[chunk] = np.minimum(grid[chunk], _tube_sdf(lo + ijk * voxel, sec, tree))
    grid = grid.reshape(shape)
    grid[[0, -1], :, :] = band
    grid[:, [0, -1], :] = band
    grid[:, :, [0, -1]] = band
    tiny = np.float32(1e-4 * voxel)
    grid[np.abs(grid) < tiny] = tiny
    verts, faces, _, _ = marching_cubes(grid, level=0.0, spacing=(voxel, voxel, voxel))
    del grid
    mesh = trimesh.Trimesh(vertices=verts + lo, faces=faces, process=True)
    components, cavities, specks = pieces(mesh, speck_mm3=voxel**3)
    mesh = repair(mesh)
    return TreeSurface(mesh=mesh, components=components, voxel_mm=float(voxel),
                       grid_voxels=int(np.prod(shape)), cavities=cavities, specks=specks)
