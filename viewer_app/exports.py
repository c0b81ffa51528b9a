"""What the page's download buttons send: the outputs of a reconstruction, and the marks.

Pure (no viser): bytes and file names, from :func:`recon.io.outputs_as_bytes`.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from recon.io import MESH_FORMATS, outputs_as_bytes

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction
    from recon.seeds import Seeds
    from recon.tree import TreeReconstruction

__all__ = ["EXPORT_KINDS", "export_bytes", "export_name"]

EXPORT_KINDS = (*MESH_FORMATS, "centerline.csv", "centerline.vtp", "report.json", "seeds.json")


def export_name(kind: str) -> str:
    """The file name of an export ("mesh.stl" for the kind "stl")."""
    return f"mesh.{kind}" if kind in MESH_FORMATS else kind


def export_bytes(kind: str, reconstruction: Reconstruction | TreeReconstruction | None,
                 seeds: Seeds) -> bytes:
    """Bytes of an output: a mesh format ("stl", "obj", "ply", "glb"), "centerline.csv",
    "centerline.vtp", "report.json" or "seeds.json" (the marks; needs no reconstruction).
    A tree's are the command line's for it (recon.io.outputs): the whole tree's mesh, its
    branches in the CSV's ``branch`` column and the VTP's ``BranchId``.

    Raises ValueError when there is no reconstruction yet or the kind is unknown.
    """
    if kind not in EXPORT_KINDS:
        raise ValueError(f"export: unknown kind {kind!r} (one of {', '.join(EXPORT_KINDS)})")
    if kind == "seeds.json":
        return (json.dumps(seeds.to_dict(), indent=2) + "\n").encode()
    if reconstruction is None:
        raise ValueError(f"export {kind}: reconstruct first")
    files = outputs_as_bytes(reconstruction, formats=(kind if kind in MESH_FORMATS else "stl",))
    return files[export_name(kind)]
