"""Read an angiogram stored as an image file (PNG, TIFF, ...) and its geometry JSON.

Pixels are read with Pillow (OpenCV as a fallback), every page of a TIFF as
one frame, RGB converted to grey by luminance and taken as MONOCHROME2
(vessels dark). The geometry comes from the JSON given, or else from a
sidecar JSON with the image's name and ".json" (see :mod:`recon.io.overrides`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from recon.errors import LoadError
from recon.io.overrides import (
    GEOMETRY_KEYS,
    GeometryOverrides,
    overrides_from_dict,
    read_geometry_json,
)
from recon.io.raw import RawFile, first_line

__all__ = ["IMAGE_SUFFIXES", "is_image_file", "read_image_file"]

IMAGE_SUFFIXES = {".png", ".tif", ".tiff", ".jpg", ".jpeg", ".bmp", ".pgm", ".webp"}


def is_image_file(path: Path) -> bool:
    """True when the suffix is one of :data:`IMAGE_SUFFIXES` (read as an image, not DICOM)."""
    return path.suffix.lower() in IMAGE_SUFFIXES


def read_image_file(path: str, geometry_json: str | None) -> RawFile:
    """Frames of an image file, its geometry JSON (``geometry_json`` or the sidecar) as defaults."""
    stack, mode = _read_image_pixels(path)
    n_frames, rows, cols = stack.shape
    p = Path(path)
    json_path = Path(geometry_json) if geometry_json is not None else p.with_suffix(".json")
    defaults: GeometryOverrides | None = None
    json_name = None
    if geometry_json is not None or json_path.exists():
        data = read_geometry_json(json_path)
        for key, size in (("rows", rows), ("cols", cols)):
            if key in data and data[key] != size:
                raise LoadError(
                    f"{json_path}: {key} is {data[key]!r} but {p.name} has {size} {key}"
                )
        defaults = overrides_from_dict(data, str(json_path))
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
    header: dict[str, Any] = {k: None for k in GEOMETRY_KEYS}
    header.update(patient_pixel_spacing_mm=None, fov_mm=None, magnification=None)
    header["kind"] = "image"
    header["json"] = json_name
    return RawFile(frames=stack, header=header, info=info, patient={}, default_overrides=defaults)


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
            raise LoadError(f"{path}: cannot read the image ({first_line(exc)})") from None
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
