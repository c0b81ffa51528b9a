"""What the page's download buttons send: the outputs of a reconstruction, its report
(PDF) and its DICOM SR, and the marks.

Pure (no viser): bytes and file names, from :func:`recon.io.outputs_as_bytes`,
:func:`recon.io.report_pdf.report_pdf_bytes` and :mod:`recon.io.sr`: the files
``coronary3d reconstruct`` writes (``--report``, ``--sr``) for the same reconstruction.
"""

from __future__ import annotations

import json
from typing import TYPE_CHECKING

from recon.io import MESH_FORMATS, outputs_as_bytes
from recon.io.outputs import REPORT_PDF_NAME, SR_NAME

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction
    from recon.seeds import Seeds
    from recon.tree import TreeReconstruction
    from recon.types import Angiogram

__all__ = ["EXPORT_KINDS", "REPORT_KINDS", "export_bytes", "export_name"]

#: The report of the whole reconstruction (every segment and bifurcation, with intervals).
REPORT_KINDS = (REPORT_PDF_NAME, SR_NAME)
EXPORT_KINDS = (*MESH_FORMATS, "centerline.csv", "centerline.vtp", "report.json",
                *REPORT_KINDS, "seeds.json")


def export_name(kind: str) -> str:
    """The file name of an export ("mesh.stl" for the kind "stl")."""
    return f"mesh.{kind}" if kind in MESH_FORMATS else kind


def export_bytes(kind: str, reconstruction: Reconstruction | TreeReconstruction | None,
                 seeds: Seeds, inputs: tuple[Angiogram, Angiogram] | None = None) -> bytes:
    """Bytes of an output: a mesh format ("stl", "obj", "ply", "glb"), "centerline.csv",
    "centerline.vtp", "report.json", "report.pdf", "measurements-sr.dcm" or "seeds.json"
    (the marks; needs no reconstruction). A tree's are the command line's for it
    (recon.io.outputs): the whole tree's mesh, its branches in the CSV's ``branch``
    column and the VTP's ``BranchId``, every branch in the PDF and the SR.

    ``inputs``: the two angiograms (the frames used) the reconstruction was made from,
    for the PDF's images and the SR's source references (its patient and study are
    copied from file A; both must be DICOM of one patient, recon.io.sr.read_sr_sources).

    Raises ValueError (a recon.errors.OutputError for an SR the inputs cannot carry) when
    there is no reconstruction yet, the kind is unknown or the inputs are missing.
    """
    if kind not in EXPORT_KINDS:
        raise ValueError(f"export: unknown kind {kind!r} (one of {', '.join(EXPORT_KINDS)})")
    if kind == "seeds.json":
        return (json.dumps(seeds.to_dict(), indent=2) + "\n").encode()
    if reconstruction is None:
        raise ValueError(f"export {kind}: reconstruct first")
    if kind in REPORT_KINDS and inputs is None:
        raise ValueError(f"export {kind}: the reconstruction's input files are not known")
    if kind == REPORT_PDF_NAME:
        from recon.io.report_pdf import report_pdf_bytes

        return report_pdf_bytes(reconstruction, inputs[0].image, inputs[1].image)
    if kind == SR_NAME:
        from recon.io.sr import read_sr_sources

        a, b = inputs
        sources = read_sr_sources(a.path, b.path, (a.frame_index + 1, b.frame_index + 1))
        return outputs_as_bytes(reconstruction, formats=(), sr_sources=sources)[SR_NAME]
    files = outputs_as_bytes(reconstruction, formats=(kind if kind in MESH_FORMATS else "stl",))
    return files[export_name(kind)]
