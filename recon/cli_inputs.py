"""What `coronary3d reconstruct` reads: the files no output may replace, and --segment."""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["segment_choice", "file_bytes", "input_files"]


def segment_choice(text: str | None, seeds, seeds_path: str) -> int | None:
    """--segment as an index into the seeds' segments (None: all of them). Raises
    ValueError (the one-line message) when the name or index does not exist."""
    if text is None:
        return None
    names = [s.name for s in seeds.segments]
    if text in names:
        return names.index(text)
    if text.strip().isdigit() and int(text) < len(names):
        return int(text)
    shown = ", ".join(repr(n) for n in names[:10]) or "none"
    raise ValueError(f"argument --segment: no segment {text!r} in {seeds_path} "
                     f"(segments: {shown}; or an index from 0 to {len(names) - 1})")


def file_bytes(path: str) -> int:
    try:
        return os.stat(path).st_size
    except OSError:
        return 0  # the loader says what is wrong with it


def input_files(file_a: str, file_b: str, seeds: str, geometry_json: str | None,
                 geometry_a: str | None = None,
                 geometry_b: str | None = None) -> list[tuple[str, str]]:
    """(role, path) of every file a reconstruction reads, which no output may replace."""
    found = [("file A", file_a), ("file B", file_b), ("seeds file", seeds)]
    for role, path in (("geometry JSON", geometry_json), ("geometry JSON of file A", geometry_a),
                       ("geometry JSON of file B", geometry_b)):
        if path:
            found.append((role, path))
    for role, path in (("A", file_a), ("B", file_b)):
        sidecar = Path(path).with_suffix(".json")
        if sidecar != Path(path):
            found.append((f"geometry JSON of file {role}", str(sidecar)))
    return found
