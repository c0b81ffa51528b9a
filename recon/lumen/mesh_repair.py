"""Checks and repairs of the triangle meshes that marching cubes gives (recon.lumen.surface).

:func:`repair` keeps the largest piece, drops degenerate faces and winds the
faces outwards; :func:`shared_edges` gives trimesh's face adjacency, closedness
and winding consistency from one sort of the edge keys; :func:`signed_volume`
the enclosed volume; :func:`pieces` tells separate pieces from inner cavities.
"""

from __future__ import annotations

import numpy as np
import trimesh
from numpy.typing import NDArray

__all__ = ["repair", "nondegenerate_faces", "shared_edges", "signed_volume", "pieces"]

FloatArray = NDArray[np.float64]


def repair(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    """Largest component, no degenerate faces, outward winding."""
    mesh.update_faces(nondegenerate_faces(mesh))
    mesh.remove_unreferenced_vertices()
    adjacency, closed, consistent = shared_edges(mesh.faces)
    labels = trimesh.graph.connected_component_labels(adjacency, len(mesh.faces))
    if labels.size and labels.max() > 0:
        keep = labels == np.bincount(labels).argmax()
        mesh.update_faces(keep)
        mesh.remove_unreferenced_vertices()
        _, closed, consistent = shared_edges(mesh.faces)
    if not closed:
        trimesh.repair.fill_holes(mesh)
    if not (closed and consistent) and not mesh.is_winding_consistent:
        trimesh.repair.fix_winding(mesh)
    if signed_volume(mesh.vertices, mesh.faces) < 0:
        mesh.invert()
    return mesh


def nondegenerate_faces(mesh: trimesh.Trimesh) -> NDArray[np.bool_]:
    """trimesh's ``mesh.nondegenerate_faces()`` (F,) mask (both heights of a face's
    oriented box above ``tol.merge``): a face whose heights are clearly above it (100
    times, far beyond rounding) is kept here; trimesh decides the few others itself."""
    v0, v1, v2 = (mesh.vertices[mesh.faces[:, k]] for k in range(3))
    edge_a, edge_b = v1 - v0, v2 - v0  # the box's edges (trimesh's extents)
    twice_area = np.cross(edge_a, edge_b)
    area2 = np.einsum("ij,ij->i", twice_area, twice_area)
    longest2 = np.maximum(np.einsum("ij,ij->i", edge_a, edge_a),
                          np.einsum("ij,ij->i", edge_b, edge_b))
    keep = area2 > (100.0 * trimesh.tol.merge) ** 2 * longest2  # heights > 100 tol.merge
    unsure = np.flatnonzero(~keep)
    if unsure.size:
        triangles = np.stack([v0[unsure], v1[unsure], v2[unsure]], axis=1)
        keep[unsure] = trimesh.triangles.nondegenerate(triangles, height=trimesh.tol.merge)
    return keep


def shared_edges(faces: NDArray[np.int64]) -> tuple[NDArray[np.int64], bool, bool]:
    """Pairs (P, 2) of faces (F, 3) sharing an edge that exactly two faces use; closed (all
    edges so); consistently wound (each such edge run both ways): trimesh's ``face_adjacency``,
    ``is_watertight``, ``is_winding_consistent`` from one sort of edge keys, not hashed rows."""
    edges = faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2).astype(np.int64)  # face f: rows 3f..
    lo, hi = np.minimum(edges[:, 0], edges[:, 1]), np.maximum(edges[:, 0], edges[:, 1])
    key = lo * (int(faces.max()) + 1 if faces.size else 1) + hi
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    starts = np.flatnonzero(np.concatenate([[True], sorted_key[1:] != sorted_key[:-1]]))
    counts = np.diff(np.concatenate([starts, [len(key)]]))
    first, second = order[starts[counts == 2]], order[starts[counts == 2] + 1]
    pairs = np.stack([first // 3, second // 3], axis=1)
    return (pairs[pairs[:, 0] != pairs[:, 1]], bool(2 * len(first) == len(edges)),
            bool(np.all(edges[first, 1] == edges[second, 0])))


def signed_volume(vertices: FloatArray, faces: NDArray[np.int64]) -> float:
    """Volume enclosed by a closed triangle mesh, vertices (V, 3), faces (F, 3): the sum
    of the signed tetrahedra (origin, v0, v1, v2), v0 . (v1 x v2) / 6 (the divergence
    theorem); negative when the faces wind inwards. (trimesh's ``volume`` integrates
    the whole inertia tensor to get the same number.)"""
    return float(np.sum(_face_volumes(vertices, faces)))


def _face_volumes(vertices: FloatArray, faces: NDArray[np.int64]) -> FloatArray:
    """Signed volume (F,) of each face's tetrahedron with the origin, v0 . (v1 x v2) / 6."""
    v0, v1, v2 = (vertices[faces[:, k]] for k in range(3))
    return np.einsum("ij,ij->i", v0, np.cross(v1, v2)) / 6.0


def pieces(mesh: trimesh.Trimesh, speck_mm3: float = 0.0) -> tuple[int, int, int]:
    """(separate pieces, inner cavities, specks) of a marching-cubes mesh.

    Marching cubes winds every closed surface the same way about the inside,
    so an outer piece has a signed volume of the largest piece's sign and a
    cavity (an outside pocket within the inside) the opposite sign. A closed
    surface enclosing less than ``speck_mm3`` (either sign) is a speck: one voxel
    of the sampled distance field on the wrong side of the level, not a piece of
    vessel (:func:`recon.lumen.surface.build_tree_surface` passes one voxel's volume;
    the thinnest vessel it draws, a semi-axis of one voxel, encloses more than
    three voxels per voxel of length).
    """
    labels = trimesh.graph.connected_component_labels(mesh.face_adjacency, len(mesh.faces))
    if not labels.size:
        return 0, 0, 0
    signed = np.bincount(labels, weights=_face_volumes(mesh.vertices, mesh.faces))
    largest = int(np.argmax(np.bincount(labels)))
    speck = (np.abs(signed) < speck_mm3) & (np.arange(len(signed)) != largest)
    outer = (np.sign(signed) == np.sign(signed[largest])) & ~speck
    cavity = ~outer & ~speck
    return (int(np.count_nonzero(outer)), int(np.count_nonzero(cavity)),
            int(np.count_nonzero(speck)))
