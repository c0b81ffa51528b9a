"""recon.io.sr: the DICOM SR of `reconstruct --sr`, read back with highdicom, pydicom, dcmtk."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import highdicom as hd
import numpy as np
import pydicom
import pytest
from PIL import Image
from support import DATA, DEMO, assert_one_line_error, run_cli

from recon.errors import OutputError
from recon.io.angiogram import load_angiogram
from recon.io.sr import SR_FILE_NAME, SR_MEASUREMENTS, measurement_report_sr, read_sr_sources

# report.json key -> (code value, scheme, UCUM unit, derivation code, method code)
EXPECTED = {
    "mld_mm": ("397413000", "SCT", "mm", "255605001", None),
    "reference_diameter_mm": ("397413000", "SCT", "mm", None, "122489"),
    "diameter_stenosis_pct": ("408715008", "SCT", "%", None, None),
    "area_stenosis_pct": ("408714007", "SCT", "%", None, None),
    "mla_mm2": ("122480", "DCM", "mm2", "255605001", None),
    "lesion_length_mm": ("408716009", "SCT", "mm", None, None),
    "segment_length_mm": ("122510", "DCM", "mm", None, None),
    # the model's FFR (recon.lumen.ffr), its method "computed" (not a wire's)
    "ffr": ("371842003", "SCT", "{ratio}", None, "128576006"),
}
UPPER_UNCERTAINTY, LOWER_UNCERTAINTY = "371886008", "371885007"  # SCT, TID 310


@pytest.fixture(scope="module")
def demo_sr(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sr") / "demo"
    proc = run_cli("reconstruct", "--demo", "--sr", "--quiet", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    return out


def _measurements(sr: hd.sr.Comprehensive3DSR) -> list:
    """The first segment's measurements (the demo: one segment, then its one lesion)."""
    groups = sr.content.get_image_measurement_groups()
    assert [g.tracking_identifier for g in groups] == ["main", "main lesion 1"]
    return groups[0].get_measurements()


def test_the_sr_holds_the_reports_measurements_with_their_codes(demo_sr):
    report = json.loads((demo_sr / "report.json").read_text())
    sr = hd.sr.srread(demo_sr / SR_FILE_NAME)
    assert isinstance(sr, hd.sr.Comprehensive3DSR)
    assert sr.ConceptNameCodeSequence[0].CodeValue == "126000"  # TID 1500
    measurements = _measurements(sr)
    assert len(measurements) == len(EXPECTED) == len(SR_MEASUREMENTS)
    for m, (key, (code, scheme, unit, derivation, method)) in zip(
        measurements, EXPECTED.items(), strict=True
    ):
        assert (m.name.value, m.name.scheme_designator) == (code, scheme), key
        assert (m.unit.value, m.unit.scheme_designator) == (unit, "UCUM"), key
        assert (m.derivation.value if m.derivation else None) == derivation, key
        assert (m.method.value if m.method else None) == method, key
        assert m.value == pytest.approx(report["measurements"][key], rel=1e-9), key
    # the report's 95 % intervals reach the SR as measurement uncertainties
    assert report["measurements_ci95"]
    found = _uncertainties(pydicom.dcmread(demo_sr / SR_FILE_NAME))
    assert sorted(found) == [LOWER_UNCERTAINTY, UPPER_UNCERTAINTY]


def test_the_sr_references_both_views_and_copies_their_patient_and_study(demo_sr):
    a = pydicom.dcmread(DEMO / "a.dcm", stop_before_pixels=True)
    b = pydicom.dcmread(DEMO / "b.dcm", stop_before_pixels=True)
    ds = pydicom.dcmread(demo_sr / SR_FILE_NAME)
    sr = hd.sr.srread(demo_sr / SR_FILE_NAME)
    group = sr.content.get_image_measurement_groups()[0]
    referenced = [img.referenced_sop_instance_uid for img in group.source_images]
    assert referenced == [a.SOPInstanceUID, b.SOPInstanceUID]
    for keyword in ("PatientName", "PatientID", "PatientSex", "StudyInstanceUID", "StudyID",
                    "StudyDate", "AccessionNumber"):
        assert ds[keyword].value == a[keyword].value, keyword
    assert ds.SeriesInstanceUID not in (a.SeriesInstanceUID, b.SeriesInstanceUID)
    assert ds.Modality == "SR" and ds.CompletionFlag == "COMPLETE"
    # the demo's views are two studies: A's is the SR's, B's is other evidence
    evidence = {
        seq.StudyInstanceUID: [s.ReferencedSOPInstanceUID for x in seq.ReferencedSeriesSequence
                               for s in x.ReferencedSOPSequence]
        for name in ("CurrentRequestedProcedureEvidenceSequence", "PertinentOtherEvidenceSequence")
        for seq in ds.get(name, [])
    }
    assert evidence == {
        a.StudyInstanceUID: [a.SOPInstanceUID],
        b.StudyInstanceUID: [b.SOPInstanceUID],
    }


@pytest.mark.skipif(shutil.which("dsrdump") is None, reason="dcmtk's dsrdump is not installed")
def test_dcmtk_dsrdump_parses_the_sr(demo_sr):
    proc = subprocess.run(["dsrdump", "-Ee", str(demo_sr / SR_FILE_NAME)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "Comprehensive 3D SR Document" in proc.stdout
    assert "Lumen Diameter Stenosis" in proc.stdout
    assert "E:" not in proc.stderr and "W:" not in proc.stderr, proc.stderr


def test_intervals_are_written_when_the_report_has_them(demo_sr):
    report = json.loads((demo_sr / "report.json").read_text())
    mld = report["measurements"]["mld_mm"]
    report["measurements_ci95"] = {"mld_mm": [mld - 0.1, mld + 0.25]}
    report.pop("branches")  # the top level as the one segment, without its lesion groups
    report["lesions"] = []
    sources = read_sr_sources(DEMO / "a.dcm", DEMO / "b.dcm")
    ds = pydicom.dcmread(pydicom.filebase.DicomBytesIO(measurement_report_sr(report, sources)))
    found = _uncertainties(ds)
    assert sorted(found) == [LOWER_UNCERTAINTY, UPPER_UNCERTAINTY]
    assert found[UPPER_UNCERTAINTY] == pytest.approx(0.25)
    assert found[LOWER_UNCERTAINTY] == pytest.approx(0.1)


def test_a_cine_frame_is_referenced_by_its_number(tmp_path):
    out = tmp_path / "im7"
    proc = run_cli("reconstruct", str(DATA / "IM7.dcm"), str(DATA / "IM8.dcm"), "--seeds",
                   str(DATA / "im7_im8_seeds.json"), "--sr", "--quiet", "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    # highdicom's person-name warning quotes the patient: nothing of it reaches stderr
    assert "fantom" not in proc.stderr.lower()
    report = json.loads((out / "report.json").read_text())
    sr = hd.sr.srread(out / SR_FILE_NAME)
    images = sr.content.get_image_measurement_groups()[0].source_images
    chosen = [load_angiogram(DATA / name).frame_index + 1 for name in ("IM7.dcm", "IM8.dcm")]
    assert [list(img.referenced_frame_numbers) for img in images] == [[f] for f in chosen]
    groups = sr.content.get_image_measurement_groups()
    assert [g.tracking_identifier for g in groups] == ["diagonal branch"]  # no lesion
    assert groups[0].get_measurements()[0].value == pytest.approx(
        report["measurements"]["mld_mm"])


def test_image_inputs_are_refused_before_any_work(tmp_path):
    png = tmp_path / "a.png"
    Image.fromarray(np.full((64, 64), 200, dtype=np.uint8)).save(png)
    (tmp_path / "a.json").write_text(json.dumps(
        {"alpha_deg": 0, "beta_deg": 0, "sid_mm": 1000, "sod_mm": 750, "pixel_spacing_mm": 0.3}))
    out = tmp_path / "out"
    proc = run_cli("reconstruct", str(png), str(DEMO / "b.dcm"), "--seeds",
                   str(DEMO / "seeds.json"), "--sr", "--out", str(out))
    assert_one_line_error(proc, str(png), "--sr needs DICOM inputs")
    assert "tracing" not in proc.stderr and not out.exists()


def test_two_patients_are_refused(tmp_path):
    b = pydicom.dcmread(DEMO / "b.dcm")
    b.PatientID = "SOMEONE ELSE"
    other = tmp_path / "b.dcm"
    b.save_as(other)
    with pytest.raises(OutputError, match=r"b\.dcm: --sr: the two views name different patients"):
        read_sr_sources(DEMO / "a.dcm", other)


def test_missing_patient_attributes_stay_empty_not_invented(demo_sr, tmp_path):
    a = pydicom.dcmread(DEMO / "a.dcm")
    del a.PatientBirthDate, a.PatientSex
    path = tmp_path / "a.dcm"
    a.save_as(path)
    b = pydicom.dcmread(DEMO / "b.dcm")
    del b.PatientBirthDate, b.PatientSex
    path_b = tmp_path / "b.dcm"
    b.save_as(path_b)
    report = json.loads((demo_sr / "report.json").read_text())
    data = measurement_report_sr(report, read_sr_sources(path, path_b))
    ds = pydicom.dcmread(pydicom.filebase.DicomBytesIO(data))
    assert ds.PatientBirthDate == "" and ds.PatientSex == ""
    assert ds.PatientID == a.PatientID


def _uncertainties(ds: pydicom.Dataset) -> dict[str, float]:
    """Code value -> value of every measurement uncertainty item in the SR tree."""
    found: dict[str, float] = {}

    def walk(items) -> None:
        for item in items:
            code = item.ConceptNameCodeSequence[0].CodeValue if "ConceptNameCodeSequence" in item \
                else None
            if code in (UPPER_UNCERTAINTY, LOWER_UNCERTAINTY):
                found[code] = float(item.MeasuredValueSequence[0].NumericValue)
            walk(item.get("ContentSequence", []))

    walk(ds.ContentSequence)
    return found


# ------------------------------------------------------------ the whole tree (issue 46)
@pytest.fixture(scope="module")
def tree_sr(tmp_path_factory) -> Path:
    """The demo tree with its side branch clicked, the segments named LAD and D1."""
    from recon.io.seeds_file import save_seeds
    from recon.seeds import Seeds
    from recon.synth import make_phantom
    from recon.synth.tree_case import tree_seeds

    seeds, _, _ = tree_seeds(np.random.default_rng(1), make_phantom("static", 7, render=False))
    main, side = seeds.segments
    from dataclasses import replace

    named = Seeds(segments=(replace(main, name="LAD"),
                            replace(side, name="D1", parent="LAD")),
                  features=seeds.features)
    root = tmp_path_factory.mktemp("tree_sr")
    save_seeds(named, root / "seeds.json")
    proc = run_cli("reconstruct", "--demo", "--seeds", str(root / "seeds.json"), "--sr",
                   "--quiet", "--out", str(root / "out"))
    assert proc.returncode == 0, proc.stderr
    return root / "out"


def test_the_sr_carries_every_segment_and_every_lesion_with_coded_sites(tree_sr):
    report = json.loads((tree_sr / "report.json").read_text())
    sr = hd.sr.srread(tree_sr / SR_FILE_NAME)
    groups = sr.content.get_image_measurement_groups()
    expected = []
    for branch in report["branches"]:
        name = branch["inputs"]["segment"]
        expected += [name] + [f"{name} lesion {les['number']}" for les in branch["lesions"]]
    assert [g.tracking_identifier for g in groups] == expected == ["LAD", "LAD lesion 1", "D1"]
    sites = {g.tracking_identifier: g.finding_sites[0].value.value for g in groups}
    # SCT 59438005 anterior descending branch of the left coronary artery, 91750005 the
    # first diagonal branch (DICOM CID 3015)
    assert sites == {"LAD": "59438005", "LAD lesion 1": "59438005", "D1": "91750005"}
    by_name = {g.tracking_identifier: g for g in groups}
    for branch in report["branches"]:  # every segment's figures, report.json's to the digit
        name = branch["inputs"]["segment"]
        values = {(m.name.value, m.derivation.value if m.derivation else None): m.value
                  for m in by_name[name].get_measurements()}
        assert values[("397413000", "255605001")] == pytest.approx(
            branch["measurements"]["mld_mm"], rel=1e-9)
        assert values[("122510", None)] == pytest.approx(
            branch["measurements"]["segment_length_mm"], rel=1e-9)
    lesion = report["branches"][0]["lesions"][0]
    ds_item = [m for m in by_name["LAD lesion 1"].get_measurements()
               if m.name.value == "408715008"][0]
    assert ds_item.value == pytest.approx(lesion["diameter_stenosis_pct"], rel=1e-9)


def test_uncertainties_carry_the_unit_of_their_measurement(tree_sr):
    """TID 310: the +/- range of a measurement's uncertainty is in that measurement's units
    (highdicom's own items said "1")."""
    ds = pydicom.dcmread(tree_sr / SR_FILE_NAME)
    pairs = []

    def walk(items) -> None:
        for item in items:
            if item.get("ValueType") == "NUM":
                unit = item.MeasuredValueSequence[0].MeasurementUnitsCodeSequence[0].CodeValue
                for sub in item.get("ContentSequence", []):
                    code = sub.ConceptNameCodeSequence[0].CodeValue
                    if code in (UPPER_UNCERTAINTY, LOWER_UNCERTAINTY):
                        pairs.append((unit, sub.MeasuredValueSequence[0]
                                      .MeasurementUnitsCodeSequence[0].CodeValue))
            walk(item.get("ContentSequence", []))

    walk(ds.ContentSequence)
    assert len(pairs) > 20
    assert all(own == theirs for own, theirs in pairs), pairs
    assert {own for own, _ in pairs} >= {"mm", "%", "mm2"}
    assert "1" not in {theirs for _, theirs in pairs}


@pytest.mark.skipif(shutil.which("dsrdump") is None, reason="dcmtk's dsrdump is not installed")
def test_dsrdump_reads_every_segment_of_the_tree(tree_sr):
    proc = subprocess.run(["dsrdump", "-Ee", str(tree_sr / SR_FILE_NAME)], capture_output=True,
                          text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "E:" not in proc.stderr and "W:" not in proc.stderr, proc.stderr
    for text in ('"LAD"', '"LAD lesion 1"', '"D1"', "Anterior Descending",
                 "1st Diagonal Coronary Artery", '(mm,UCUM,"mm")', '(%,UCUM,"Percent")'):
        assert text in proc.stdout, text
    assert '(1,UCUM,"no units")' not in proc.stdout


@pytest.mark.parametrize("name, code", [
    ("LAD", "59438005"), ("pLAD", "68787002"), ("mid LAD", "91748002"), ("LCx", "57396003"),
    ("RCA", "13647002"), ("distal RCA", "41879009"), ("LM", "3227004"), ("D2", "91751009"),
    ("OM1", "91754001"), ("ramus", "244252004"), ("branch 1", "41801008"),
    ("diagonal branch", "41801008")])
def test_finding_site_codes_from_segment_names(name, code):
    from recon.io.sr import finding_site_code

    assert finding_site_code(name).value == code


def test_write_sr_is_the_pages_call(tmp_path):
    """write_sr(result, path, (path_a, path_b)): the file the page's download serves."""
    from recon.io.seeds_file import load_seeds
    from recon.io.sr import write_sr
    from recon.pipeline import reconstruct_pair

    a, b = load_angiogram(DEMO / "a.dcm"), load_angiogram(DEMO / "b.dcm")
    rec = reconstruct_pair(a, b, load_seeds(DEMO / "seeds.json"))
    path = write_sr(rec, tmp_path / "x.dcm", (DEMO / "a.dcm", DEMO / "b.dcm"))
    groups = hd.sr.srread(path).content.get_image_measurement_groups()
    assert [g.tracking_identifier for g in groups] == ["main", "main lesion 1"]
    mld = [m for m in groups[0].get_measurements() if m.name.value == "397413000"][0]
    assert mld.value == pytest.approx(rec.measurements.mld_mm, rel=1e-9)
    other = pydicom.dcmread(DEMO / "b.dcm")
    other.PatientID = "SOMEONE ELSE"
    other.save_as(tmp_path / "b.dcm")
    with pytest.raises(OutputError, match="different patients"):
        write_sr(rec, tmp_path / "y.dcm", (DEMO / "a.dcm", tmp_path / "b.dcm"))
    assert not (tmp_path / "y.dcm").exists()
