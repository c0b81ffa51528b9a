"""The record both readers return: a file's frames and header facts before
the geometry is resolved (:mod:`recon.io.dicom_read`, :mod:`recon.io.image_files`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from recon.io.overrides import GeometryOverrides

__all__ = ["RawFile", "first_line"]


@dataclass
class RawFile:
    """What a file holds before geometry resolution."""

    frames: NDArray[np.float32]  # (F, H, W), MONOCHROME2 sense
    header: dict[str, Any]  # geometry-related header values (None when absent)
    info: dict[str, Any]
    patient: dict[str, str]
    default_overrides: GeometryOverrides | None = None  # sidecar JSON of an image file


def first_line(exc: BaseException) -> str:
    """"ExceptionType: first line of its message", for one-line LoadErrors."""
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0].rstrip(': ')}" if text else type(exc).__name__
