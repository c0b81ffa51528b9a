"""recon.io.report_pdf: the one-page report, its texts and the patient data rule."""

from __future__ import annotations

import pydicom
import pytest
from matplotlib.table import Table
from matplotlib.text import Text
from support import DATA

from recon.io import load_angiogram, load_seeds
from recon.pipeline import reconstruct_pair


@pytest.fixture(scope="module")
def case():
    a, b = load_angiogram(str(DATA / "IM1.dcm")), load_angiogram(str(DATA / "IM2.dcm"))
    rec = reconstruct_pair(a, b, load_seeds(DATA / "im1_im2_seeds.json"))
    return rec, a, b


def _texts(fig) -> str:
    texts = [t.get_text() for t in fig.findobj(Text)]
    texts += [c.get_text().get_text() for tbl in fig.findobj(Table)
              for c in tbl.get_celld().values()]
    return "\n".join(texts)


def test_the_page_says_what_a_clinician_needs_and_no_patient_data(case) -> None:
    from recon.io.report_pdf import report_figure

    rec, a, b = case
    text = _texts(report_figure(rec, a.image, b.image))
    m = rec.measurements
    for needed in ("RESEARCH USE ONLY", "IM1.dcm", "IM2.dcm", "Minimal lumen diameter",
                   f"{m.mld_mm:.2f} mm", f"{m.diameter_stenosis_pct:.0f} %",
                   "Best next view", "Foreshortening in A / B", "Diameter profile"):
        assert needed in text, needed
    ds = pydicom.dcmread(DATA / "IM1.dcm", stop_before_pixels=True)
    private = [str(ds.PatientName), str(ds.PatientID)]
    assert all(p and p not in text for p in private)
    shown = _texts(report_figure(rec, a.image, b.image, identify=True))
    assert all(p in shown for p in private)  # asked for with --identify


def test_written_whole_as_part_of_the_output_set(case, tmp_path) -> None:
    """The command line's path: report_pdf_bytes, then write_outputs(extra=...)."""
    import hashlib
    import json

    from recon.io.outputs import write_outputs
    from recon.io.report_pdf import report_pdf_bytes

    rec, a, b = case
    out = tmp_path / "sub"
    written = write_outputs(rec, out, extra={"report.pdf": report_pdf_bytes(rec, a.image,
                                                                            b.image)})
    pdf = out / "report.pdf"
    assert pdf in written
    data = pdf.read_bytes()
    assert data.startswith(b"%PDF") and data.rstrip().endswith(b"%%EOF") and len(data) > 10_000
    manifest = json.loads((out / "outputs.json").read_text())
    assert manifest["complete"] is True
    assert manifest["files"]["report.pdf"]["sha256"] == hashlib.sha256(data).hexdigest()
