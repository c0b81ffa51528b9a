"""measurements-sr.dcm: the 3D measurements as a DICOM Structured Report (highdicom).

The document is a TID 1500 "Measurement Report" in a Comprehensive 3D SR
instance. DICOM's own QCA template (TID 3213, Quantitative Arterial
Analysis) describes measurements made in one projection image; ours are
made along a 3D centerline triangulated from two projections, so the
generic measurement report is the honest container: one measurement group
(TID 1501) per reconstructed segment (every branch of a tree, in the seeds'
order; tracking identifier the segment's name), then one per lesion of that
segment (report.json's ``lesions``; tracking identifier "<segment> lesion <k>"),
whose source images are both angiograms (by SOP Instance UID, and frame number
for a cine).

Finding Site: the segment's name read as a coronary artery or segment of DICOM
PS3.16 CID 3015 "Coronary Artery" (SNOMED CT codes as pydicom's
``pydicom.sr.codedict`` holds them): LM, LAD, LCx, RCA with a proximal / mid /
distal qualifier, D1-D3, OM1-OM3, ramus, PDA, ... (:func:`finding_site_code`);
a name it does not know is "Coronary artery" (SCT 41801008).

Concepts (SNOMED CT "SCT", DICOM "DCM"; units UCUM):

=========================  ===========================================  ======
measurement                concept (modifier)                           unit
=========================  ===========================================  ======
MLD                        SCT 397413000 Vessel lumen diameter          mm
                           (derivation SCT 255605001 Minimum)
reference diameter         SCT 397413000 Vessel lumen diameter          mm
                           (method DCM 122489 Curve Fitted Reference)
% diameter stenosis        SCT 408715008 Lumen Diameter Stenosis        %
% area stenosis            SCT 408714007 Lumen Area Stenosis            %
MLA                        DCM 122480 Vessel Lumen Cross-Sectional      mm2
                           Area (derivation Minimum)
lesion length              SCT 408716009 Stenotic Lesion Length         mm
segment length             DCM 122510 Length Luminal Segment            mm
FFR (model estimate)       SCT 371842003 Fractional flow reserve        {ratio}
                           (method SCT 128576006 Computed hemodynamic
                           measurement method)
=========================  ===========================================  ======

The FFR is the distal value of :mod:`recon.lumen.ffr`'s model, for research, not
measured with a pressure wire: its method says that it was computed.

When the report carries 95 % intervals (``report["measurements_ci95"]``,
a ``{key: [low, high]}`` per measurement key; a lesion's ``ci95``), each
measurement gets them as its upper and lower measurement uncertainty (TID 310:
SCT 371886008 / 371885007, in the units of the measurement they qualify, mm or %;
highdicom's own items carry the unit "1", so they are made here); otherwise none.

The patient and study modules are copied from view A's file (highdicom
copies them from the first evidence dataset); both files must name the
same patient. The SR opens a new series. Image files (PNG/TIFF with a
geometry JSON) carry no patient or study, so ``--sr`` refuses them rather
than inventing one.
"""

from __future__ import annotations

import io
import os
import warnings
from dataclasses import dataclass
from pathlib import Path

import highdicom as hd
import pydicom
from pydicom.dataset import Dataset
from pydicom.sr.codedict import codes
from pydicom.uid import generate_uid

from recon import __version__
from recon.errors import OutputError
from recon.io.image_files import is_image_file

__all__ = [
    "SR_FILE_NAME",
    "SR_MEASUREMENTS",
    "SR_LESION_MEASUREMENTS",
    "SRSources",
    "read_sr_sources",
    "measurement_report_sr",
    "finding_site_code",
    "write_sr",
]

SR_FILE_NAME = "measurements-sr.dcm"
SR_SERIES_NUMBER = 9301  # a series number apart from the acquisition's series
SR_SERIES_DESCRIPTION = "coronary3d 3D QCA measurements"

# report.json measurement key -> (concept, unit, derivation, method)
SR_MEASUREMENTS: dict[str, tuple[hd.sr.Code, hd.sr.Code, hd.sr.Code | None, hd.sr.Code | None]]
SR_MEASUREMENTS = {
    "mld_mm": (codes.SCT.VesselLumenDiameter, codes.UCUM.Millimeter, codes.SCT.Minimum, None),
    "reference_diameter_mm": (
        codes.SCT.VesselLumenDiameter,
        codes.UCUM.Millimeter,
        None,
        codes.DCM.CurveFittedReference,
    ),
    "diameter_stenosis_pct": (codes.SCT.LumenDiameterStenosis, codes.UCUM.Percent, None, None),
    "area_stenosis_pct": (codes.SCT.LumenAreaStenosis, codes.UCUM.Percent, None, None),
    "mla_mm2": (
        codes.DCM.VesselLumenCrossSectionalArea,
        codes.UCUM.SquareMillimeter,
        codes.SCT.Minimum,
        None,
    ),
    "lesion_length_mm": (codes.SCT.StenoticLesionLength, codes.UCUM.Millimeter, None, None),
    "segment_length_mm": (codes.DCM.LengthLuminalSegment, codes.UCUM.Millimeter, None, None),
    "ffr": (codes.SCT.FractionalFlowReserve, codes.UCUM.Ratio, None,
            codes.SCT.ComputedHemodynamicMeasurementMethod),
}

# a lesion's key in report.json's ``lesions`` -> (concept, unit, derivation, method)
SR_LESION_MEASUREMENTS = {
    "mld_mm": SR_MEASUREMENTS["mld_mm"],
    "reference_diameter_mm": SR_MEASUREMENTS["reference_diameter_mm"],
    "diameter_stenosis_pct": SR_MEASUREMENTS["diameter_stenosis_pct"],
    "area_stenosis_pct": SR_MEASUREMENTS["area_stenosis_pct"],
    "mla_mm2": SR_MEASUREMENTS["mla_mm2"],
    "length_mm": SR_MEASUREMENTS["lesion_length_mm"],
}
_UPPER = hd.sr.CodedConcept("371886008", "SCT", "+, range of upper measurement uncertainty")
_LOWER = hd.sr.CodedConcept("371885007", "SCT", "-, range of lower measurement uncertainty")

# Type 2 attributes highdicom reads from the first evidence dataset; a file that
# lacks one gets it empty (DICOM's "unknown"), never a made-up value.
_PATIENT_STUDY_TYPE2 = (
    "PatientName",
    "PatientID",
    "PatientBirthDate",
    "PatientSex",
    "AccessionNumber",
    "StudyID",
    "StudyDate",
    "StudyTime",
    "ReferringPhysicianName",
)


@dataclass(frozen=True, eq=False)
class SRSources:
    """The two source angiograms' headers (read without their pixels), paths, and the
    1-based frame used of each (None: not recorded; referenced only for a cine)."""

    header_a: Dataset
    header_b: Dataset
    path_a: str
    path_b: str
    frame_numbers: tuple[int | None, int | None] = (None, None)


def read_sr_sources(
    path_a: str | os.PathLike,
    path_b: str | os.PathLike,
    frame_numbers: tuple[int | None, int | None] = (None, None),
) -> SRSources:
    """The headers an SR of this pair needs (checked before the reconstruction runs), and
    the 1-based frames used of each view.

    Raises :class:`OutputError` with one line naming the file when an input
    is an image file (no patient or study to copy), not readable DICOM,
    lacks a SOP or Study Instance UID, or names another patient than view A.
    """
    headers = []
    for path in (os.fspath(path_a), os.fspath(path_b)):
        if is_image_file(Path(path)):
            raise OutputError(
                f"{path}: --sr needs DICOM inputs (the report copies their patient and "
                "study); an image file has neither, so no SR is written for it"
            )
        try:
            ds = pydicom.dcmread(path, stop_before_pixels=True)
        except (OSError, pydicom.errors.InvalidDicomError) as exc:
            raise OutputError(f"{path}: --sr cannot read the DICOM header ({exc})") from None
        for keyword in ("SOPClassUID", "SOPInstanceUID", "StudyInstanceUID"):
            if not str(ds.get(keyword, "") or ""):
                raise OutputError(f"{path}: --sr needs {keyword}, which the file lacks")
        headers.append(ds)
    a, b = headers
    if (str(a.get("PatientID", "")), str(a.get("PatientName", ""))) != (
        str(b.get("PatientID", "")),
        str(b.get("PatientName", "")),
    ):
        raise OutputError(
            f"{os.fspath(path_b)}: --sr: the two views name different patients "
            "(PatientID or PatientName differ from view A's)"
        )
    return SRSources(
        header_a=a,
        header_b=b,
        path_a=os.fspath(path_a),
        path_b=os.fspath(path_b),
        frame_numbers=frame_numbers,
    )


def measurement_report_sr(report: dict, sources: SRSources) -> bytes:
    """The SR file's bytes for one reconstruction's report (report.json's dict): a group
    per segment (``report["branches"]`` for a tree, else the report itself) and one per
    lesion of each."""
    evidence = [_evidence(sources.header_a), _evidence(sources.header_b)]
    algorithm = hd.sr.AlgorithmIdentification(name="coronary3d", version=__version__)
    groups = []
    for entry in report.get("branches") or [report]:
        name = str(entry.get("inputs", {}).get("segment") or "segment")
        site = [hd.sr.FindingSite(anatomic_location=finding_site_code(name))]
        values, intervals = entry["measurements"], entry.get("measurements_ci95") or {}
        groups.append(hd.sr.MeasurementsAndQualitativeEvaluations(
            tracking_identifier=hd.sr.TrackingIdentifier(uid=generate_uid(), identifier=name),
            finding_type=codes.SCT.Stenosis, finding_sites=site, algorithm_id=algorithm,
            measurements=_measurements(SR_MEASUREMENTS, values, intervals),
            source_images=_source_images(evidence, sources.frame_numbers)))
        for lesion in entry.get("lesions") or []:
            ident = f"{name} lesion {lesion['number']}"
            groups.append(hd.sr.MeasurementsAndQualitativeEvaluations(
                tracking_identifier=hd.sr.TrackingIdentifier(uid=generate_uid(),
                                                              identifier=ident),
                finding_type=codes.SCT.Stenosis, finding_sites=site, algorithm_id=algorithm,
                measurements=_measurements(SR_LESION_MEASUREMENTS, lesion,
                                           lesion.get("ci95") or {}),
                source_images=_source_images(evidence, sources.frame_numbers)))
    observer = hd.sr.ObserverContext(
        observer_type=codes.DCM.Device,
        observer_identifying_attributes=hd.sr.DeviceObserverIdentifyingAttributes(
            uid=generate_uid(), name="coronary3d", model_name=__version__
        ),
    )
    content = hd.sr.MeasurementReport(
        observation_context=hd.sr.ObservationContext(observer_device_context=observer),
        procedure_reported=codes.SCT.CoronaryArteriography,
        imaging_measurements=groups,
    )
    with warnings.catch_warnings():
        # highdicom warns about the form of a person name, quoting it: patient data
        # stays out of the terminal and the logs
        warnings.simplefilter("ignore")
        sr = hd.sr.Comprehensive3DSR(
            evidence=evidence,
            content=content[0],
            series_instance_uid=generate_uid(),
            series_number=SR_SERIES_NUMBER,
            sop_instance_uid=generate_uid(),
            instance_number=1,
            manufacturer="coronary3d",
            series_description=SR_SERIES_DESCRIPTION,
            is_complete=True,
        )
    buffer = io.BytesIO()
    sr.save_as(buffer, enforce_file_format=True)
    return buffer.getvalue()


def _source_images(evidence: list[Dataset], frame_numbers: tuple[int | None, int | None]
                   ) -> list[hd.sr.SourceImageForMeasurementGroup]:
    """Both angiograms as a group's source images (the frame used, for a cine)."""
    images = []
    for ds, frame in zip(evidence, frame_numbers, strict=True):
        cine = frame is not None and int(ds.get("NumberOfFrames", 1) or 1) > 1
        images.append(hd.sr.SourceImageForMeasurementGroup(
            referenced_sop_class_uid=ds.SOPClassUID,
            referenced_sop_instance_uid=ds.SOPInstanceUID,
            referenced_frame_numbers=[int(frame)] if cine else None))
    return images


def _measurements(concepts: dict, values: dict, intervals: dict) -> list[hd.sr.Measurement]:
    """The measurements of ``concepts`` (key -> concept, unit, derivation, method) that
    ``values`` holds, each with its 95 % interval from ``intervals`` (key -> [lo, hi]) as
    upper and lower measurement uncertainty in the measurement's own unit."""
    out = []
    for key, (concept, unit, derivation, method) in concepts.items():
        if values.get(key) is None:  # a report without the FFR
            continue
        value = float(values[key])
        properties = None
        if intervals.get(key) is not None:
            low, high = (float(v) for v in intervals[key])
            properties = hd.sr.MeasurementProperties()
            for name, spread in ((_UPPER, max(0.0, high - value)),
                                 (_LOWER, max(0.0, value - low))):
                properties.append(hd.sr.NumContentItem(
                    name=name, value=spread, unit=unit,
                    relationship_type=hd.sr.RelationshipTypeValues.HAS_PROPERTIES))
        out.append(hd.sr.Measurement(name=concept, value=value, unit=unit,
                                     derivation=derivation, method=method,
                                     properties=properties))
    return out


#: Segment-name words -> the CID 3015 concept (pydicom's codes.SCT name); checked in order,
#: the first whose words all occur in the name wins.
_SITES: tuple[tuple[tuple[str, ...], str], ...] = (
    (("lm",), "LeftMainCoronaryArtery"), (("lmca",), "LeftMainCoronaryArtery"),
    (("left", "main"), "LeftMainCoronaryArtery"),
    (("plad",), "ProximalLeftAnteriorDescendingCoronaryArtery"),
    (("proximal", "lad"), "ProximalLeftAnteriorDescendingCoronaryArtery"),
    (("mlad",), "MidLeftAnteriorDescendingCoronaryArtery"),
    (("mid", "lad"), "MidLeftAnteriorDescendingCoronaryArtery"),
    (("dlad",), "DistalLeftAnteriorDescendingCoronaryArtery"),
    (("distal", "lad"), "DistalLeftAnteriorDescendingCoronaryArtery"),
    (("lad",), "LeftAnteriorDescendingCoronaryArtery"),
    (("anterior", "descending"), "LeftAnteriorDescendingCoronaryArtery"),
    (("proximal", "lcx"), "ProximalCircumflexCoronaryArtery"),
    (("proximal", "cx"), "ProximalCircumflexCoronaryArtery"),
    (("mid", "lcx"), "MidCircumflexCoronaryArtery"), (("mid", "cx"), "MidCircumflexCoronaryArtery"),
    (("distal", "lcx"), "DistalCircumflexCoronaryArtery"),
    (("distal", "cx"), "DistalCircumflexCoronaryArtery"),
    (("lcx",), "CircumflexCoronaryArtery"), (("cx",), "CircumflexCoronaryArtery"),
    (("circumflex",), "CircumflexCoronaryArtery"),
    (("prca",), "ProximalRightCoronaryArtery"),
    (("proximal", "rca"), "ProximalRightCoronaryArtery"),
    (("mrca",), "MidRightCoronaryArtery"), (("mid", "rca"), "MidRightCoronaryArtery"),
    (("drca",), "DistalRightCoronaryArtery"), (("distal", "rca"), "DistalRightCoronaryArtery"),
    (("rca",), "RightCoronaryArtery"), (("right", "coronary"), "RightCoronaryArtery"),
    (("d1",), "_1stDiagonalCoronaryArtery"), (("diagonal", "1"), "_1stDiagonalCoronaryArtery"),
    (("first", "diagonal"), "_1stDiagonalCoronaryArtery"),
    (("d2",), "_2ndDiagonalCoronaryArtery"), (("diagonal", "2"), "_2ndDiagonalCoronaryArtery"),
    (("second", "diagonal"), "_2ndDiagonalCoronaryArtery"),
    (("d3",), "_3rdDiagonalCoronaryArtery"), (("diagonal", "3"), "_3rdDiagonalCoronaryArtery"),
    (("third", "diagonal"), "_3rdDiagonalCoronaryArtery"),
    (("om1",), "_1stMarginalCoronaryArtery"), (("om", "1"), "_1stMarginalCoronaryArtery"),
    (("om2",), "_2ndMarginalCoronaryArtery"), (("om", "2"), "_2ndMarginalCoronaryArtery"),
    (("om3",), "_3rdMarginalCoronaryArtery"), (("om", "3"), "_3rdMarginalCoronaryArtery"),
    (("ramus",), "IntermediateArteryRamus"), (("intermediate",), "IntermediateArteryRamus"),
    (("pda",), "PosteriorDescendingRightCoronaryArtery"),
    (("posterior", "descending"), "PosteriorDescendingRightCoronaryArtery"),
    (("s1",), "_1stSeptalCoronaryArtery"), (("first", "septal"), "_1stSeptalCoronaryArtery"),
)


def finding_site_code(segment_name: str) -> hd.sr.Code:
    """The Finding Site concept of a segment named ``segment_name`` (module docstring):
    its words (letters and digits, case ignored) matched against :data:`_SITES`."""
    import re

    words = set(re.findall(r"[a-z]+|\d+", str(segment_name).lower()))
    joined = set(re.findall(r"[a-z]+\d*", str(segment_name).lower()))  # "om1", "d2"
    for needed, concept in _SITES:
        if all(w in words or w in joined for w in needed):
            return getattr(codes.SCT, concept)
    return codes.SCT.CoronaryArtery


def write_sr(result, path: str | os.PathLike, sources: SRSources | tuple) -> Path:
    """Write the SR of a reconstruction (a :class:`recon.pipeline.Reconstruction` or
    :class:`recon.tree.TreeReconstruction`) to ``path`` (whole or not at all) and return
    the path. ``sources``: an :class:`SRSources`, or the two inputs as (path_a, path_b)
    or (path_a, path_b, (frame_a, frame_b)) with 1-based frames, checked as
    :func:`read_sr_sources` checks them. Its values are report.json's to the digit (the
    report goes through JSON, as in the output set)."""
    import json

    import numpy as np

    from recon.io.files import atomic_write_bytes

    def plain(value: object) -> object:
        if isinstance(value, np.generic):
            return value.item()
        if isinstance(value, np.ndarray | tuple):
            return list(value)
        return str(value)

    if not isinstance(sources, SRSources):
        sources = read_sr_sources(*sources)
    report = json.loads(json.dumps(result.report(), default=plain))
    atomic_write_bytes(path, measurement_report_sr(report, sources))
    return Path(path)


def _evidence(header: Dataset) -> Dataset:
    """A copy of a source header with the Type 2 patient/study attributes present."""
    ds = Dataset()
    ds.update(header)
    for keyword in _PATIENT_STUDY_TYPE2:
        if keyword not in ds:
            setattr(ds, keyword, "")
    return ds
