"""Whether the two inputs of a reconstruction are one patient's.

Two views reconstruct one vessel only when they show one patient; a pair of two
patients' files (opened by mistake) gives a meaningless 3D result with no sign of it.
:func:`patient_check` reads both DICOM headers (no pixels) and compares their
PatientID (0010,0020): different IDs are two patients. The StudyInstanceUID may
differ (two runs of one patient filed as two studies); it is reported, not refused.
A file without a PatientID, an image file (PNG/TIFF: no patient at all) or a file
pydicom cannot read cannot be compared: the answer is then "unknown", and the
loader says what is wrong with an unreadable file.

:func:`check_same_patient` refuses a pair of two patients in one line that names both
files (never the identifiers: patient data stays out of the terminal and the logs),
unless the caller allows it. The command line's ``--allow-different-patients`` and the
page's confirmation are the two ways to allow it.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

from recon.errors import LoadError
from recon.io.image_files import is_image_file

__all__ = ["PatientCheck", "PatientMismatchError", "patient_check", "check_same_patient"]


class PatientMismatchError(LoadError):
    """The two inputs name different patients (one line naming both files)."""


@dataclass(frozen=True)
class PatientCheck:
    """The two inputs' patients compared.

    same_patient : True (equal PatientID), False (different), None (unknown: a file
        without a PatientID, an image file, or a header that cannot be read).
    same_study : True / False by StudyInstanceUID, None when unknown.
    why_unknown : why the patients could not be compared (None when they were).
    """

    path_a: str
    path_b: str
    same_patient: bool | None
    same_study: bool | None
    why_unknown: str | None = None

    def message(self, hint: str = "") -> str:
        """One line naming both files (not the identifiers) when they are two patients'."""
        text = (f"{self.path_a} and {self.path_b} name different patients (their PatientID "
                "differs): a reconstruction needs two views of one patient")
        return text + (f"; {hint}" if hint else "")


def _ids(path: str) -> tuple[str | None, str | None, str | None]:
    """(PatientID, StudyInstanceUID, why unknown) of one input."""
    if is_image_file(Path(path)):
        return None, None, f"{path} is an image file (no patient recorded)"
    import pydicom

    try:
        ds = pydicom.dcmread(path, stop_before_pixels=True,
                             specific_tags=["PatientID", "StudyInstanceUID"])
    except Exception:  # noqa: BLE001 - the loader reports an unreadable file properly
        return None, None, f"{path}: the DICOM header could not be read"
    patient = str(ds.get("PatientID", "") or "").strip() or None
    study = str(ds.get("StudyInstanceUID", "") or "").strip() or None
    return patient, study, None if patient else f"{path} records no PatientID"


def patient_check(path_a: str | os.PathLike, path_b: str | os.PathLike) -> PatientCheck:
    """Compare the patients (and studies) of two input files (module docstring)."""
    a, b = os.fspath(path_a), os.fspath(path_b)
    pid_a, study_a, why_a = _ids(a)
    pid_b, study_b, why_b = _ids(b)
    same_patient = None if pid_a is None or pid_b is None else pid_a == pid_b
    same_study = None if study_a is None or study_b is None else study_a == study_b
    return PatientCheck(a, b, same_patient, same_study, why_a or why_b)


def check_same_patient(path_a: str | os.PathLike, path_b: str | os.PathLike, *,
                       allow_different: bool = False, hint: str = "") -> PatientCheck:
    """:func:`patient_check`, raising :class:`PatientMismatchError` (one line naming both
    files, ``hint`` appended) when they are two patients' and ``allow_different`` is
    False."""
    check = patient_check(path_a, path_b)
    if check.same_patient is False and not allow_different:
        raise PatientMismatchError(check.message(hint))
    return check
