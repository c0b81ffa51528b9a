"""The accepted physical ranges of every geometry value and image, checked at the edge.

Every geometry value, whether it comes from a DICOM header, a geometry JSON
or a command-line flag, passes through :func:`check_geometry_value`; the
resolved pair SID/SOD through :func:`check_sod_below_sid`; every loaded image
through :func:`check_image`. A value outside its range is a user's mistake:
a one-line :class:`~recon.errors.LoadError` naming the file, the tag or flag,
the value and the range.

The ranges are this project's chosen plausible values for a clinical C-arm
(not a standard): SID 700-1300 mm covers the source-to-image distances of
cardiac C-arms (the bundled real files have 860-976 mm, the paper's Table 1
1028-1200 mm); SOD at least 400 mm and below the SID (the isocenter lies
between source and detector); a detector pixel of 0.05-1 mm (flat panels and
image intensifiers have 0.1-0.4 mm); the primary angle within +-180 deg and
the secondary within +-90 deg; an image of at least 64 x 64 pixels.
"""

from __future__ import annotations

import math
import re
from typing import Any

import numpy as np
from numpy.typing import NDArray

from recon.errors import LoadError

__all__ = [
    "GEOMETRY_RANGES",
    "MIN_IMAGE_PX",
    "check_geometry_value",
    "check_image",
    "check_sod_below_sid",
    "safe_text",
]

# key -> (low, high, unit); low and high are inclusive.
GEOMETRY_RANGES: dict[str, tuple[float, float, str]] = {
    "alpha_deg": (-180.0, 180.0, "deg"),
    "beta_deg": (-90.0, 90.0, "deg"),
    "sid_mm": (700.0, 1300.0, "mm"),
    "sod_mm": (400.0, 1300.0, "mm"),
    "pixel_spacing_mm": (0.05, 1.0, "mm"),
}
MIN_IMAGE_PX = 64

_UNSAFE = re.compile(r"[^0-9A-Za-z.,:;+\-_/\\ ()\[\]'=]")


def safe_text(value: object, limit: int = 40) -> str:
    """A short printable rendering of a value for a message: no control
    characters, nothing beyond ``limit`` characters (raw header bytes are not echoed)."""
    if isinstance(value, float):
        return f"{value:g}"
    text = _UNSAFE.sub("?", str(value))
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _as_number(value: Any) -> float | None:
    """A plain finite or non-finite float, or None for text, booleans and the like."""
    if isinstance(value, bool):
        return None
    if isinstance(value, (int, float, np.integer, np.floating)):
        try:
            return float(value)
        except OverflowError:
            return math.inf
    return None


def check_geometry_value(key: str, value: Any, where: str) -> float | tuple[float, float]:
    """``value`` of geometry key ``key`` as float (or (row, col) for the spacing),
    when it is a finite number inside :data:`GEOMETRY_RANGES`.

    ``where`` names the source in the message: "file.dcm: DistanceSourceToDetector
    (0018,1110)", "--sid-mm", "view.json: sid_mm". Raises LoadError otherwise.
    """
    low, high, unit = GEOMETRY_RANGES[key]
    items = list(value) if isinstance(value, (tuple, list)) else [value]
    if key == "pixel_spacing_mm" and len(items) == 1:
        items = items * 2
    if key == "pixel_spacing_mm" and len(items) != 2:
        raise LoadError(f"{where}: expected one number or [row, col], got {safe_text(value)}")
    if key != "pixel_spacing_mm" and len(items) != 1:
        raise LoadError(f"{where}: expected one number, got {safe_text(value)}")
    numbers = []
    for item in items:
        number = _as_number(item)
        if number is None:
            raise LoadError(f"{where}: expected a number, got {safe_text(repr(item))}")
        if not math.isfinite(number):
            raise LoadError(f"{where}: must be a finite number, got {number}")
        if not low <= number <= high:
            raise LoadError(
                f"{where} = {number:g} {unit} is outside the accepted range "
                f"{low:g} to {high:g} {unit}"
            )
        numbers.append(number)
    if key == "pixel_spacing_mm":
        return (numbers[0], numbers[1])
    return numbers[0]


def check_sod_below_sid(sod_mm: float, sod_from: str, sid_mm: float, sid_from: str,
                        path: str) -> None:
    """LoadError unless the isocenter lies between source and detector (SOD < SID)."""
    if not sod_mm < sid_mm:
        raise LoadError(
            f"{path}: invalid geometry: SOD {sod_mm:g} mm ({sod_from}) must be below "
            f"SID {sid_mm:g} mm ({sid_from})"
        )


def check_image(frames: NDArray[Any], path: str) -> None:
    """LoadError unless the frames (F, H, W) are at least
    :data:`MIN_IMAGE_PX` square and hold finite values only."""
    rows, cols = frames.shape[-2:]
    if rows < MIN_IMAGE_PX or cols < MIN_IMAGE_PX:
        raise LoadError(
            f"{path}: the image is {rows} x {cols} px; at least {MIN_IMAGE_PX} x "
            f"{MIN_IMAGE_PX} is needed"
        )
    if np.issubdtype(frames.dtype, np.floating) and not np.isfinite(frames).all():
        bad = int(np.count_nonzero(~np.isfinite(frames)))
        raise LoadError(f"{path}: the pixel data holds {bad} NaN or infinite value(s)")
