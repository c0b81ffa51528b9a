"""recon.io.patients: two inputs of two patients are refused (issue 46 item 3)."""

from __future__ import annotations

import numpy as np
import pydicom
import pytest
from PIL import Image
from support import DEMO, assert_one_line_error, run_cli

from recon.io.patients import PatientMismatchError, check_same_patient, patient_check


@pytest.fixture
def other_patient(tmp_path):
    """The demo's view B with another PatientID (its study kept)."""
    ds = pydicom.dcmread(DEMO / "b.dcm")
    ds.PatientID = "ANOTHER-PATIENT-77"
    path = tmp_path / "b.dcm"
    ds.save_as(path)
    return path


def test_one_patient_in_two_studies_is_one_patient():
    check = patient_check(DEMO / "a.dcm", DEMO / "b.dcm")
    assert check.same_patient is True
    assert check.same_study is False  # the demo's views are filed as two studies
    assert check.why_unknown is None
    assert check_same_patient(DEMO / "a.dcm", DEMO / "b.dcm").same_patient


def test_two_patients_are_refused_in_one_line_naming_both_files(other_patient):
    check = patient_check(DEMO / "a.dcm", other_patient)
    assert check.same_patient is False
    with pytest.raises(PatientMismatchError) as err:
        check_same_patient(DEMO / "a.dcm", other_patient, hint="confirm to go on")
    text = str(err.value)
    assert "\n" not in text and str(DEMO / "a.dcm") in text and str(other_patient) in text
    assert "different patients" in text and text.endswith("confirm to go on")
    ids = {str(pydicom.dcmread(p, stop_before_pixels=True).PatientID)
           for p in (DEMO / "a.dcm", other_patient)}
    assert not any(i in text for i in ids)
    allowed = check_same_patient(DEMO / "a.dcm", other_patient, allow_different=True)
    assert allowed.same_patient is False


def test_a_file_without_a_patient_cannot_be_compared(tmp_path):
    ds = pydicom.dcmread(DEMO / "b.dcm")
    del ds.PatientID
    no_id = tmp_path / "b.dcm"
    ds.save_as(no_id)
    check = check_same_patient(DEMO / "a.dcm", no_id)
    assert check.same_patient is None and "records no PatientID" in check.why_unknown
    png = tmp_path / "a.png"
    Image.fromarray(np.zeros((64, 64), dtype=np.uint8)).save(png)
    check = check_same_patient(png, DEMO / "b.dcm")
    assert check.same_patient is None and "image file" in check.why_unknown


def test_the_command_line_refuses_two_patients_unless_allowed(other_patient, tmp_path):
    out = tmp_path / "out"
    proc = run_cli("reconstruct", str(DEMO / "a.dcm"), str(other_patient), "--seeds",
                   str(DEMO / "seeds.json"), "--out", str(out))
    assert_one_line_error(proc, str(DEMO / "a.dcm"), str(other_patient), "different patients",
                          "--allow-different-patients")
    assert not out.exists() and "tracing" not in proc.stderr
    assert "ANOTHER-PATIENT-77" not in proc.stderr + proc.stdout
    proc = run_cli("reconstruct", str(DEMO / "a.dcm"), str(other_patient), "--seeds",
                   str(DEMO / "seeds.json"), "--out", str(out), "--quiet",
                   "--allow-different-patients")
    assert proc.returncode == 0, proc.stderr
    warning = [line for line in proc.stderr.splitlines() if "different patients" in line]
    assert len(warning) == 1 and warning[0].startswith("coronary3d: warning:")
    assert str(other_patient) in warning[0]
    assert "ANOTHER-PATIENT-77" not in proc.stderr + proc.stdout
    assert (out / "report.json").exists()
