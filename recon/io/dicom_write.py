"""Write X-Ray Angiographic Image Storage files (the phantom's and the tests').

Frame indices given to the writer are 0-based and written as the 1-based
DICOM frame numbers (RepresentativeFrameNumber, R Wave Pointer); see
:mod:`recon.io.frames`.
"""

from __future__ import annotations

import io
import os
from collections.abc import Sequence
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pydicom
from numpy.typing import ArrayLike
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.encaps import encapsulate
from pydicom.uid import ExplicitVRLittleEndian, generate_uid

from recon.geometry import ViewGeometry
from recon.io.dicom_read import XA_SOP_CLASS_UID
from recon.io.files import atomic_write_bytes

__all__ = ["write_xa_dicom"]


def _ds_number(value: float) -> str:
    """A DICOM DS string (at most 16 characters) for ``value``."""
    text = f"{float(value):.10g}"
    if len(text) > 16:
        text = f"{float(value):.8g}"
    return text


def _xa_dataset(
    frames: ArrayLike,
    geometry: ViewGeometry,
    *,
    frame_time_ms: float | None,
    r_wave_frames: Sequence[int] | None,
    bits_stored: int,
    series_description: str,
    representative_frame: int | None,
    pixel_intensity_relationship: str | None = None,
) -> Dataset:
    """Build the dataset written by :func:`write_xa_dicom` (see there)."""
    arr = np.asarray(frames)
    if arr.ndim not in (2, 3):
        raise ValueError(f"frames must have shape (H, W) or (F, H, W), got {arr.shape}")
    if arr.dtype.kind not in "ub":
        raise ValueError(f"frames must be an unsigned integer array, got dtype {arr.dtype}")
    if not 1 <= bits_stored <= 16:
        raise ValueError(f"bits_stored must be in 1..16, got {bits_stored}")
    stack = arr[None] if arr.ndim == 2 else arr
    n_frames, rows, cols = stack.shape
    if n_frames < 1 or rows < 1 or cols < 1:
        raise ValueError(f"frames must not be empty, got shape {arr.shape}")
    if (rows, cols) != (geometry.rows, geometry.cols):
        raise ValueError(
            f"frames are {rows}x{cols} but the geometry says {geometry.rows}x{geometry.cols}"
        )
    if int(stack.max()) >= 2**bits_stored:
        raise ValueError(f"pixel value {int(stack.max())} does not fit in {bits_stored} bits")
    bits_allocated = 8 if bits_stored <= 8 else 16
    pixels = np.ascontiguousarray(stack, dtype=np.uint8 if bits_allocated == 8 else "<u2")

    def _frame_number(index: int, what: str) -> int:
        if not 0 <= int(index) < n_frames:
            raise ValueError(f"{what} {index} is outside 0..{n_frames - 1} (0-based)")
        return int(index) + 1  # DICOM frame numbers are 1-based

    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = XA_SOP_CLASS_UID
    meta.MediaStorageSOPInstanceUID = generate_uid()
    meta.TransferSyntaxUID = ExplicitVRLittleEndian

    ds = Dataset()
    ds.file_meta = meta
    now = datetime.now()
    ds.SpecificCharacterSet = "ISO_IR 100"
    ds.ImageType = ["DERIVED", "SECONDARY", "SINGLE PLANE"]
    ds.SOPClassUID = XA_SOP_CLASS_UID
    ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
    ds.StudyDate = ds.SeriesDate = ds.ContentDate = now.strftime("%Y%m%d")
    ds.StudyTime = ds.SeriesTime = ds.ContentTime = now.strftime("%H%M%S")
    ds.AccessionNumber = ""
    ds.Modality = "XA"
    ds.Manufacturer = "coronary3d"
    ds.ReferringPhysicianName = ""
    ds.SeriesDescription = series_description
    ds.PatientName = "PHANTOM"
    ds.PatientID = "PHANTOM"
    ds.PatientBirthDate = ""
    ds.PatientSex = "O"
    ds.StudyInstanceUID = generate_uid()
    ds.SeriesInstanceUID = generate_uid()
    ds.StudyID = "1"
    ds.SeriesNumber = 1
    ds.InstanceNumber = 1
    ds.PatientOrientation = ""
    ds.KVP = ""
    ds.PositionerMotion = "STATIC"
    ds.PositionerPrimaryAngle = _ds_number(geometry.alpha_deg)
    ds.PositionerSecondaryAngle = _ds_number(geometry.beta_deg)
    ds.DistanceSourceToDetector = _ds_number(geometry.sid_mm)
    ds.DistanceSourceToPatient = _ds_number(geometry.sod_mm)
    ds.ImagerPixelSpacing = [_ds_number(s) for s in geometry.pixel_spacing_mm]
    ds.EstimatedRadiographicMagnificationFactor = _ds_number(geometry.sid_mm / geometry.sod_mm)
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.Rows = rows
    ds.Columns = cols
    ds.BitsAllocated = bits_allocated
    ds.BitsStored = bits_stored
    ds.HighBit = bits_stored - 1
    ds.PixelRepresentation = 0
    ds.LossyImageCompression = "00"
    if pixel_intensity_relationship is not None:
        ds.PixelIntensityRelationship = pixel_intensity_relationship
    if arr.ndim == 3:
        ds.NumberOfFrames = n_frames
        ds.FrameIncrementPointer = pydicom.tag.Tag("FrameTime")
        ds.FrameTime = _ds_number(frame_time_ms if frame_time_ms is not None else 66.6667)
        ds.CineRate = max(1, round(1000.0 / float(ds.FrameTime)))
    elif frame_time_ms is not None:
        ds.FrameTime = _ds_number(frame_time_ms)
    if representative_frame is not None:
        ds.RepresentativeFrameNumber = _frame_number(representative_frame, "representative_frame")
    if r_wave_frames is not None and len(r_wave_frames) > 0:
        ds.RWavePointer = [_frame_number(k, "r_wave_frames entry") for k in r_wave_frames]
    ds.PixelData = pixels.tobytes()
    return ds


def write_xa_dicom(
    path: str | os.PathLike,
    frames: ArrayLike,
    geometry: ViewGeometry,
    *,
    frame_time_ms: float | None = None,
    r_wave_frames: Sequence[int] | None = None,
    bits_stored: int = 12,
    series_description: str = "",
    representative_frame: int | None = None,
    pixel_intensity_relationship: str | None = None,
) -> None:
    """Write an X-Ray Angiographic Image Storage file (explicit VR little endian).

    Parameters
    ----------
    path : output file; written atomically (temporary file in the same
        folder, then rename).
    frames : (H, W) or (F, H, W) unsigned integer array, MONOCHROME2 (vessels
        dark), values below ``2**bits_stored``. A 3-D array is written as a
        cine (NumberOfFrames, FrameTime) even when F == 1.
    geometry : the view; its angles, SID, SOD and pixel spacing go to
        PositionerPrimaryAngle, PositionerSecondaryAngle,
        DistanceSourceToDetector, DistanceSourceToPatient and
        ImagerPixelSpacing; rows/cols must match the frames. The rigid
        correction of the geometry is not written (the header is nominal).
    frame_time_ms : FrameTime (default 66.6667 ms for a cine).
    r_wave_frames : 0-based frame indices of R waves, written to R Wave
        Pointer (0028,6040) as 1-based frame numbers.
    bits_stored : 1..16; BitsAllocated is 8 up to 8 bits, else 16.
    series_description : SeriesDescription.
    representative_frame : 0-based index written to RepresentativeFrameNumber
        (1-based).
    pixel_intensity_relationship : PixelIntensityRelationship (0028,1040)
        ("LIN", "LOG", "DISP", ...); not written when None.

    Fresh UIDs are generated; the patient is the anonymous "PHANTOM".
    Raises ValueError for arrays or indices that do not fit.
    """
    ds = _xa_dataset(
        frames,
        geometry,
        frame_time_ms=frame_time_ms,
        r_wave_frames=r_wave_frames,
        bits_stored=bits_stored,
        series_description=series_description,
        representative_frame=representative_frame,
        pixel_intensity_relationship=pixel_intensity_relationship,
    )
    _save_dataset(ds, path)


def _save_dataset(ds: Dataset, path: str | os.PathLike) -> None:
    buffer = io.BytesIO()
    ds.save_as(buffer, enforce_file_format=True)
    atomic_write_bytes(Path(path), buffer.getvalue())


def _write_test_dicom(
    path: str | os.PathLike,
    frames: ArrayLike,
    geometry: ViewGeometry,
    *,
    bits_stored: int = 12,
    remove: Sequence[str] = (),
    set_values: dict[str, Any] | None = None,
    garbage_compressed_as: str | None = None,
    **kwargs: Any,
) -> None:
    """Private, for tests: an XA file like :func:`write_xa_dicom` with tags
    removed (DICOM keywords in ``remove``) or set (``set_values``: keyword ->
    value, e.g. SOPClassUID, Modality, PhotometricInterpretation,
    PixelSpacing, FieldOfViewDimensions), or with undecodable encapsulated
    pixel data under the transfer syntax UID ``garbage_compressed_as``. Tests
    use it to build CT, MONOCHROME1, geometry-less and undecodable files
    without importing pydicom."""
    ds = _xa_dataset(
        frames,
        geometry,
        frame_time_ms=kwargs.get("frame_time_ms"),
        r_wave_frames=kwargs.get("r_wave_frames"),
        bits_stored=bits_stored,
        series_description=kwargs.get("series_description", ""),
        representative_frame=kwargs.get("representative_frame"),
    )
    for keyword in remove:
        if keyword in ds:
            del ds[keyword]
    for keyword, value in (set_values or {}).items():
        setattr(ds, keyword, value)
        if keyword == "SOPClassUID":
            ds.file_meta.MediaStorageSOPClassUID = value
    if garbage_compressed_as is not None:
        ds.file_meta.TransferSyntaxUID = garbage_compressed_as
        ds.PixelData = encapsulate([b"\x00\x01 not a codestream " * 4])
        ds["PixelData"].VR = "OB"
    _save_dataset(ds, path)
