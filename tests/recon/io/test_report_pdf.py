"""recon.io.report_pdf: the report of the whole reconstruction, its texts, the patient data
rule, and the PDF read back with pypdf (issue 46 item 7)."""

from __future__ import annotations

import re

import numpy as np
import pydicom
import pypdf
import pytest
from matplotlib.table import Table
from matplotlib.text import Text
from support import DATA, DEMO, run_cli

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


def test_the_pages_say_what_a_clinician_needs_and_no_patient_data(case) -> None:
    from recon.io.report_pdf import report_pages

    rec, a, b = case
    pages = report_pages(rec, a.image, b.image)
    assert len(pages) == 2  # the overview and the one segment's page
    text = "\n".join(_texts(p) for p in pages)
    m = rec.measurements
    for needed in ("RESEARCH USE ONLY", "IM1.dcm", "IM2.dcm", "Minimal lumen diameter",
                   f"{m.mld_mm:.2f} mm", f"{m.diameter_stenosis_pct:.0f} %",
                   "Best next view", "Foreshortening in A / B", "Diameter profile",
                   "diagonal branch"):
        assert needed in text, needed
    ds = pydicom.dcmread(DATA / "IM1.dcm", stop_before_pixels=True)
    private = [str(ds.PatientName), str(ds.PatientID)]
    assert all(p and p not in text for p in private)
    shown = "\n".join(_texts(p) for p in report_pages(rec, a.image, b.image, identify=True))
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


# ------------------------------------------------------------ the whole tree
@pytest.fixture(scope="module")
def tree_out(tmp_path_factory):
    """`coronary3d reconstruct --demo --report` on the demo with its side branch clicked:
    the output folder."""
    from recon.io.seeds_file import save_seeds
    from recon.synth import make_phantom
    from recon.synth.tree_case import tree_seeds

    seeds, _, _ = tree_seeds(np.random.default_rng(1), make_phantom("static", 7, render=False))
    root = tmp_path_factory.mktemp("tree_pdf")
    save_seeds(seeds, root / "seeds.json")
    proc = run_cli("reconstruct", "--demo", "--seeds", str(root / "seeds.json"), "--report",
                   "--quiet", "--out", str(root / "out"))
    assert proc.returncode == 0, proc.stderr
    return root / "out"


@pytest.fixture(scope="module")
def tree_pdf(tree_out):
    """Its report.json and the PDF's pages' text."""
    import json

    report = json.loads((tree_out / "report.json").read_text())
    pages = [p.extract_text() for p in pypdf.PdfReader(tree_out / "report.pdf").pages]
    return report, pages


def _ci_text(value: float, ci: list[float], fmt: str, unit: str) -> str:
    return f"{value:{fmt}} {unit} ({ci[0]:{fmt}}–{ci[1]:{fmt}})"


def test_the_pdf_shows_every_segment_with_its_intervals(tree_pdf):
    report, pages = tree_pdf
    names = [b["inputs"]["segment"] for b in report["branches"]]
    assert names == ["main", "branch 1"] and len(pages) == 1 + len(names)
    overview = pages[0]
    for branch, page in zip(report["branches"], pages[1:], strict=True):
        m, ci = branch["measurements"], branch["measurements_ci95"]
        assert f"Segment {branch['inputs']['segment']}" in page
        for key, fmt, unit in (("mld_mm", ".2f", "mm"), ("diameter_stenosis_pct", ".0f", "%"),
                               ("segment_length_mm", ".1f", "mm"),
                               ("lesion_length_mm", ".1f", "mm")):
            text = _ci_text(m[key], ci[key], fmt, unit)
            assert text in page, (branch["inputs"]["segment"], text)
            assert text in overview, (branch["inputs"]["segment"], text)
    # the main's lesion, numbered, with its own intervals; the side branch's ostium
    (lesion,) = report["branches"][0]["lesions"]
    assert _ci_text(lesion["diameter_stenosis_pct"], lesion["ci95"]["diameter_stenosis_pct"],
                    ".0f", "%") in pages[1]
    assert "1 lesion: lesion 1 at" in pages[1]
    side = re.sub(r"\s+", " ", pages[2])
    assert "No lesion; a" in side and "(ostium) is not confirmed" in side
    assert "none (ostium not confirmed)" in overview


def test_the_pdf_has_the_bifurcation_table_and_the_charts_bands(tree_pdf):
    report, pages = tree_pdf
    (bif,) = report["bifurcations"]
    overview = re.sub(r"\s+", " ", pages[0])
    assert "Medina" in overview and f"main › branch 1 {bif['medina']}" in overview
    assert f"{bif['bifurcation_angle_deg']:.0f}°" in overview
    main_page = re.sub(r"\s+", " ", pages[1])
    assert "side branch branch 1" in main_page  # where the side branch leaves the main
    assert "lesion" in main_page and "end zone" in main_page
    if report["branches"][0]["centerline"]["overlap_a_mm"]:
        assert "view A radius replaced (overlap)" in main_page
    assert "ostium zone" in re.sub(r"\s+", " ", pages[2])


def test_no_patient_data_in_the_pdf_unless_asked(tree_pdf):
    _, pages = tree_pdf
    ds = pydicom.dcmread(DEMO / "a.dcm", stop_before_pixels=True)
    assert not any(str(ds.PatientID) in p or str(ds.PatientName) in p for p in pages)


def test_write_report_pdf_is_the_pages_call(case, tmp_path):
    from recon.io.report_pdf import write_report_pdf

    rec, a, b = case
    path = write_report_pdf(rec, tmp_path / "r.pdf", a.image, b.image)
    reader = pypdf.PdfReader(path)
    assert len(reader.pages) == 2 and "Segment diagonal branch" in reader.pages[1].extract_text()
    # without the images the traces are still drawn, and it says so
    path = write_report_pdf(rec, tmp_path / "no-images.pdf")
    assert "image not given" in pypdf.PdfReader(path).pages[0].extract_text()


# ------------------------------------------------------------ the FFR (issue 47)
def _flat(text: str) -> str:
    return re.sub(r"\s+", " ", text)


def _expected_ffr_line(distal: float, ci: list[float], band: list[float]) -> str:
    lo, hi = sorted(band)
    return (f"FFR (model estimate, research use only) {distal:.2f} (95 % {ci[0]:.2f}–"
            f"{ci[1]:.2f}); flow assumption 0.25–0.45 m/s: {lo:.2f}–{hi:.2f} (not a "
            "confidence interval)")


def test_the_pdf_has_each_segments_ffr_line_and_the_research_sentence(tree_pdf):
    report, pages = tree_pdf
    overview = _flat(pages[0])
    for branch, page in zip(report["branches"], pages[1:], strict=True):
        ffr = branch["ffr"]
        assert ffr is not None and ffr["ci95"] is not None, branch["inputs"]["segment"]
        page = _flat(page)
        assert _expected_ffr_line(ffr["distal"], ffr["ci95"], ffr["flow_band"]["ffr"]) in page
        assert "not validated against a pressure wire here" in page
        assert "It must not guide treatment." in page
        assert "0.80 cut-off" in page and "(not a confidence interval)" in page
        # the overview's table and the segment's table: the same value and interval
        value = f"{ffr['distal']:.2f} ({ffr['ci95'][0]:.2f}–{ffr['ci95'][1]:.2f})"
        assert value in overview and value in page
    assert "FFR (model)" in overview


def _ffr_axes(fig):
    (ax,) = [a for a in fig.axes if a.get_ylabel() == "FFR pullback"]
    return ax


def test_the_pullback_chart_draws_the_ffr_its_interval_the_flow_band_and_the_cut_off(case):
    from matplotlib.collections import PolyCollection

    from recon.io.report_pdf import segment_figure

    rec, _, _ = case
    ffr = rec.ffr
    assert ffr is not None and ffr.ffr_lo is not None
    fig = segment_figure(rec, rec)
    ax = _ffr_axes(fig)
    (diameter_ax,) = [a for a in fig.axes if a.get_title() == "Diameter profile"]
    assert ax.get_xlim() == diameter_ax.get_xlim()  # one distance scale for both charts
    lines = {ln.get_label(): ln for ln in ax.get_lines()}
    curve = lines["FFR (model estimate)"]
    assert np.array_equal(curve.get_xdata(), ffr.s_mm)
    assert np.array_equal(curve.get_ydata(), ffr.ffr)
    dashed = [ln for ln in ax.get_lines() if ln.get_linestyle() == "--"]
    assert len(dashed) == 2
    for ln, row in zip(dashed, ffr.band, strict=True):
        assert np.array_equal(ln.get_ydata(), row)
    assert dashed[0].get_label() == \
        "flow assumption 0.25–0.45 m/s (not a confidence interval)"
    cut = lines["0.80 cut-off"]
    assert list(cut.get_ydata()) == [0.8, 0.8]
    (band,) = [c for c in ax.collections if isinstance(c, PolyCollection)
               and c.get_label() == "95 % interval"]
    ys = band.get_paths()[0].vertices[:, 1]
    assert np.isclose(ys.min(), ffr.ffr_lo.min()) and np.isclose(ys.max(), ffr.ffr_hi.max())
    low, high = ax.get_ylim()
    assert low <= min(0.7, float(ffr.ffr_lo.min())) and high > 1.0
    assert all(t <= 1.0 + 1e-9 for t in ax.get_yticks())  # no tick above FFR 1


def test_where_the_ffr_was_not_computed_the_pdf_says_why(case, tmp_path):
    """As recon.pipeline leaves it when the model refuses the lumen: ffr None and the
    reason among the warnings."""
    from dataclasses import replace

    from recon.io.report_pdf import write_report_pdf

    rec, a, b = case
    reason = ("FFR: segment 'diagonal branch': the lumen closes at 20.0 mm (area 0.004 "
              "mm^2); no flow can be modelled through it")
    off = replace(rec, ffr=None, warnings=(*rec.warnings, f"FFR not computed: {reason}"))
    path = write_report_pdf(off, tmp_path / "no-ffr.pdf", a.image, b.image)
    overview, page = (_flat(p.extract_text()) for p in pypdf.PdfReader(path).pages)
    assert ("FFR not computed: segment 'diagonal branch': the lumen closes at 20.0 mm"
            in page)
    assert "no FFR pullback: the FFR was not computed" in page
    assert "FFR (model estimate, research use only)" not in page
    assert "not computed" in overview and "FFR not computed" in overview  # its table, warnings
    bare = replace(rec, ffr=None)  # no reason recorded: said, not made up
    from recon.io.report_pdf import ffr_not_computed

    assert ffr_not_computed(bare) == "FFR not computed: no reason was recorded"


def test_a_report_page_renders_with_the_pullback_drawn(tree_out):
    """The main's page rasterised (pdftoppm, else pypdfium2) into test-artifacts/report/
    to be looked at; the FFR curve's navy is drawn inside the pullback chart's rows."""
    import shutil
    import subprocess
    from pathlib import Path

    from PIL import Image

    repo = Path(__file__).resolve().parents[3]
    out = repo / "test-artifacts" / "report"
    out.mkdir(parents=True, exist_ok=True)
    pdf = tree_out / "report.pdf"
    png = out / "tree-main-page.png"
    if shutil.which("pdftoppm"):
        subprocess.run(["pdftoppm", "-png", "-r", "100", "-f", "2", "-l", "2", "-singlefile",
                        str(pdf), str(png.with_suffix(""))], check=True)
    else:
        pdfium = pytest.importorskip("pypdfium2", reason="neither pdftoppm nor pypdfium2")
        pdfium.PdfDocument(str(pdf))[1].render(scale=100 / 72).to_pil().save(png)
    image = np.asarray(Image.open(png).convert("RGB")).astype(int)
    h, w, _ = image.shape
    assert abs(h / w - 11.69 / 8.27) < 0.01  # A4 portrait
    navy = (abs(image[..., 0]) < 40) & (abs(image[..., 1]) < 40) & (image[..., 2] > 90)
    rows = np.flatnonzero(navy.any(axis=1)) / h  # from the top
    in_chart = (rows > 1 - 0.605) & (rows < 1 - 0.475)
    assert in_chart.sum() >= 5  # the curve (FFR and its 'distal' label) drawn in the chart


def test_a_borderline_narrowing_has_its_band_on_the_diameter_chart(case):
    """Issue 46: a narrowing below the lesion floor whose interval reaches it is shaded on
    the segment page's diameter chart, over its extent, with its own legend entry."""
    from dataclasses import replace

    from matplotlib.patches import Rectangle

    from recon.io.report_pdf import segment_figure
    from recon.lumen.lesions import Lesion
    from recon.lumen.measure import Narrowing

    rec, _, _ = case
    # a 22 % narrowing at 30-38 mm (interval 17-30 %), listed as borderline here
    n = Narrowing(peak_s_mm=34.0, start_s_mm=30.0, end_s_mm=38.0, length_mm=8.0, mld_mm=2.0,
                  mld_s_mm=34.0, reference_diameter_mm=2.56, diameter_stenosis_pct=22.0,
                  area_stenosis_pct=39.2, mla_mm2=3.14, reference_area_mm2=5.15, zone="",
                  supported=True)
    les = Lesion(1, n, {"diameter_stenosis_pct": (17.0, 30.0)})
    shown = replace(rec)  # a copy whose (cached) lesion report lists it
    shown.__dict__["lesions"] = replace(rec.lesions, borderline=(les,))
    (ax,) = [a for a in segment_figure(shown, shown).axes if a.get_title() == "Diameter profile"]
    bands = [p for p in ax.patches if p.get_label().startswith("borderline narrowing")]
    assert len(bands) == 1
    x = np.asarray(bands[0].get_xy())[:, 0] if not isinstance(bands[0], Rectangle) else \
        np.array([bands[0].get_x(), bands[0].get_x() + bands[0].get_width()])
    assert np.isclose(x.min(), les.narrowing.start_s_mm)
    assert np.isclose(x.max(), les.narrowing.end_s_mm)
    (plain_ax,) = [a for a in segment_figure(rec, rec).axes
                   if a.get_title() == "Diameter profile"]
    assert not [p for p in plain_ax.patches if p.get_label().startswith("borderline")]
