"""Read a projection X-ray DICOM file (XA, and RF/DX/CR/SC) into a raw record.

Pixels are decoded by pydicom (uncompressed, JPEG Lossless, JPEG Baseline or
what pylibjpeg decodes) and kept as raw stored values in float32, no rescale
and no windowing; MONOCHROME1 is inverted on reading so that contrast-filled
vessels are dark (the MONOCHROME2 sense). Geometry tags are read from the top
level or from the first item of the functional groups of enhanced objects.
R Wave Pointer frame numbers (1-based) are converted to 0-based
``info["r_wave_frames"]``; the raw values stay in ``info["r_wave_pointer"]``.
"""

from __future__ import annotations

import math
import warnings
from typing import Any

import numpy as np
import pydicom
from pydicom.dataset import Dataset
from pydicom.uid import UID

from recon.errors import LoadError
from recon.io.image_files import IMAGE_SUFFIXES
from recon.io.raw import RawFile, first_line
from recon.io.validate import safe_text

__all__ = ["LOSSY_TRANSFER_SYNTAXES", "XA_SOP_CLASS_UID", "is_lossy", "read_dicom"]

XA_SOP_CLASS_UID = "1.2.840.10008.5.1.4.1.1.12.1"  # X-Ray Angiographic Image Storage

# Projection X-ray SOP classes this loader reads. XA is the target; the others
# (enhanced XA, radiofluoroscopic, DX, CR, secondary capture) are accepted when
# the geometry is present in the header or supplied by the user.
_PROJECTION_SOP_CLASSES = {
    XA_SOP_CLASS_UID,
    "1.2.840.10008.5.1.4.1.1.12.1.1",  # Enhanced XA Image Storage
    "1.2.840.10008.5.1.4.1.1.12.2",  # X-Ray Radiofluoroscopic Image Storage
    "1.2.840.10008.5.1.4.1.1.12.2.1",  # Enhanced XRF Image Storage
    "1.2.840.10008.5.1.4.1.1.1",  # Computed Radiography Image Storage
    "1.2.840.10008.5.1.4.1.1.1.1",  # Digital X-Ray Image Storage - For Presentation
    "1.2.840.10008.5.1.4.1.1.1.1.1",  # Digital X-Ray Image Storage - For Processing
    "1.2.840.10008.5.1.4.1.1.7",  # Secondary Capture Image Storage
    "1.2.840.10008.5.1.4.1.1.7.2",  # Multi-frame Grayscale Byte SC Image Storage
    "1.2.840.10008.5.1.4.1.1.7.3",  # Multi-frame Grayscale Word SC Image Storage
}
_PROJECTION_MODALITIES = {"XA", "RF", "DX", "CR", "OT"}

# Transfer syntaxes whose compression may discard information (lossy, or "lossy
# or lossless" where the file does not say which). pydicom's UID.is_compressed
# is True for the lossless ones too, so they are listed here explicitly.
LOSSY_TRANSFER_SYNTAXES = {
    "1.2.840.10008.1.2.4.50": "JPEG Baseline (Process 1)",
    "1.2.840.10008.1.2.4.51": "JPEG Extended (Process 2 & 4)",
    **{f"1.2.840.10008.1.2.4.{k}": "JPEG lossy (retired process)"
       for k in (52, 53, 54, 55, 56, 59, 60, 61, 62, 63, 64)},
    "1.2.840.10008.1.2.4.81": "JPEG-LS Lossy (Near-Lossless)",
    "1.2.840.10008.1.2.4.91": "JPEG 2000 (lossy or lossless)",
    "1.2.840.10008.1.2.4.93": "JPEG 2000 Part 2 Multi-component (lossy or lossless)",
    "1.2.840.10008.1.2.4.203": "HTJ2K (lossy or lossless)",
    "1.2.840.10008.1.2.4.111": "JPEG XL JPEG Recompression",
    "1.2.840.10008.1.2.4.112": "JPEG XL (lossy or lossless)",
    **{f"1.2.840.10008.1.2.4.{k}": "MPEG/HEVC video"
       for k in (100, 101, 102, 103, 104, 105, 106, 107, 108)},
}


def is_lossy(transfer_syntax: str, lossy_image_compression: object = None) -> bool:
    """True for a lossy transfer syntax, or when LossyImageCompression (0028,2110)
    is "01" (the pixels were lossy-compressed at some point, whatever the file's
    transfer syntax is now)."""
    return (str(transfer_syntax) in LOSSY_TRANSFER_SYNTAXES
            or str(lossy_image_compression or "").strip() == "01")


def _dicom_value(ds: Dataset, keyword: str) -> Any:
    """A tag's value from the top level, or from the first item of the
    shared / per-frame functional groups (enhanced multi-frame objects)."""
    if keyword in ds and ds[keyword].value not in (None, ""):
        return ds[keyword].value
    for group in ("SharedFunctionalGroupsSequence", "PerFrameFunctionalGroupsSequence"):
        seq = ds.get(group)
        if not seq:
            continue
        for macro in seq[0]:
            if macro.VR != "SQ" or not macro.value:
                continue
            item = macro.value[0]
            if keyword in item and item[keyword].value not in (None, ""):
                return item[keyword].value
    return None


def _as_float(value: Any) -> float | None:
    if value is None:
        return None
    try:
        if isinstance(value, (list, tuple, pydicom.multival.MultiValue)):
            value = value[0]
        out = float(value)
    except (TypeError, ValueError, IndexError):
        return None
    return out if math.isfinite(out) else None


def _as_floats(value: Any) -> tuple[float, ...] | None:
    if value is None:
        return None
    if not isinstance(value, (list, tuple, pydicom.multival.MultiValue)):
        value = [value]
    try:
        out = tuple(float(v) for v in value)
    except (TypeError, ValueError):
        return None
    return out if out and all(math.isfinite(v) for v in out) else None


def _as_ints(value: Any) -> list[int]:
    if value is None:
        return []
    if not isinstance(value, (list, tuple, pydicom.multival.MultiValue)):
        value = [value]
    out = []
    for v in value:
        try:
            out.append(int(v))
        except (TypeError, ValueError):
            continue
    return out


def _decode_every_element(ds: Dataset, path: str) -> None:
    """Decode every element now, so that a corrupt one is a LoadError here and
    not an exception deep in a later ``ds.get`` (the raw bytes are not echoed)."""
    tag = None
    try:
        for dataset in (getattr(ds, "file_meta", None), ds):
            for elem in dataset.iterall() if dataset is not None else ():
                _ = elem.value
                tag = elem.tag
    except Exception as exc:  # pydicom raises many kinds on corrupt element bytes
        after = f" after element {tag}" if tag is not None else ""
        raise LoadError(
            f"{path}: corrupt DICOM header: an element{after} cannot be decoded "
            f"({type(exc).__name__})"
        ) from None


def _header_number(ds: Dataset, keyword: str, key: str, invalid: dict[str, str],
                   positive: bool = False) -> float | None:
    """A one-number tag (the first value of several), None when absent; a value
    present but unusable is recorded in ``invalid`` (and None is returned)."""
    raw = _dicom_value(ds, keyword)
    if raw is None:
        return None
    value = _as_float(raw)
    if value is None or (positive and value <= 0):
        invalid[key] = safe_text(raw)
        return None
    return value


def _header_numbers(ds: Dataset, keyword: str, key: str,
                    invalid: dict[str, str]) -> tuple[float, ...] | None:
    """A one- or two-number positive tag (a spacing, a field of view), as
    :func:`_header_number`."""
    raw = _dicom_value(ds, keyword)
    if raw is None:
        return None
    values = _as_floats(raw)
    if values is None or len(values) > 2 or not all(v > 0 for v in values):
        invalid[key] = safe_text(raw)
        return None
    return values


def _representative_frame(value: Any, path: str) -> int | None:
    """RepresentativeFrameNumber (0028,6010), one positive integer, or None when absent."""
    if value is None or value == "":
        return None
    if isinstance(value, (list, tuple, pydicom.multival.MultiValue)):
        raise LoadError(
            f"{path}: RepresentativeFrameNumber (0028,6010) has {len(value)} values; "
            f"expected one frame number"
        )
    try:
        return int(value)
    except (TypeError, ValueError):
        raise LoadError(
            f"{path}: RepresentativeFrameNumber (0028,6010) is not a frame number "
            f"({safe_text(value)})"
        ) from None


def _raw_maximum(ds: Dataset, allocated: int) -> int | None:
    """The largest stored value of uncompressed unsigned pixel data, before pydicom
    masks it to BitsStored; None when the data is compressed or signed."""
    meta = getattr(ds, "file_meta", None)
    ts = str(meta.get("TransferSyntaxUID", "")) if meta is not None else ""
    if ts not in ("1.2.840.10008.1.2", "1.2.840.10008.1.2.1") or allocated not in (8, 16):
        return None
    if int(ds.get("PixelRepresentation", 0) or 0) != 0 or "PixelData" not in ds:
        return None
    data = ds.PixelData
    dtype = np.dtype("<u2") if allocated == 16 else np.dtype(np.uint8)
    usable = len(data) - len(data) % dtype.itemsize
    if usable == 0:
        return None
    return int(np.frombuffer(data[:usable], dtype=dtype).max())


def _bits_stored(ds: Dataset, arr: np.ndarray, path: str) -> int:
    """BitsStored (0028,0101), checked against BitsAllocated and the pixel values."""
    allocated = 8 * arr.dtype.itemsize
    raw = ds.get("BitsStored")
    if raw is None or raw == "":
        return allocated
    try:
        bits = int(raw)
    except (TypeError, ValueError):
        raise LoadError(f"{path}: BitsStored (0028,0101) is not a number ({safe_text(raw)})") \
            from None
    if not 1 <= bits <= max(allocated, 8):
        raise LoadError(f"{path}: BitsStored (0028,0101) is {bits}; expected 1 to {allocated}")
    top = _raw_maximum(ds, allocated) if bits < allocated else None
    if top is not None and top > 2**bits - 1:
        raise LoadError(
            f"{path}: BitsStored (0028,0101) is {bits} but the stored pixel values reach {top} "
            f"({top.bit_length()} bits)"
        )
    return bits


def read_dicom(path: str) -> RawFile:
    """Frames, header geometry and facts of a DICOM file; LoadError for what cannot be used."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            ds = pydicom.dcmread(path)
        except pydicom.errors.InvalidDicomError:
            raise LoadError(
                f"{path}: not a DICOM file (no DICM preamble) and not an image file "
                f"({', '.join(sorted(IMAGE_SUFFIXES))})"
            ) from None
        except Exception as exc:  # truncated or corrupt header
            raise LoadError(
                f"{path}: unreadable DICOM file, truncated or corrupt "
                f"({safe_text(first_line(exc), 80)})"
            ) from None
        _decode_every_element(ds, path)

        meta = getattr(ds, "file_meta", None)
        sop_class = str(
            ds.get("SOPClassUID", "") or (meta or {}).get("MediaStorageSOPClassUID", "")
        )
        modality = str(ds.get("Modality", "") or "")
        sop_name = UID(sop_class).name if sop_class else "unknown SOP class"
        if not sop_class and not modality:
            raise LoadError(
                f"{path}: the DICOM header has no SOP class and no modality "
                f"(truncated file, or not an image)"
            )
        if sop_class:
            accepted = sop_class in _PROJECTION_SOP_CLASSES
        else:
            accepted = modality in _PROJECTION_MODALITIES
        if not accepted:
            raise LoadError(
                f"{path}: is a {sop_name} (modality {modality or '?'}), not an X-ray "
                f"angiogram; this program reads XA (or RF/DX projection) images"
            )
        if "PixelData" not in ds and "FloatPixelData" not in ds:
            raise LoadError(
                f"{path}: the DICOM file has no pixel data (truncated file, or no image in it)"
            )
        ts = str(meta.get("TransferSyntaxUID", "")) if meta is not None else ""
        try:
            pixels = ds.pixel_array
        except Exception as exc:
            ts_name = UID(ts).name if ts else "unknown transfer syntax"
            raise LoadError(
                f"{path}: cannot decode the pixel data ({ts_name}): "
                f"{safe_text(first_line(exc), 80)}"
            ) from None

    rows, cols = int(ds.get("Rows", 0) or 0), int(ds.get("Columns", 0) or 0)
    n_frames = int(_as_float(ds.get("NumberOfFrames")) or 1)
    samples = int(ds.get("SamplesPerPixel", 1) or 1)
    arr = np.asarray(pixels)
    if samples > 1:  # colour (pydicom returns RGB): luminance, (.., H, W, 3) -> (.., H, W)
        arr = arr[..., :3].astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)
    if arr.ndim == 2:
        arr = arr[None]
    if arr.ndim != 3 or arr.shape[1:] != (rows, cols) or arr.shape[0] != n_frames:
        raise LoadError(
            f"{path}: pixel data of shape {arr.shape} does not match "
            f"{n_frames} frame(s) of {rows}x{cols}"
        )
    photometric = str(ds.get("PhotometricInterpretation", "MONOCHROME2") or "MONOCHROME2")
    bits_stored = _bits_stored(ds, arr, path)
    signed = int(ds.get("PixelRepresentation", 0) or 0) == 1
    frames = arr.astype(np.float32, copy=False)
    if photometric == "MONOCHROME1":
        if signed:
            lo, hi = -(2 ** (bits_stored - 1)), 2 ** (bits_stored - 1) - 1
        else:
            lo, hi = 0, 2**bits_stored - 1
        frames = (lo + hi) - frames  # same value range, vessels now dark

    rep_number = ds.get("RepresentativeFrameNumber")
    r_wave_pointer = _as_ints(ds.get("RWavePointer"))
    frame_time = _as_float(ds.get("FrameTime"))
    if frame_time is None and "FrameTimeVector" in ds:
        ftv = _as_floats(ds.get("FrameTimeVector"))
        if ftv and len(ftv) > 1:
            frame_time = float(np.mean(ftv[1:]))
    info: dict[str, Any] = {
        "format": "dicom",
        "sop_class": sop_class,
        "sop_class_name": sop_name,
        "modality": modality,
        "rows": rows,
        "cols": cols,
        "n_frames": n_frames,
        "frame_time_ms": frame_time,
        "bits_allocated": int(ds.get("BitsAllocated", 0) or 0),
        "bits_stored": bits_stored,
        "pixel_representation": int(signed),
        "photometric": photometric,
        "inverted_on_load": photometric == "MONOCHROME1",
        "transfer_syntax": ts,
        "transfer_syntax_name": UID(ts).name if ts else "",
        # raw PixelIntensityRelationship (0028,1040) (LIN, LOG, DISP, or vendor
        # values such as DRM), None when absent; and whether the pixels are lossy
        "pixel_intensity_relationship": (
            str(ds.get("PixelIntensityRelationship")).strip() or None
            if ds.get("PixelIntensityRelationship") is not None else None
        ),
        "lossy": is_lossy(ts, ds.get("LossyImageCompression")),
        "representative_frame_number": _representative_frame(rep_number, path),
        "r_wave_pointer": r_wave_pointer,
        "r_wave_frames": [k - 1 for k in r_wave_pointer if 1 <= k <= n_frames],
        "manufacturer": str(ds.get("Manufacturer", "") or ""),
        "series_description": str(ds.get("SeriesDescription", "") or ""),
    }
    invalid: dict[str, str] = {}
    header = {
        "alpha_deg": _header_number(ds, "PositionerPrimaryAngle", "alpha_deg", invalid),
        "beta_deg": _header_number(ds, "PositionerSecondaryAngle", "beta_deg", invalid),
        "sid_mm": _header_number(ds, "DistanceSourceToDetector", "sid_mm", invalid,
                                 positive=True),
        "sod_mm": _header_number(ds, "DistanceSourceToPatient", "sod_mm", invalid,
                                 positive=True),
        "pixel_spacing_mm": _header_numbers(ds, "ImagerPixelSpacing", "pixel_spacing_mm",
                                            invalid),
        "patient_pixel_spacing_mm": _header_numbers(ds, "PixelSpacing",
                                                    "patient_pixel_spacing_mm", invalid),
        "fov_mm": _header_numbers(ds, "FieldOfViewDimensions", "fov_mm", invalid),
        "magnification": _header_number(ds, "EstimatedRadiographicMagnificationFactor",
                                        "magnification", invalid, positive=True),
        "kind": "dicom",
        # key -> a safe rendering of a value that is present but not usable
        # (text, NaN, zero or negative, too many values)
        "invalid": invalid,
    }
    patient = {
        "name": str(ds.get("PatientName", "") or ""),
        "id": str(ds.get("PatientID", "") or ""),
    }
    return RawFile(frames=frames, header=header, info=info, patient=patient)
