"""User-supplied geometry values (command line or JSON) that replace a header's.

A geometry JSON holds any of ``alpha_deg``, ``beta_deg``, ``sid_mm``,
``sod_mm`` and ``pixel_spacing_mm`` ([row, col] or one number). It is the
header of a PNG/TIFF angiogram, and overrides for a DICOM file. Keys of
``ViewGeometry.to_dict()`` (rows, cols, ...) are tolerated; other keys are
rejected as likely typos.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from recon.errors import LoadError
from recon.io.files import read_json
from recon.io.validate import check_geometry_value

__all__ = [
    "GEOMETRY_FIELDS",
    "GEOMETRY_KEYS",
    "GeometryOverrides",
    "read_geometry_json",
    "overrides_from_dict",
    "per_file_overrides",
    "header_replacements",
    "overrides_from_entries",
    "ENTRY_KEYS",
    "spacing_pair",
]

# The five geometry values: key, DICOM keyword, tag, command-line flag.
GEOMETRY_FIELDS = (
    ("alpha_deg", "PositionerPrimaryAngle", "(0018,1510)", "--alpha-deg"),
    ("beta_deg", "PositionerSecondaryAngle", "(0018,1511)", "--beta-deg"),
    ("sid_mm", "DistanceSourceToDetector", "(0018,1110)", "--sid-mm"),
    ("sod_mm", "DistanceSourceToPatient", "(0018,1111)", "--sod-mm"),
    ("pixel_spacing_mm", "ImagerPixelSpacing", "(0018,1164)", "--pixel-spacing-mm"),
)
GEOMETRY_KEYS = tuple(f[0] for f in GEOMETRY_FIELDS)
_FLAGS = {f[0]: f[3] for f in GEOMETRY_FIELDS}
# Keys of ViewGeometry.to_dict() that a geometry JSON may carry and that are
# checked (rows, cols) or ignored (the rest) rather than rejected as typos.
_TOLERATED_JSON_KEYS = ("rows", "cols", "principal_offset_px", "rotvec_corr", "t_corr_mm")


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
        for key in GEOMETRY_KEYS:
            value = getattr(self, key)
            if value is not None:
                object.__setattr__(self, key, check_geometry_value(key, value, self.where(key)))

    def where(self, key: str) -> str:
        """How a message names the value of ``key``: the flag for the command
        line, else "<source>: <key>"."""
        if self.source == "command line":
            return _FLAGS[key]
        return f"{self.source}: {key}"

    def values(self) -> dict[str, Any]:
        """The supplied (not None) values by key."""
        return {k: getattr(self, k) for k in GEOMETRY_KEYS if getattr(self, k) is not None}

    def merged_over(self, other: GeometryOverrides | None) -> GeometryOverrides:
        """These overrides with ``other`` filling the values they leave None."""
        if other is None:
            return self
        kwargs: dict[str, Any] = {}
        for key in GEOMETRY_KEYS:
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
        data = read_geometry_json(path)
        return overrides_from_dict(data, str(path))


def read_geometry_json(path: str | os.PathLike) -> dict:
    """The object of a geometry JSON file; LoadError naming the file otherwise."""
    data = read_json(path, LoadError, "geometry JSON")
    if not isinstance(data, dict):
        raise LoadError(
            f"{Path(path)}: the geometry JSON must be an object with keys {GEOMETRY_KEYS}"
        )
    return data


def overrides_from_dict(data: dict, source: str) -> GeometryOverrides:
    """Overrides from a parsed geometry JSON; errors name ``source``."""
    unknown = sorted(set(data) - set(GEOMETRY_KEYS) - set(_TOLERATED_JSON_KEYS))
    if unknown:
        raise LoadError(
            f"{source}: unknown key {unknown[0]!r} (expected {', '.join(GEOMETRY_KEYS)})"
        )
    kwargs: dict[str, Any] = {key: data[key] for key in GEOMETRY_KEYS if data.get(key) is not None}
    return GeometryOverrides(**kwargs, source=Path(source).name)


def spacing_pair(value: object) -> tuple[float, float] | None:
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


def per_file_overrides(
    common: GeometryOverrides | None, per_file: str | os.PathLike | None
) -> GeometryOverrides | None:
    """One file's overrides: its own geometry JSON (``--geometry-a`` / ``--geometry-b``)
    with the values given for every file (``--sid-mm`` ...) filling what it leaves out."""
    own = GeometryOverrides.from_json(per_file) if per_file is not None else None
    if own is None:
        return common
    return own.merged_over(common)


def header_replacements(geometry_notes: tuple[str, ...] | list[str]) -> list[str]:
    """The geometry notes of a file (``Angiogram.geometry_notes``) that say a value the
    header has was replaced by a user's value: each must reach the user as a warning."""
    return [n for n in geometry_notes if "(header says" in n]


# The values a user types for a file that lacks them (the viewer's Geometry folder).
ENTRY_KEYS = ("sid_mm", "sod_mm", "pixel_spacing_mm")
_ENTRY_WORDS = {"sid_mm": "SID", "sod_mm": "SOD", "pixel_spacing_mm": "pixel spacing",
                "alpha_deg": "primary angle", "beta_deg": "secondary angle"}


def overrides_from_entries(
    entries: dict[str, str], header: dict[str, Any], source: str
) -> tuple[GeometryOverrides | None, list[str]]:
    """Overrides from typed values (key -> text; "" keeps the header's value).

    ``header`` holds the file's own values (key -> number, (row, col) or None, as
    :func:`recon.io.describe.describe_file` reports them). A typed value equal to the
    header's is not an override; one that differs replaces it and is named in the
    returned messages ("SID 1000 mm replaces the header's 976 mm"). Raises LoadError
    naming ``source`` and the value for text that is not a number in range.
    """
    kwargs: dict[str, Any] = {}
    replaced: list[str] = []
    for key, text in entries.items():
        text = str(text).strip()
        if key not in GEOMETRY_KEYS:
            raise LoadError(f"{source}: unknown geometry value {key!r}")
        if not text:
            continue
        try:
            number = float(text)
        except ValueError:
            raise LoadError(f"{source}: {_ENTRY_WORDS[key]} {text!r} is not a number") from None
        value: Any = (number, number) if key == "pixel_spacing_mm" else number
        own = header.get(key)
        if own is not None and np.allclose(np.asarray(own, float), np.asarray(value, float)):
            continue
        kwargs[key] = value
        if own is not None:
            shown = "/".join(f"{v:g}" for v in np.asarray(own, float).reshape(-1)[:1])
            replaced.append(f"{_ENTRY_WORDS[key]} {number:g} replaces the header's {shown}")
    if not kwargs:
        return None, []
    return GeometryOverrides(**kwargs, source=source), replaced
