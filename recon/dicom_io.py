"""Read and write X-ray angiograms: XA DICOM, or PNG/TIFF plus a geometry JSON.

The only module of the project that imports pydicom. Loading returns an
:class:`Angiogram`: one frame (H, W) float32 in the MONOCHROME2 sense
(contrast-filled vessels dark; MONOCHROME1 is inverted on load; raw stored
values, no rescale and no windowing), its :class:`~recon.geometry.ViewGeometry`
read from the positioner tags of the project's C-arm convention, and why that
frame was chosen.

Frame indices in this module's Python API are 0-based everywhere (the
``frame`` argument, ``Angiogram.frame_index``, ``representative_frame`` and
``r_wave_frames`` of :func:`write_xa_dicom`, ``info["r_wave_frames"]``).
DICOM frame numbers are 1-based: the Frame Pointers module says of
RepresentativeFrameNumber (0028,6010) "frame numbers begin at 1", and the XA
Image module's R Wave Pointer (0028,6040) marks the R waves "by referencing
frame numbers", numbered the same way. Both are converted at this edge
(index = number - 1); the raw values stay in
``info["representative_frame_number"]`` and ``info["r_wave_pointer"]``.
(Cross-check on tests/data/rca-cine-ecg.dcm: the R peaks of its group-5000
ECG curve, 40 samples per frame, fall at 0-based frames 20.8, 52.4 and 77.1
against R Wave Pointer 20, 53, 77: consistent with either base to within one
frame, so the standard's 1-based reading decides.)

Frame choice, first rule that applies:

1. the ``frame`` argument (0-based, validated);
2. RepresentativeFrameNumber, when in range;
3. end-diastole: the R-wave frames are end-diastolic (the R wave closes
   diastole, the coronaries are longest and slowest there); among them the one
   with the strongest vessel contrast (:func:`vessel_contrast_scores`), because
   an injection run opacifies the arteries for a few beats only and an
   end-diastolic frame without contrast is useless; ties go to the frame
   nearest the middle of the run;
4. the frame of strongest vessel contrast.

Geometry follows the project's C-arm convention (``recon/geometry.py``): alpha =
PositionerPrimaryAngle (0018,1510), beta = PositionerSecondaryAngle
(0018,1511), SID = DistanceSourceToDetector (0018,1110), SOD =
DistanceSourceToPatient (0018,1111), pixel spacing (row, col) =
ImagerPixelSpacing (0018,1164). A user override always wins over the header.
Fallbacks, each recorded in ``Angiogram.geometry_notes``:

- SOD = SID / EstimatedRadiographicMagnificationFactor (0018,1114);
- detector spacing = PixelSpacing (0028,0030) x SID / SOD (PixelSpacing of a
  projection image is defined in the patient, at the isocenter);
- detector spacing = FieldOfViewDimensions (0018,1149) / (Rows, Columns).
"""

from __future__ import annotations

import io
import math
import os
import tempfile
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from datetime import datetime
from pathlib import Path
from typing import Any

import numpy as np
import pydicom
from numpy.typing import ArrayLike, NDArray
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.encaps import encapsulate
from pydicom.uid import UID, ExplicitVRLittleEndian, generate_uid
from scipy import ndimage

from recon.errors import CoronaryError
from recon.fileio import read_json
from recon.geometry import ViewGeometry

__all__ = [
    "XA_SOP_CLASS_UID",
    "LoadError",
    "GeometryOverrides",
    "Angiogram",
    "load_angiogram",
    "describe_file",
    "format_description",
    "vessel_contrast_scores",
    "write_xa_dicom",
]

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

_IMAGE_SUFFIXES = {".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".pgm", ".webp"}

# The five geometry values: key, DICOM keyword, tag, command-line flag.
_GEOMETRY_FIELDS = (
    ("alpha_deg", "PositionerPrimaryAngle", "(0018,1510)", "--alpha-deg"),
    ("beta_deg", "PositionerSecondaryAngle", "(0018,1511)", "--beta-deg"),
    ("sid_mm", "DistanceSourceToDetector", "(0018,1110)", "--sid-mm"),
    ("sod_mm", "DistanceSourceToPatient", "(0018,1111)", "--sod-mm"),
    ("pixel_spacing_mm", "ImagerPixelSpacing", "(0018,1164)", "--pixel-spacing-mm"),
)
_GEOMETRY_KEYS = tuple(f[0] for f in _GEOMETRY_FIELDS)
# Keys of ViewGeometry.to_dict() that a geometry JSON may carry and that are
# checked (rows, cols) or ignored (the rest) rather than rejected as typos.
_TOLERATED_JSON_KEYS = ("rows", "cols", "principal_offset_px", "rotvec_corr", "t_corr_mm")


class LoadError(CoronaryError):
    """An input image or geometry that cannot be used; one line "<file>: <what is wrong>"."""


# ------------------------------------------------------------------ overrides
@dataclass(frozen=True)
class GeometryOverrides:
    """User-supplied geometry values; each one, when not None, replaces the header's.

    Attributes
    ----------
    alpha_deg, beta_deg : positioner angles in degrees (LAO +, CRA +).
    sid_mm, sod_mm : source-to-detector and source-to-isocenter distances in mm.
    pixel_spacing_mm : detector pixel size (row, col) in mm.
    source : where the values came from, for the notes ("override" or the
        JSON file name).
    """

    alpha_deg: float | None = None
    beta_deg: float | None = None
    sid_mm: float | None = None
    sod_mm: float | None = None
    pixel_spacing_mm: tuple[float, float] | None = None
    source: str = "override"

    def __post_init__(self) -> None:
        for key in ("alpha_deg", "beta_deg", "sid_mm", "sod_mm"):
            value = getattr(self, key)
            if value is not None:
                value = float(value)
                if not math.isfinite(value):
                    raise LoadError(f"{self.source}: {key} must be a finite number, got {value}")
                if key in ("sid_mm", "sod_mm") and value <= 0:
                    raise LoadError(f"{self.source}: {key} must be positive, got {value}")
                object.__setattr__(self, key, value)
        if self.pixel_spacing_mm is not None:
            spacing = _spacing_pair(self.pixel_spacing_mm)
            if spacing is None:
                raise LoadError(
                    f"{self.source}: pixel_spacing_mm must be one positive number or "
                    f"[row, col], got {self.pixel_spacing_mm!r}"
                )
            object.__setattr__(self, "pixel_spacing_mm", spacing)

    def values(self) -> dict[str, Any]:
        """The supplied (not None) values by key."""
        return {k: getattr(self, k) for k in _GEOMETRY_KEYS if getattr(self, k) is not None}

    def merged_over(self, other: GeometryOverrides | None) -> GeometryOverrides:
        """These overrides with ``other`` filling the values they leave None."""
        if other is None:
            return self
        kwargs: dict[str, Any] = {}
        for key in _GEOMETRY_KEYS:
            mine = getattr(self, key)
            kwargs[key] = mine if mine is not None else getattr(other, key)
        mine_set, other_set = self.values(), other.values()
        if mine_set and other_set:
            source = f"{self.source} / {other.source}"
        else:
            source = self.source if mine_set else other.source
        return GeometryOverrides(**kwargs, source=source)

    @classmethod
    def from_json(cls, path: str | os.PathLike) -> GeometryOverrides:
        """Read ``{"alpha_deg", "beta_deg", "sid_mm", "sod_mm", "pixel_spacing_mm"}``.

        Any subset of the keys may be given; ``pixel_spacing_mm`` is [row, col]
        or one number. Keys of ``ViewGeometry.to_dict()`` (rows, cols, ...) are
        tolerated; other keys are rejected as likely typos.
        """
        data = _read_json(path)
        return _overrides_from_dict(data, str(path))


def _read_json(path: str | os.PathLike) -> dict:
    data = read_json(path, LoadError, "geometry JSON")
    if not isinstance(data, dict):
        raise LoadError(
            f"{Path(path)}: the geometry JSON must be an object with keys {_GEOMETRY_KEYS}"
        )
    return data


def _overrides_from_dict(data: dict, source: str) -> GeometryOverrides:
    unknown = sorted(set(data) - set(_GEOMETRY_KEYS) - set(_TOLERATED_JSON_KEYS))
    if unknown:
        raise LoadError(
            f"{source}: unknown key {unknown[0]!r} (expected {', '.join(_GEOMETRY_KEYS)})"
        )
    kwargs: dict[str, Any] = {}
    for key in _GEOMETRY_KEYS:
        value = data.get(key)
        if value is None:
            continue
        if key == "pixel_spacing_mm":
            kwargs[key] = value
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise LoadError(f"{source}: {key} must be a number, got {value!r}")
        kwargs[key] = float(value)
    return GeometryOverrides(**kwargs, source=Path(source).name)


def _spacing_pair(value: object) -> tuple[float, float] | None:
    """(row, col) spacing from one number or a pair; None when invalid."""
    try:
        arr = np.asarray(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None
    if arr.size == 1:
        arr = np.repeat(arr, 2)
    if arr.size != 2 or not np.all(np.isfinite(arr)) or not np.all(arr > 0):
        return None
    return (float(arr[0]), float(arr[1]))


# ------------------------------------------------------------------ angiogram
@dataclass(frozen=True, eq=False)
class Angiogram:
    """One loaded angiogram: the chosen frame, its geometry and provenance.

    Attributes
    ----------
    image : (H, W) float32, the chosen frame, MONOCHROME2 sense (vessels
        dark), raw stored values.
    geometry : the view's nominal :class:`ViewGeometry` (rows, cols = H, W).
    path : the file it came from.
    frame_index : 0-based index of ``image`` in the run.
    frame_reason : why this frame ("explicit", "RepresentativeFrameNumber 5",
        "end-diastolic: R wave at frame 20 ...", "strongest vessel contrast",
        "single frame").
    n_frames : number of frames in the file.
    frame_time_ms : FrameTime, or None.
    frames : (F, H, W) float32 of the whole run, or None for a single frame.
    geometry_notes : how geometry values that are not plain header tags were
        obtained (overrides, fallbacks).
    info : header facts (sop_class, sop_class_name, modality, rows, cols,
        bits_stored, photometric, transfer_syntax, r_wave_pointer (1-based,
        raw), r_wave_frames (0-based), representative_frame_number, ...).
    """

    image: NDArray[np.float32]
    geometry: ViewGeometry
    path: str
    frame_index: int
    frame_reason: str
    n_frames: int
    frame_time_ms: float | None = None
    frames: NDArray[np.float32] | None = None
    geometry_notes: tuple[str, ...] = ()
    info: dict = field(default_factory=dict)

    @property
    def shape(self) -> tuple[int, int]:
        """(H, W) of the image."""
        return (int(self.image.shape[0]), int(self.image.shape[1]))

    def with_frame(self, index: int) -> Angiogram:
        """The same run with frame ``index`` (0-based) as the image; reason "explicit"."""
        index = _check_frame_index(index, self.n_frames, self.path)
        image = self.image if self.frames is None else self.frames[index]
        return replace(self, image=image, frame_index=index, frame_reason="explicit")


def _check_frame_index(index: object, n_frames: int, path: str) -> int:
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)):
        raise LoadError(f"{path}: frame must be an integer index, got {index!r}")
    if not 0 <= int(index) < n_frames:
        raise LoadError(
            f"{path}: frame {int(index)} is out of range; the file has {n_frames} "
            f"frame{'s' if n_frames != 1 else ''} (0-based: 0..{n_frames - 1})"
        )
    return int(index)


# --------------------------------------------------------------- raw reading
@dataclass
class _Raw:
    """What a file holds before geometry resolution."""

    frames: NDArray[np.float32]  # (F, H, W), MONOCHROME2 sense
    header: dict[str, Any]  # geometry-related header values (None when absent)
    info: dict[str, Any]
    patient: dict[str, str]
    default_overrides: GeometryOverrides | None = None  # sidecar JSON of an image file


def _is_image_file(path: Path) -> bool:
    return path.suffix.lower() in _IMAGE_SUFFIXES


def _read_any(path: str, geometry_json: str | None) -> _Raw:
    p = Path(path)
    if not p.exists():
        raise LoadError(f"{path}: no such file")
    if p.is_dir():
        raise LoadError(f"{path}: is a folder, not an image file")
    if _is_image_file(p):
        return _read_image_file(path, geometry_json)
    return _read_dicom(path)


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


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0].rstrip(': ')}" if text else type(exc).__name__


def _read_dicom(path: str) -> _Raw:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            ds = pydicom.dcmread(path)
        except pydicom.errors.InvalidDicomError:
            raise LoadError(
                f"{path}: not a DICOM file (no DICM preamble) and not an image file "
                f"({', '.join(sorted(_IMAGE_SUFFIXES))})"
            ) from None
        except Exception as exc:  # truncated or corrupt header
            raise LoadError(
                f"{path}: unreadable DICOM file, truncated or corrupt ({_first_line(exc)})"
            ) from None

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
                f"{path}: cannot decode the pixel data ({ts_name}): {_first_line(exc)}"
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
    bits_stored = int(ds.get("BitsStored", 8 * arr.dtype.itemsize) or 8)
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
        "representative_frame_number": int(rep_number) if rep_number is not None else None,
        "r_wave_pointer": r_wave_pointer,
        "r_wave_frames": [k - 1 for k in r_wave_pointer if 1 <= k <= n_frames],
        "manufacturer": str(ds.get("Manufacturer", "") or ""),
        "series_description": str(ds.get("SeriesDescription", "") or ""),
    }
    header = {
        "alpha_deg": _as_float(_dicom_value(ds, "PositionerPrimaryAngle")),
        "beta_deg": _as_float(_dicom_value(ds, "PositionerSecondaryAngle")),
        "sid_mm": _as_float(_dicom_value(ds, "DistanceSourceToDetector")),
        "sod_mm": _as_float(_dicom_value(ds, "DistanceSourceToPatient")),
        "pixel_spacing_mm": _as_floats(_dicom_value(ds, "ImagerPixelSpacing")),
        "patient_pixel_spacing_mm": _as_floats(_dicom_value(ds, "PixelSpacing")),
        "fov_mm": _as_floats(_dicom_value(ds, "FieldOfViewDimensions")),
        "magnification": _as_float(_dicom_value(ds, "EstimatedRadiographicMagnificationFactor")),
        "kind": "dicom",
    }
    patient = {
        "name": str(ds.get("PatientName", "") or ""),
        "id": str(ds.get("PatientID", "") or ""),
    }
    return _Raw(frames=frames, header=header, info=info, patient=patient)


def _read_image_file(path: str, geometry_json: str | None) -> _Raw:
    stack, mode = _read_image_pixels(path)
    n_frames, rows, cols = stack.shape
    p = Path(path)
    json_path = Path(geometry_json) if geometry_json is not None else p.with_suffix(".json")
    defaults: GeometryOverrides | None = None
    json_name = None
    if geometry_json is not None or json_path.exists():
        data = _read_json(json_path)
        for key, size in (("rows", rows), ("cols", cols)):
            if key in data and data[key] != size:
                raise LoadError(
                    f"{json_path}: {key} is {data[key]!r} but {p.name} has {size} {key}"
                )
        defaults = _overrides_from_dict(data, str(json_path))
        json_name = json_path.name
    info: dict[str, Any] = {
        "format": "image",
        "path": str(path),
        "sop_class": "",
        "sop_class_name": f"{p.suffix.lstrip('.').upper()} image",
        "modality": "",
        "rows": rows,
        "cols": cols,
        "n_frames": n_frames,
        "frame_time_ms": None,
        "bits_stored": 16 if mode.startswith("I;16") else (8 if len(mode) <= 4 else None),
        "photometric": "MONOCHROME2 (assumed)",
        "image_mode": mode,
        "transfer_syntax": "",
        "representative_frame_number": None,
        "r_wave_pointer": [],
        "r_wave_frames": [],
        "geometry_json": str(json_path) if json_name else None,
    }
    header: dict[str, Any] = {k: None for k in _GEOMETRY_KEYS}
    header.update(patient_pixel_spacing_mm=None, fov_mm=None, magnification=None)
    header["kind"] = "image"
    header["json"] = json_name
    return _Raw(frames=stack, header=header, info=info, patient={}, default_overrides=defaults)


def _read_image_pixels(path: str) -> tuple[NDArray[np.float32], str]:
    """Pixels (F, H, W) float32 of an image file (all pages of a TIFF), and its mode."""
    from PIL import Image, ImageSequence, UnidentifiedImageError

    weights = np.array([0.299, 0.587, 0.114], np.float32)

    def _gray(img: Image.Image) -> NDArray[np.float32]:
        if img.mode in ("L", "I", "F") or img.mode.startswith("I;"):
            return np.asarray(img).astype(np.float32)
        return np.asarray(img.convert("RGB")).astype(np.float32) @ weights

    try:
        with Image.open(path) as img:
            mode = img.mode
            pages = [_gray(page) for page in ImageSequence.Iterator(img)]
    except (UnidentifiedImageError, OSError, ValueError) as exc:
        import cv2

        arr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if arr is None:
            raise LoadError(f"{path}: cannot read the image ({_first_line(exc)})") from None
        mode = f"opencv {arr.dtype}"
        if arr.ndim == 3:  # BGR(A)
            arr = arr[..., 2::-1][..., :3].astype(np.float32) @ weights
        pages = [arr.astype(np.float32)]
    shapes = {pg.shape for pg in pages}
    if len(shapes) != 1:
        pages = pages[:1]
    stack = np.stack(pages)
    if stack.ndim != 3 or stack.shape[1] < 2 or stack.shape[2] < 2:
        raise LoadError(f"{path}: not a 2-D image (shape {stack.shape})")
    return stack, mode


# ---------------------------------------------------------------- geometry
def _resolve_geometry(
    raw: _Raw, overrides: GeometryOverrides | None
) -> tuple[dict[str, Any], list[str], list[str]]:
    """Geometry values, notes and problems (missing values) of a file.

    Returns ``values`` (key -> float / (row, col) / None), ``notes`` (how
    non-header values were obtained) and ``problems`` (one phrase per missing
    value, naming the tag and how to supply it).
    """
    h = raw.header
    rows, cols = raw.frames.shape[1:]
    if raw.default_overrides is not None:
        ov = (overrides or GeometryOverrides()).merged_over(raw.default_overrides)
    else:
        ov = overrides or GeometryOverrides()
    ov_values = ov.values()
    values: dict[str, Any] = {}
    notes: list[str] = []

    def from_override(key: str, header_value: Any, label: str) -> bool:
        if key not in ov_values:
            return False
        src = _override_source(key, overrides, raw.default_overrides)
        value = ov_values[key]
        values[key] = value
        if h["kind"] == "image":
            return True  # the JSON is the image's header: nothing to note
        shown = _fmt_value(value)
        if header_value is not None:
            notes.append(f"{label} {shown} from {src} (header says {_fmt_value(header_value)})")
        else:
            notes.append(f"{label} {shown} from {src}")
        return True

    for key, label in (("alpha_deg", "primary angle"), ("beta_deg", "secondary angle")):
        if not from_override(key, h[key], label):
            values[key] = h[key]
    if not from_override("sid_mm", h["sid_mm"], "SID"):
        values["sid_mm"] = h["sid_mm"] if (h["sid_mm"] or 0) > 0 else None
    if not from_override("sod_mm", h["sod_mm"], "SOD"):
        sod = h["sod_mm"] if (h["sod_mm"] or 0) > 0 else None
        mag = h["magnification"]
        if sod is None and values["sid_mm"] is not None and mag is not None and mag > 1:
            sod = values["sid_mm"] / mag
            notes.append(
                f"SOD {sod:.1f} mm = SID / EstimatedRadiographicMagnificationFactor "
                f"{mag:g} (DistanceSourceToPatient missing)"
            )
        values["sod_mm"] = sod
    if not from_override("pixel_spacing_mm", h["pixel_spacing_mm"], "pixel spacing"):
        spacing = _spacing_pair(h["pixel_spacing_mm"]) if h["pixel_spacing_mm"] else None
        if spacing is None and h["patient_pixel_spacing_mm"]:
            iso = _spacing_pair(h["patient_pixel_spacing_mm"])
            sid, sod = values["sid_mm"], values["sod_mm"]
            if iso is not None and sid is not None and sod is not None:
                mag = sid / sod
                spacing = (iso[0] * mag, iso[1] * mag)
                notes.append(
                    f"pixel spacing {_fmt_value(spacing)} mm = PixelSpacing "
                    f"{_fmt_value(iso)} mm x SID/SOD {mag:.4g} (ImagerPixelSpacing missing; "
                    f"PixelSpacing taken as calibrated at the isocenter)"
                )
        if spacing is None and h["fov_mm"]:
            fov = h["fov_mm"]
            if all(v > 0 for v in fov):
                spacing = (fov[0] / rows, fov[-1] / cols)
                notes.append(
                    f"pixel spacing {_fmt_value(spacing)} mm from FieldOfViewDimensions "
                    f"{_fmt_value(fov)} mm / {rows}x{cols} px (ImagerPixelSpacing missing)"
                )
        values["pixel_spacing_mm"] = spacing

    problems = []
    for key, keyword, tag, flag in _GEOMETRY_FIELDS:
        if values[key] is None:
            if h["kind"] == "image":
                json_name = h.get("json")
                if json_name:
                    problems.append(f"{key} is missing from {json_name}; add it or give {flag}")
                else:
                    problems.append(
                        f"{key} is missing: no geometry JSON (looked for "
                        f"{Path(raw.info['path']).with_suffix('.json').name}); give one or {flag}"
                    )
            else:
                problems.append(f"{keyword} {tag} is missing; give {flag} or a geometry JSON")
    return values, notes, problems


def _override_source(
    key: str, overrides: GeometryOverrides | None, defaults: GeometryOverrides | None
) -> str:
    if overrides is not None and getattr(overrides, key) is not None:
        return overrides.source
    if defaults is not None:
        return defaults.source
    return "override"


def _fmt_value(value: Any) -> str:
    if isinstance(value, (tuple, list)):
        return "/".join(f"{float(v):g}" for v in value)
    return f"{float(value):g}"


def _geometry(raw: _Raw, values: dict[str, Any], problems: list[str], path: str) -> ViewGeometry:
    if problems:
        extra = ""
        if len(problems) > 1:
            others = [p.split(" is missing")[0] for p in problems[1:]]
            extra = f" (also missing: {', '.join(others)})"
        raise LoadError(f"{path}: {problems[0]}{extra}")
    rows, cols = raw.frames.shape[1:]
    try:
        return ViewGeometry(
            alpha_deg=float(values["alpha_deg"]),
            beta_deg=float(values["beta_deg"]),
            sid_mm=float(values["sid_mm"]),
            sod_mm=float(values["sod_mm"]),
            pixel_spacing_mm=tuple(values["pixel_spacing_mm"]),
            rows=int(rows),
            cols=int(cols),
        )
    except ValueError as exc:
        raise LoadError(f"{path}: invalid geometry: {exc}") from None


# ------------------------------------------------------------ frame choice
def vessel_contrast_scores(frames: ArrayLike) -> NDArray[np.float64]:
    """Cheap vessel-contrast score (F,) of each frame of a run (F, H, W).

    Each frame is block-averaged to about 128 px, its black top-hat (grey
    closing with a 9 px square minus the frame) keeps dark structures thinner
    than about 9 / 128 of the field, and the score is the 99th percentile of
    the top-hat inside the exposed field (the dark collimator border is
    masked out), divided by the frame's median brightness there so that
    exposure changes do not count as contrast. Higher = darker, better filled
    vessels.
    """
    stack = np.asarray(frames, dtype=np.float32)
    if stack.ndim == 2:
        stack = stack[None]
    if stack.ndim != 3:
        raise ValueError(f"frames must have shape (F, H, W), got {stack.shape}")
    n, h, w = stack.shape
    s = max(1, min(h, w) // 128)
    hs, ws = h // s, w // s
    small = stack[:, : hs * s, : ws * s].reshape(n, hs, s, ws, s).mean(axis=(2, 4))
    k = 9
    closed = ndimage.grey_closing(small, size=(1, k, k))
    tophat = closed - small
    bright = np.percentile(small.reshape(n, -1), 99, axis=1)[:, None, None]
    exposed = small > 0.1 * bright
    exposed = ndimage.binary_erosion(exposed, structure=np.ones((1, k, k), bool))
    masked = np.where(exposed, tophat, np.nan)
    level = np.where(exposed, small, np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-masked frames give NaN
        score = np.nanpercentile(masked.reshape(n, -1), 99, axis=1)
        median = np.nanmedian(level.reshape(n, -1), axis=1)
    out = score / np.maximum(median, 1e-6)
    return np.nan_to_num(out, nan=0.0).astype(np.float64)


def _choose_frame(raw: _Raw, frame: int | None, path: str) -> tuple[int, str]:
    n = raw.frames.shape[0]
    if frame is not None:
        return _check_frame_index(frame, n, path), "explicit"
    if n == 1:
        return 0, "single frame"
    ignored = []
    rep = raw.info.get("representative_frame_number")
    if rep is not None:
        if 1 <= rep <= n:
            return rep - 1, f"RepresentativeFrameNumber {rep}"
        ignored.append(f"RepresentativeFrameNumber {rep} out of range ignored")
    r_frames = raw.info.get("r_wave_frames") or []
    if r_frames:
        candidates = np.asarray(sorted(set(r_frames)))
        scores = vessel_contrast_scores(raw.frames[candidates])
        middle = (n - 1) / 2.0
        # best contrast; ties (within 1 %) broken by distance to the middle of the run
        best = scores.max()
        tied = candidates[scores >= best * 0.99 - 1e-12]
        index = int(tied[np.argmin(np.abs(tied - middle))])
        pointer = ", ".join(str(k) for k in raw.info.get("r_wave_pointer", []))
        reason = (
            f"end-diastolic: R wave at frame {index} (0-based; R Wave Pointer {pointer}, "
            f"1-based), the R-wave frame with the strongest vessel contrast"
        )
        return index, reason
    scores = vessel_contrast_scores(raw.frames)
    index = int(np.argmax(scores))
    reason = "strongest vessel contrast"
    if ignored:
        reason += f" ({'; '.join(ignored)})"
    return index, reason


# ------------------------------------------------------------------ loading
def load_angiogram(
    path: str | os.PathLike,
    *,
    frame: int | None = None,
    overrides: GeometryOverrides | None = None,
    geometry_json: str | os.PathLike | None = None,
) -> Angiogram:
    """Load one angiogram (XA DICOM, or an image file with a geometry JSON).

    Parameters
    ----------
    path : an XA DICOM file (single or multi-frame, 8-16 bit, uncompressed or
        JPEG Lossless / JPEG Baseline / what pylibjpeg decodes), or an image
        file Pillow or OpenCV reads (PNG, TIFF, ...; RGB is converted to grey
        by luminance) whose geometry comes from ``geometry_json`` or, when
        that is None, from a sidecar JSON with the same name and ".json".
    frame : 0-based frame index; None chooses one (see the module docstring).
    overrides : geometry values that replace the header's (or fill its gaps).
    geometry_json : a JSON with alpha_deg, beta_deg, sid_mm, sod_mm,
        pixel_spacing_mm [row, col]; for DICOM it acts as overrides (explicit
        ``overrides`` win over it).

    Returns
    -------
    Angiogram with image (H, W) float32 in the MONOCHROME2 sense.

    Raises
    ------
    LoadError : one line "<file>: <what is wrong>" for unreadable, non-XA, or
        undecodable files, a frame out of range, or missing geometry.
    """
    path_str = os.fspath(path)
    raw, index, reason, values, notes, problems = _read_and_resolve(
        path_str, frame, overrides, geometry_json
    )
    geometry = _geometry(raw, values, problems, path_str)
    n = raw.frames.shape[0]
    return Angiogram(
        image=raw.frames[index],
        geometry=geometry,
        path=path_str,
        frame_index=index,
        frame_reason=reason,
        n_frames=n,
        frame_time_ms=raw.info.get("frame_time_ms"),
        frames=raw.frames if n > 1 else None,
        geometry_notes=tuple(notes),
        info=dict(raw.info),
    )


def _read_and_resolve(
    path_str: str,
    frame: int | None,
    overrides: GeometryOverrides | None,
    geometry_json: str | os.PathLike | None,
) -> tuple:
    """Read a file, choose its frame and resolve its geometry (shared by load and describe).

    A geometry JSON given for a DICOM file acts as overrides, under the explicit ones.
    """
    json_str = os.fspath(geometry_json) if geometry_json is not None else None
    raw = _read_any(path_str, json_str)
    if json_str is not None and raw.info["format"] == "dicom":
        overrides = (overrides or GeometryOverrides()).merged_over(
            GeometryOverrides.from_json(json_str)
        )
    index, reason = _choose_frame(raw, frame, path_str)
    values, notes, problems = _resolve_geometry(raw, overrides)
    return raw, index, reason, values, notes, problems


def describe_file(
    path: str | os.PathLike,
    *,
    show_patient: bool = False,
    frame: int | None = None,
    overrides: GeometryOverrides | None = None,
    geometry_json: str | os.PathLike | None = None,
) -> dict:
    """What ``coronary3d info`` prints about a file, as a JSON-ready dict.

    Missing geometry is reported (value None, listed under "missing"), never
    raised; unreadable files and a frame out of range raise :class:`LoadError`.
    Patient name and ID are included only when ``show_patient``.
    """
    path_str = os.fspath(path)
    raw, index, reason, values, notes, problems = _read_and_resolve(
        path_str, frame, overrides, geometry_json
    )
    geometry = {k: (list(v) if isinstance(v, tuple) else v) for k, v in values.items()}
    info = raw.info
    desc: dict[str, Any] = {
        "path": path_str,
        "format": info["format"],
        "sop_class": info["sop_class"],
        "sop_class_name": info["sop_class_name"],
        "modality": info["modality"],
        "rows": info["rows"],
        "cols": info["cols"],
        "n_frames": info["n_frames"],
        "frame_time_ms": info["frame_time_ms"],
        "bits_stored": info["bits_stored"],
        "photometric": info["photometric"],
        "transfer_syntax": info.get("transfer_syntax_name") or info["transfer_syntax"],
        "geometry": geometry,
        "geometry_notes": notes,
        "missing": problems,
        "r_wave_pointer": info["r_wave_pointer"],
        "r_wave_frames": info["r_wave_frames"],
        "representative_frame_number": info["representative_frame_number"],
        "frame_index": index,
        "frame_reason": reason,
    }
    if show_patient:
        desc["patient_name"] = raw.patient.get("name", "")
        desc["patient_id"] = raw.patient.get("id", "")
    return desc


def format_description(desc: dict) -> str:
    """Human-readable multi-line text of a :func:`describe_file` dict."""
    g = desc["geometry"]

    def val(key: str, unit: str, fmt: str = "g") -> str:
        v = g.get(key)
        if v is None:
            return "missing"
        if isinstance(v, (list, tuple)):
            return " x ".join(f"{float(x):{fmt}}" for x in v) + f" {unit} (row x col)"
        return f"{float(v):{fmt}} {unit}"

    name = desc["sop_class_name"] or desc["sop_class"] or "?"
    if desc["modality"]:
        name += f" ({desc['modality']})"
    frames = f"{desc['n_frames']}"
    if desc["frame_time_ms"] is not None:
        frames += f", frame time {desc['frame_time_ms']:g} ms"
    lines = [
        f"{desc['path']}",
        f"  type            {name}",
        f"  size            {desc['rows']} x {desc['cols']} px (rows x cols)",
        f"  frames          {frames}",
    ]
    if desc["bits_stored"] is not None or desc["photometric"]:
        lines.append(
            f"  pixels          {desc['bits_stored'] or '?'} bit, {desc['photometric']}"
            + (f", {desc['transfer_syntax']}" if desc["transfer_syntax"] else "")
        )
    lines += [
        f"  primary angle   {val('alpha_deg', 'deg')}",
        f"  secondary angle {val('beta_deg', 'deg')}",
        f"  SID             {val('sid_mm', 'mm')}",
        f"  SOD             {val('sod_mm', 'mm')}",
        f"  pixel spacing   {val('pixel_spacing_mm', 'mm')}",
    ]
    for note in desc["geometry_notes"]:
        lines.append(f"  note            {note}")
    for problem in desc["missing"]:
        lines.append(f"  missing         {problem}")
    if desc["r_wave_pointer"]:
        lines.append(
            "  R waves         frames "
            + ", ".join(str(k) for k in desc["r_wave_frames"])
            + " (0-based; R Wave Pointer "
            + ", ".join(str(k) for k in desc["r_wave_pointer"])
            + ")"
        )
    lines.append(f"  chosen frame    {desc['frame_index']} (0-based): {desc['frame_reason']}")
    if "patient_name" in desc:
        lines.append(f"  patient         {desc['patient_name']} (ID {desc['patient_id']})")
    return "\n".join(lines)


# ------------------------------------------------------------------ writing
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
    )
    _save_dataset(ds, path)


def _save_dataset(ds: Dataset, path: str | os.PathLike) -> None:
    buffer = io.BytesIO()
    ds.save_as(buffer, enforce_file_format=True)
    _atomic_write(Path(path), buffer.getvalue())


def _atomic_write(path: Path, data: bytes) -> None:
    """Write through a temporary file in the same folder and an atomic rename (mode 644)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


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
