"""measurements-sr.dcm: the 3D measurements as a DICOM Structured Report (highdicom).

The document is a TID 1500 "Measurement Report" in a Comprehensive 3D SR
instance. DICOM's own QCA template (TID 3213, Quantitative Arterial
Analysis) describes measurements made in one projection image; ours are
made along a 3D centerline triangulated from two projections, so the
generic measurement report is the honest container: one measurement group
(TID 1501) for the reconstructed segment, whose source images are both
angiograms (by SOP Instance UID, and frame number for a cine).

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
a ``{key: [low, high]}`` per measurement key), each measurement gets them
as its upper and lower measurement uncertainty (TID 310); otherwise none.

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
    "SRSources",
    "read_sr_sources",
    "measurement_report_sr",
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
    """The SR file's bytes for one reconstruction's report (report.json's dict)."""
    evidence = [_evidence(sources.header_a), _evidence(sources.header_b)]
    images = []
    for ds, frame in zip(evidence, sources.frame_numbers, strict=True):
        cine = frame is not None and int(ds.get("NumberOfFrames", 1) or 1) > 1
        frames = [int(frame)] if cine else None
        images.append(
            hd.sr.SourceImageForMeasurementGroup(
                referenced_sop_class_uid=ds.SOPClassUID,
                referenced_sop_instance_uid=ds.SOPInstanceUID,
                referenced_frame_numbers=frames,
            )
        )
    algorithm = hd.sr.AlgorithmIdentification(name="coronary3d", version=__version__)
    values = report["measurements"]
    intervals = report.get("measurements_ci95") or {}
    measurements = []
    for key, (concept, unit, derivation, method) in SR_MEASUREMENTS.items():
        if values.get(key) is None:  # a report without the FFR
            continue
        value = float(values[key])
        properties = None
        if key in intervals:
            low, high = (float(v) for v in intervals[key])
            properties = hd.sr.MeasurementProperties(
                upper_measurement_uncertainty=max(0.0, high - value),
                lower_measurement_uncertainty=max(0.0, value - low),
            )
        measurements.append(
            hd.sr.Measurement(
                name=concept,
                value=value,
                unit=unit,
                derivation=derivation,
                method=method,
                properties=properties,
            )
        )
    segment = str(report.get("inputs", {}).get("segment") or "segment")
    group = hd.sr.MeasurementsAndQualitativeEvaluations(
        tracking_identifier=hd.sr.TrackingIdentifier(uid=generate_uid(), identifier=segment),
        finding_type=codes.SCT.Stenosis,
        finding_sites=[hd.sr.FindingSite(anatomic_location=codes.SCT.CoronaryArtery)],
        algorithm_id=algorithm,
        measurements=measurements,
        source_images=images,
    )
    observer = hd.sr.ObserverContext(
        observer_type=codes.DCM.Device,
        observer_identifying_attributes=hd.sr.DeviceObserverIdentifyingAttributes(
            uid=generate_uid(), name="coronary3d", model_name=__version__
        ),
    )
    content = hd.sr.MeasurementReport(
        observation_context=hd.sr.ObservationContext(observer_device_context=observer),
        procedure_reported=codes.SCT.CoronaryArteriography,
        imaging_measurements=[group],
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


def _evidence(header: Dataset) -> Dataset:
    """A copy of a source header with the Type 2 patient/study attributes present."""
    ds = Dataset()
    ds.update(header)
    for keyword in _PATIENT_STUDY_TYPE2:
        if keyword not in ds:
            setattr(ds, keyword, "")
    return ds
