"""Reading JSON files and writing files whole: the two file chores every stage shares.

An OSError on a user's path never escapes: reading raises the caller's error
class (a :class:`~recon.errors.LoadError` or a subclass), writing raises
:class:`~recon.errors.OutputError`, each with one line naming the file.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from recon.errors import OutputError

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


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file and an atomic rename.

    The file appears whole or not at all, with the usual mode (0666 less the
    umask). Missing parent folders are made. Raises :class:`OutputError`
    naming ``path`` when it cannot be written.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise OutputError(_cannot_write(path, exc)) from exc
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; give the usual file mode
        os.replace(tmp, path)
    except BaseException as exc:
        Path(tmp).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise OutputError(_cannot_write(path, exc)) from exc
        raise


def _cannot_write(path: Path, exc: OSError) -> str:
    """One line: the path, and why (naming the other path involved, if any)."""
    reason = exc.strerror or str(exc)
    other = exc.filename
    if other is not None and Path(os.fsdecode(other)) != path and not str(other).endswith(".tmp"):
        reason += f": {os.fsdecode(other)}"
    return f"{path}: cannot write the file ({reason})"
