"""The batch manifest: a CSV with one row per case, read and checked before any work.

The header starts with ``id,a,b,seeds``; the optional columns of
:data:`OPTIONAL_COLUMNS` give per-case geometry files, frames and options
(an empty cell means the default). Relative paths are relative to the
manifest's folder. ``id`` names the case's output folder ``DIR/<id>/``, so
it is made of letters, digits, ``.``, ``_`` and ``-``, does not start with
``.``, and is unique. A manifest that breaks a rule raises
:class:`ManifestError`, one line naming the manifest, the line and what is
wrong; files that do not exist are not a manifest error but a failed case.
"""

from __future__ import annotations

import csv
import os
import re
import stat
from dataclasses import dataclass, field
from pathlib import Path

from recon.errors import LoadError

__all__ = ["REQUIRED_COLUMNS", "OPTIONAL_COLUMNS", "ManifestError", "BatchCase", "read_manifest"]

REQUIRED_COLUMNS = ("id", "a", "b", "seeds")
MAX_MANIFEST_BYTES = 64 * 2**20  # some 300 000 cases

# column -> what its cell holds: "path" (relative to the manifest), "int", "bool",
# or a tuple of the allowed words
OPTIONAL_COLUMNS: dict[str, str | tuple[str, ...]] = {
    "geometry_a": "path",  # geometry JSON of view A (see --geometry-json)
    "geometry_b": "path",
    "frame_a": "int",  # 0-based frame of a cine
    "frame_b": "int",
    "segment": "int",  # which segment of seeds.json (0-based)
    "matcher": ("match1", "match2", "match3", "match4"),
    "optimizer": ("palm", "lm", "anneal"),
    "intensity_a": ("auto", "lin", "log"),
    "intensity_b": ("auto", "lin", "log"),
    "self_calibration": "bool",
}

_ID = re.compile(r"[A-Za-z0-9_\-][A-Za-z0-9_.\-]*")
_TRUE, _FALSE = ("1", "true", "yes"), ("0", "false", "no")


class ManifestError(LoadError):
    """A manifest that cannot be used; one line "<manifest>[ line N]: <what is wrong>"."""


@dataclass(frozen=True)
class BatchCase:
    """One row of a manifest, its paths absolute.

    ``options`` holds the row's non-empty optional cells, parsed (keys of
    :data:`OPTIONAL_COLUMNS`); ``line`` is its line in the manifest.
    """

    id: str
    a: str
    b: str
    seeds: str
    line: int
    options: dict[str, str | int | bool] = field(default_factory=dict)


def read_manifest(path: str | os.PathLike) -> list[BatchCase]:
    """Every case of a manifest, in its order; raises :class:`ManifestError`."""
    p = Path(path)
    try:
        info = p.stat()
        if not stat.S_ISREG(info.st_mode):  # a pipe or a device would never end
            raise ManifestError(f"{p}: the manifest is not a regular file")
        if info.st_size > MAX_MANIFEST_BYTES:
            raise ManifestError(f"{p}: the manifest is {info.st_size / 1e6:.1f} MB; at most "
                                f"{MAX_MANIFEST_BYTES // 2**20} MB is read")
        text = p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise ManifestError(f"{p}: cannot read the manifest ({exc.strerror or exc})") from None
    except UnicodeDecodeError:
        raise ManifestError(f"{p}: not a text (UTF-8) CSV file") from None
    rows = list(csv.reader(text.splitlines()))
    while rows and not any(cell.strip() for cell in rows[-1]):
        rows.pop()
    if not rows:
        raise ManifestError(f"{p}: empty manifest (the header is id,a,b,seeds)")
    header = [cell.strip() for cell in rows[0]]
    if tuple(header[:4]) != REQUIRED_COLUMNS:
        raise ManifestError(
            f"{p} line 1: the header must start with id,a,b,seeds (found {','.join(header)})"
        )
    unknown = [c for c in header[4:] if c not in OPTIONAL_COLUMNS]
    if unknown:
        raise ManifestError(
            f"{p} line 1: unknown column {unknown[0]!r} (optional columns: "
            f"{', '.join(OPTIONAL_COLUMNS)})"
        )
    repeated = sorted({c for c in header if header.count(c) > 1})
    if repeated:
        raise ManifestError(f"{p} line 1: column {repeated[0]!r} appears twice")
    base = p.resolve().parent
    cases: list[BatchCase] = []
    seen: dict[str, int] = {}
    for line, row in enumerate(rows[1:], start=2):
        if not any(cell.strip() for cell in row):
            continue
        where = f"{p} line {line}"
        if len(row) != len(header):
            raise ManifestError(f"{where}: {len(row)} cells, the header has {len(header)}")
        cells = {name: cell.strip() for name, cell in zip(header, row, strict=True)}
        case_id = cells["id"]
        if not _ID.fullmatch(case_id):
            raise ManifestError(
                f"{where}: id {case_id!r} is not a folder name (letters, digits, '.', '_', '-'; "
                "not starting with '.')"
            )
        if case_id in seen:
            raise ManifestError(f"{where}: id {case_id!r} is already on line {seen[case_id]}")
        seen[case_id] = line
        for name in ("a", "b", "seeds"):
            if not cells[name]:
                raise ManifestError(f"{where}: the {name} cell is empty")
        options = {
            name: _parse(cells[name], kind, base, f"{where}: {name}")
            for name, kind in OPTIONAL_COLUMNS.items()
            if cells.get(name)
        }
        cases.append(
            BatchCase(
                id=case_id,
                a=_resolve(cells["a"], base),
                b=_resolve(cells["b"], base),
                seeds=_resolve(cells["seeds"], base),
                line=line,
                options=options,
            )
        )
    if not cases:
        raise ManifestError(f"{p}: no cases (only the header)")
    return cases


def _resolve(cell: str, base: Path) -> str:
    path = Path(cell).expanduser()
    return os.fspath(path if path.is_absolute() else base / path)


def _parse(cell: str, kind: str | tuple[str, ...], base: Path, what: str) -> str | int | bool:
    if kind == "path":
        return _resolve(cell, base)
    if kind == "int":
        try:
            return int(cell)
        except ValueError:
            raise ManifestError(f"{what} {cell!r} is not an integer") from None
    if kind == "bool":
        if cell.lower() in _TRUE + _FALSE:
            return cell.lower() in _TRUE
        raise ManifestError(f"{what} {cell!r} is not one of {', '.join(_TRUE + _FALSE)}")
    if cell not in kind:
        raise ManifestError(f"{what} {cell!r} is not one of {', '.join(kind)}")
    return cell
