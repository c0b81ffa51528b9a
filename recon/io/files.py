"""Reading JSON files and writing files whole: the two file chores every stage shares.

An OSError on a user's path never escapes: reading raises the caller's error
class (a :class:`~recon.errors.LoadError` or a subclass), writing raises
:class:`~recon.errors.OutputError`, each with one line naming the file.
"""

from __future__ import annotations

import json
import os
import stat
import tempfile
from pathlib import Path

from recon.errors import OutputError

__all__ = ["read_json", "atomic_write_bytes"]


# A JSON input (seeds, geometry, sidecar) larger than this, or nested deeper,
# is refused: the project's largest real ones are a few kB and 4 levels deep.
MAX_JSON_BYTES = 10 * 1024 * 1024
MAX_JSON_DEPTH = 32


def read_json(path: str | os.PathLike, error: type[Exception], what: str = "file") -> object:
    """Parse a JSON file; failures raise ``error`` with one line naming the file.

    ``what`` names the file's role in the message ("cannot read the geometry JSON").
    Refused: a path that is not a regular file (a folder, a pipe, /dev/zero), a
    file over :data:`MAX_JSON_BYTES`, text that is not UTF-8, invalid JSON,
    integers too long to convert and nesting deeper than :data:`MAX_JSON_DEPTH`.
    """
    p = Path(path)
    try:
        info = p.stat()
        if not stat.S_ISREG(info.st_mode):
            raise error(f"{p}: the {what} is not a regular file")
        if info.st_size > MAX_JSON_BYTES:
            raise error(
                f"{p}: the {what} is {info.st_size / 1e6:.1f} MB; at most "
                f"{MAX_JSON_BYTES // (1024 * 1024)} MB is read"
            )
        with p.open("rb") as fh:
            data = fh.read(MAX_JSON_BYTES + 1)
    except OSError as exc:
        raise error(f"{p}: cannot read the {what} ({exc.strerror or exc})") from None
    if len(data) > MAX_JSON_BYTES:
        raise error(f"{p}: the {what} is over {MAX_JSON_BYTES // (1024 * 1024)} MB")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{p}: the {what} is not UTF-8 text (byte {exc.start})") from None
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise error(f"{p}: not valid JSON (line {exc.lineno}: {exc.msg})") from None
    except RecursionError:
        raise error(f"{p}: the {what} is nested too deeply") from None
    except ValueError:  # an integer of more digits than Python converts
        raise error(f"{p}: the {what} holds a number too long to read") from None
    if _depth_over(value, MAX_JSON_DEPTH):
        raise error(f"{p}: the {what} is nested deeper than {MAX_JSON_DEPTH} levels")
    return value


def _depth_over(value: object, limit: int) -> bool:
    """True when lists / objects in ``value`` nest deeper than ``limit`` (no recursion)."""
    stack = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, (list, dict)):
            if depth > limit:
                return True
            children = item.values() if isinstance(item, dict) else item
            stack.extend((child, depth + 1) for child in children)
    return False


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
