"""Marching cubes on the blocks the surface crosses gives the mesh of one call over the grid."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes

import recon.lumen.mesh_repair as mesh_repair
import recon.lumen.surface as surface


def _bent_tube_field(shape: tuple[int, int, int], band: float,
                     wall_halfwidth: float) -> tuple[np.ndarray, np.ndarray]:
    """A torus section's signed distance where it is below ``wall_halfwidth`` (voxels) in
    magnitude, +-band elsewhere, like build_surface's grid (exact values on a shell,
    only the sign off it), nudged off 0; returns (grid, flat indices of the shell)."""
    i, j, k = np.meshgrid(*(np.arange(n, dtype=float) for n in shape), indexing="ij")
    ring = np.hypot(i - 3.0, j - 3.0) - 0.6 * min(shape[:2])  # a quarter ring about (3, 3)
    sdf = np.hypot(ring, k - shape[2] / 2.0) - 4.3
    # 1-Lipschitz: a cell's corners are within sqrt(3) of each other, so with a half-width
    # above sqrt(3) / 2 every sign change still has a shell corner
    grid = np.where(np.abs(sdf) < wall_halfwidth, sdf, np.sign(sdf) * band).astype(np.float32)
    grid[[0, -1]] = band
    grid[:, [0, -1]] = band
    grid[:, :, [0, -1]] = band
    tiny = np.float32(1e-4)
    grid[np.abs(grid) < tiny] = tiny
    wall = np.flatnonzero(np.abs(sdf.ravel()) < wall_halfwidth)
    return grid, wall


def _blocks(grid: np.ndarray, wall: np.ndarray, band: float) -> tuple[np.ndarray, np.ndarray]:
    """surface._marching_cubes_on_blocks given the grid's wall values and its inside voxels."""
    flat = grid.ravel()
    return surface._marching_cubes_on_blocks(grid.shape, band, wall, flat[wall],
                                             np.flatnonzero(flat == -band))


def _triangles(faces: np.ndarray) -> set[tuple[int, int, int]]:
    """Each face rotated to start at its smallest vertex index (so that the winding counts)."""
    start = np.argmin(faces, axis=1)
    rolled = np.stack([faces[np.arange(len(faces)), (start + k) % 3] for k in range(3)], axis=1)
    return {tuple(int(i) for i in row) for row in rolled}


@pytest.mark.parametrize("wall_halfwidth", [0.9, 2.0])
@pytest.mark.parametrize("block", [3, 5, 16])
def test_block_marching_cubes_equals_one_call_over_the_grid(
    block: int, wall_halfwidth: float, monkeypatch: pytest.MonkeyPatch
) -> None:
    grid, wall = _bent_tube_field((30, 34, 17), band=2.0, wall_halfwidth=wall_halfwidth)
    monkeypatch.setattr(surface, "_MC_BLOCK", block)
    verts, faces = _blocks(grid, wall, band=2.0)
    ref_verts, ref_faces, _, _ = marching_cubes(grid, level=0.0)

    assert len(verts) == len(ref_verts) and len(faces) == len(ref_faces)
    # the same vertices up to skimage's float32 coordinates (global in the one call,
    # block-local here), and the same triangles with the same winding
    dist, same = cKDTree(ref_verts).query(verts)
    assert dist.max() < 1e-5
    assert len(np.unique(same)) == len(ref_verts)
    assert _triangles(same[faces]) == _triangles(ref_faces)
    mesh = trimesh.Trimesh(verts, faces, process=False)
    ref = trimesh.Trimesh(ref_verts, ref_faces, process=False)
    assert mesh.is_watertight and ref.is_watertight
    assert mesh.volume == pytest.approx(ref.volume, rel=1e-6)


def test_block_marching_cubes_without_a_surface_is_refused() -> None:
    grid = np.full((10, 10, 10), 2.0, dtype=np.float32)
    with pytest.raises(ValueError, match="no surface"):
        _blocks(grid, np.arange(10), band=2.0)


def test_signed_volume_agrees_with_trimesh_and_tells_the_winding():
    from recon.lumen.mesh_repair import signed_volume

    box = trimesh.creation.box(extents=(2.0, 3.0, 4.0))
    box.apply_translation((5.0, -7.0, 11.0))  # away from the origin: the tetrahedra cancel
    assert signed_volume(box.vertices, box.faces) == pytest.approx(24.0, rel=1e-12)
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=2.5)
    assert signed_volume(sphere.vertices, sphere.faces) == pytest.approx(sphere.volume, rel=1e-12)
    assert signed_volume(sphere.vertices, sphere.faces[:, ::-1]) == pytest.approx(-sphere.volume,
                                                                                  rel=1e-12)


def _as_set(pairs: np.ndarray) -> set[tuple[int, int]]:
    return {tuple(int(i) for i in row) for row in np.sort(pairs, axis=1)}


@pytest.mark.parametrize("case", ["tube", "open", "flipped", "two pieces"])
def test_shared_edges_agree_with_trimesh(case: str) -> None:
    grid, wall = _bent_tube_field((30, 34, 17), band=2.0, wall_halfwidth=2.0)
    tube = trimesh.Trimesh(*_blocks(grid, wall, band=2.0), process=False)
    box = trimesh.creation.box()
    flipped = box.faces.copy()
    flipped[3] = flipped[3][::-1]
    mesh = {"tube": tube,
            "open": trimesh.Trimesh(box.vertices, box.faces[:-1], process=False),
            "flipped": trimesh.Trimesh(box.vertices, flipped, process=False),
            "two pieces": trimesh.util.concatenate(
                [box, box.copy().apply_translation([5.0, 0.0, 0.0])])}[case]
    pairs, closed, consistent = mesh_repair.shared_edges(np.asarray(mesh.faces))
    assert _as_set(pairs) == _as_set(mesh.face_adjacency)
    assert closed == mesh.is_watertight
    assert consistent == mesh.is_winding_consistent
    assert (closed, consistent) == {"tube": (True, True), "open": (False, True),
                                    "flipped": (True, False), "two pieces": (True, True)}[case]


def test_ball_voxels_are_the_clipped_balls_near_and_away_from_the_edges() -> None:
    """surface._ball_voxels: the voxels within each ball's radius of its centre, clipped
    to the grid, whether a ball lies inside the grid, reaches past its edge, or is empty."""
    rng = np.random.default_rng(3)
    shape = (14, 17, 11)
    base = np.concatenate([rng.integers(0, shape, size=(20, 3)),  # many reach past an edge
                           np.array([[7, 8, 5], [0, 0, 0], [13, 16, 10]])])
    radius = np.concatenate([rng.uniform(0.0, 4.5, 20), [3.2, -1.0, 2.0]])
    got = surface._ball_voxels(base, radius, shape)
    ii, jj, kk = np.meshgrid(*(np.arange(-5, 6),) * 3, indexing="ij")
    offsets = np.stack([ii.ravel(), jj.ravel(), kk.ravel()], axis=1)
    norm = np.linalg.norm(offsets, axis=1)
    expected = set()
    for b, r in zip(base, radius, strict=True):
        idx = np.clip(b + offsets[norm <= r], 0, np.asarray(shape) - 1)
        expected |= set(np.ravel_multi_index(idx.T, shape).tolist())
    assert set(got.tolist()) == expected
    inside = surface._ball_voxels(base[:1] * 0 + 7, radius[:1], shape)  # one ball, inside
    assert len(inside) == np.count_nonzero(norm <= radius[0])


def test_nondegenerate_faces_agree_with_trimesh() -> None:
    """Slivers at, below and above trimesh's merge tolerance, zero-length edges and
    coincident vertices among ordinary faces: the same mask as trimesh's."""
    rng = np.random.default_rng(5)
    verts = [rng.uniform(-5.0, 5.0, (60, 3))]
    faces = [rng.integers(0, 60, (80, 3))]
    base = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    for k, h in enumerate([0.0, 1e-9, 1e-8, 2e-8, 1e-7, 1e-6, 1.01e-6, 1e-3]):
        tip = np.array([[0.5, h, 0.0]])  # a triangle of height h over a unit edge
        verts.append(np.vstack([base, tip]) + 10.0 * k)
        faces.append(np.array([[0, 1, 2]]) + 60 + 3 * k)
    verts.append(np.zeros((3, 3)))  # all three vertices in one point
    faces.append(np.array([[0, 1, 2]]) + 60 + 3 * 8)
    verts.append(np.array([[0.0, 0.0, 0.0], [1e-9, 0.0, 0.0], [0.0, 1e-9, 0.0]]))  # tiny
    faces.append(np.array([[0, 1, 2]]) + 60 + 3 * 9)
    mesh = trimesh.Trimesh(np.vstack(verts), np.vstack(faces), process=False)
    expected = mesh.nondegenerate_faces()
    assert not expected.all() and expected[:80].any()
    np.testing.assert_array_equal(mesh_repair.nondegenerate_faces(mesh), expected)
