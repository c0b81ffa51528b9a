"""Reading JSON files and writing files whole: the two file chores every stage shares."""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

__all__ = ["read_json", "atomic_write_bytes"]


def read_json(path: str | os.PathLike, error: type[Exception], what: str = "file") -> object:
    """Parse a JSON file; failures raise ``error`` with one line naming the file.

    ``what`` names the file's role in the message ("cannot read the geometry JSON").
    """
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as exc:
        raise error(f"{p}: cannot read the {what} ({exc.strerror or exc})") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{p}: not valid JSON (line {exc.lineno}: {exc.msg})") from None


def atomic_write_bytes(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and an atomic rename."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual file mode
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
