"""Files the page opens: a pair of angiograms (inside the folders the page may read),
their headers' geometry for the Geometry folder, typed geometry values, and uploads.

Plain functions over paths and :mod:`recon.io`; :class:`viewer_app.app.ViewerApp` calls
them and shows what they return.
"""

from __future__ import annotations

import re
import time
from pathlib import Path
from typing import TYPE_CHECKING

from recon.errors import LoadError
from recon.io import load_angiogram

if TYPE_CHECKING:
    from recon.io.overrides import GeometryOverrides
    from recon.types import Angiogram
    from viewer_app.access import FileAccess

__all__ = ["header_geometries", "keep_upload", "page_wording", "patients_differ", "read_pair",
           "typed_overrides"]

VIEW_KEYS = ("a", "b")


def read_pair(access: FileAccess, paths: tuple[str, str],
              frames: tuple[int | None, int | None] = (None, None),
              overrides: tuple[GeometryOverrides | None, GeometryOverrides | None] = (None, None)
              ) -> tuple[Angiogram, Angiogram]:
    """Files A and B (``paths``) read as angiograms, each confined to the folders the page
    may read (``access``). Raises LoadError (or ValueError for a path outside them)."""
    a, b = (load_angiogram(access.readable(p, f"file {k.upper()}"), frame=f, overrides=o)
            for k, p, f, o in zip(VIEW_KEYS, paths, frames, overrides, strict=True))
    return a, b


def page_wording(exc: LoadError) -> LoadError:
    """A missing-geometry error as the page says it: enter the value under Geometry (the
    command line's message names its option instead)."""
    return LoadError(re.sub(r"give --[\w-]+ or a geometry JSON", "enter it under Geometry",
                            str(exc)))


def header_geometries(paths: tuple[str, str]) -> dict[str, dict] | None:
    """Each file's header geometry (view -> recon.io.describe's "geometry": SID, SOD,
    pixel spacing, None where missing); None when a file cannot be read at all."""
    from recon.io.describe import describe_file

    try:
        return {k: describe_file(p)["geometry"] for k, p in zip(VIEW_KEYS, paths, strict=True)}
    except LoadError:
        return None


def patients_differ(paths: tuple[str, str]) -> bool:
    """Whether files A and B (``paths``) name different patients: their PatientID differ
    (:func:`recon.io.patients.patient_check`, headers only; unknown for an image file or
    a file without one, which is not refused here). The IDs are never returned, shown
    or logged."""
    from recon.io.patients import patient_check

    return patient_check(*paths).same_patient is False


def typed_overrides(paths: tuple[str, str], entries: dict[str, dict[str, str]]
                    ) -> tuple[dict[str, GeometryOverrides], list[str]]:
    """The geometry values typed in the Geometry folder (view -> key -> text; "" keeps the
    header's) as each file's overrides, and one warning per header value they replace."""
    from recon.io.describe import describe_file
    from recon.io.overrides import overrides_from_entries

    overrides, warnings = {}, []
    for key, path in zip(VIEW_KEYS, paths, strict=True):
        header = describe_file(path)["geometry"]
        ov, replaced = overrides_from_entries(
            entries[key], header, source=f"Geometry {key.upper()} ({Path(path).name})")
        overrides[key] = ov
        warnings += [f"{key.upper()} {Path(path).name}: {r}" for r in replaced]
    return overrides, warnings


def keep_upload(folder: Path, view: str, filename: str, content: bytes) -> Path:
    """An uploaded file written to a new folder under ``folder`` (the viewer's private
    temporary folder), under its own base name; its path."""
    safe = Path(filename).name or f"upload_{view}.dcm"
    target = folder / f"{view}-{time.time_ns()}"
    target.mkdir(parents=True)
    path = target / safe
    path.write_bytes(content)
    return path
