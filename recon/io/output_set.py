"""A folder of output files written as one set: complete, or recognisably incomplete.

:func:`write_file_set` puts named files (bytes) into a folder so that the
folder always holds either one complete run or a run marked incomplete:

1. the folder is checked first (:func:`check_output_folder`): it must be a
   folder (or not exist yet), hold nothing but an earlier coronary3d output
   (its manifest :data:`MANIFEST_NAME` lists what it wrote), no output name
   may be a folder or a link, and no output may replace one of the run's
   input files;
2. temporary files that a killed earlier run left (``.NAME.PID.XXXX.tmp``
   whose process is gone) are removed;
3. the manifest is rewritten with ``"complete": false``;
4. every file goes to a temporary name in the folder (a failure here, a
   full disk or a SIGTERM, removes the temporaries and puts the earlier
   manifest back: the earlier set stays as it was, a new folder is removed);
5. the temporaries are renamed to their final names, files of the earlier
   set that this one does not have are removed, and the manifest is written
   last with ``"complete": true``, the size and SHA-256 of every file.

Termination signals (SIGTERM, SIGINT) are turned into exceptions by
:func:`raise_on_termination` so that step 4 cleans up; during steps 5 and the
cleanups they are held back by :func:`deferred_termination` and delivered
after. A SIGKILL can leave temporaries: the next run in the folder removes
them (step 2).
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import re
import secrets
import signal
import stat
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from types import FrameType

from recon.errors import OutputError

__all__ = [
    "MANIFEST_NAME",
    "Terminated",
    "check_output_folder",
    "write_file_set",
    "read_manifest",
    "raise_on_termination",
    "deferred_termination",
]

MANIFEST_NAME = "outputs.json"
MANIFEST_VERSION = 1

# .NAME.PID.RANDOM.tmp (this module) or .NAME.RANDOM.tmp (atomic_write_bytes, older runs)
_TEMP_RE = re.compile(r"^\.(?P<name>.+?)\.(?:(?P<pid>\d+)\.)?[A-Za-z0-9_]{6,16}\.tmp$")


class Terminated(KeyboardInterrupt):
    """SIGTERM (or SIGINT) received; ``signum`` says which. A KeyboardInterrupt, so that
    code which cleans up after Ctrl-C cleans up after a kill too."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"signal {signum}")
        self.signum = signum


# ------------------------------------------------------------------ signals
_held: list[int] = []  # signals received while deferred
_depth = 0  # nesting of deferred_termination


def _on_signal(signum: int, frame: FrameType | None) -> None:
    if _depth > 0:
        _held.append(signum)
        return
    raise Terminated(signum)


def raise_on_termination() -> None:
    """Make SIGTERM and SIGINT raise :class:`Terminated` in the main thread (call once,
    from the main thread; elsewhere it does nothing)."""
    with contextlib.suppress(ValueError):  # not the main thread
        signal.signal(signal.SIGTERM, _on_signal)
        signal.signal(signal.SIGINT, _on_signal)


@contextlib.contextmanager
def deferred_termination() -> Iterator[None]:
    """Hold SIGTERM / SIGINT back (when :func:`raise_on_termination` is in force) until the
    block ends, then raise :class:`Terminated` for the first one received."""
    global _depth
    _depth += 1
    try:
        yield
    finally:
        _depth -= 1
    if _depth == 0 and _held:
        signum = _held[0]
        _held.clear()
        raise Terminated(signum)


# ------------------------------------------------------------------ the folder
def read_manifest(folder: str | os.PathLike) -> dict | None:
    """The folder's manifest as a dict, or None when it has none or it is not one of ours."""
    path = Path(folder) / MANIFEST_NAME
    try:
        if not stat.S_ISREG(path.lstat().st_mode) or path.stat().st_size > 1_000_000:
            return None
        doc = json.loads(path.read_bytes().decode("utf-8"))
    except (OSError, ValueError, RecursionError):
        return None
    if not isinstance(doc, dict) or doc.get("software") != "coronary3d":
        return None
    files = doc.get("files")
    if not isinstance(files, dict) or not all(isinstance(k, str) for k in files):
        return None
    return doc


def _is_coronary3d_report(path: Path) -> bool:
    """True for a report.json that coronary3d wrote (an output folder from before manifests)."""
    try:
        if not stat.S_ISREG(path.lstat().st_mode) or path.stat().st_size > 10_000_000:
            return False
        doc = json.loads(path.read_bytes().decode("utf-8"))
    except (OSError, ValueError, RecursionError):
        return False
    software = doc.get("software") if isinstance(doc, dict) else None
    return isinstance(software, dict) and software.get("name") == "coronary3d"


def _stale_temps(folder: Path, known: set[str]) -> list[Path]:
    """Temporaries of known names whose writing process is gone."""
    stale = []
    with contextlib.suppress(OSError):
        for entry in os.scandir(folder):
            m = _TEMP_RE.match(entry.name)
            if m is None or m["name"] not in known or not entry.is_file(follow_symlinks=False):
                continue
            pid = m["pid"]
            if pid is not None and int(pid) != os.getpid() and _alive(int(pid)):
                continue  # another run is writing into this folder right now
            stale.append(Path(entry.path))
    return stale


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _same_file(a: Path, b: Path) -> bool:
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_output_folder(
    folder: str | os.PathLike,
    names: Sequence[str],
    inputs: Sequence[tuple[str, str | os.PathLike]] = (),
    known: Sequence[str] = (),
) -> None:
    """Refuse, in one line, a folder the set ``names`` must not be written into.

    ``inputs`` are (role, path) of the run's input files ("seeds file",
    path); ``known`` are further names of this kind of output (other mesh
    formats) that an earlier run may have left. Nothing is created or changed.
    Raises :class:`OutputError`.
    """
    if not os.fspath(folder).strip():  # Path("") would be the current folder
        raise OutputError("--out is empty: give the output folder")
    folder = Path(folder)
    try:
        info = folder.lstat()
    except FileNotFoundError:
        info = None
    except OSError as exc:
        raise OutputError(f"{folder}: cannot use the output folder ({exc.strerror})") from None
    if info is not None and stat.S_ISLNK(info.st_mode):
        info = folder.stat() if folder.exists() else None
    if info is not None and not stat.S_ISDIR(info.st_mode):
        raise OutputError(f"{folder}: is a file, not a folder; give a folder for the outputs")
    for role, path in inputs:
        if path is not None and _same_file(Path(path), folder):
            raise OutputError(f"{folder}: is the {role}; give a folder for the outputs")
    if info is None:
        return
    manifest = read_manifest(folder)
    listed = set(manifest["files"]) if manifest else set()
    ours = set(names) | set(known) | listed
    for name in [*names, *sorted(listed - set(names)), MANIFEST_NAME]:
        target = folder / name
        for role, path in inputs:
            if path is not None and _same_file(Path(path), target):
                raise OutputError(
                    f"{target}: is the {role} of this run; writing the outputs here would "
                    "replace it (give another --out)"
                )
        try:
            mode = target.lstat().st_mode
        except FileNotFoundError:
            continue
        except OSError as exc:
            raise OutputError(f"{target}: cannot use it ({exc.strerror})") from None
        if not stat.S_ISREG(mode):
            kind = "a folder" if stat.S_ISDIR(mode) else "a link" if stat.S_ISLNK(mode) \
                else "not a regular file"
            raise OutputError(f"{target}: is {kind}; an output file of this name cannot be "
                              "written (move it away or give another --out)")
    temps = {p.name for p in _stale_temps(folder, ours | {MANIFEST_NAME})}
    try:
        entries = sorted(e.name for e in os.scandir(folder))
    except OSError as exc:
        raise OutputError(f"{folder}: cannot read the output folder ({exc.strerror})") from None
    entries = [e for e in entries if e not in temps and not _TEMP_RE.match(e)]
    if manifest is not None:
        foreign = [e for e in entries if e not in ours and e != MANIFEST_NAME]
    elif not entries:
        foreign = []
    elif _is_coronary3d_report(folder / "report.json"):  # written before manifests existed
        foreign = [e for e in entries if e not in ours]
    else:
        foreign = entries
    if foreign:
        shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3
                                          else "")
        raise OutputError(f"{folder}: the folder holds files that are not a coronary3d output "
                          f"({shown}); give an empty or new folder")


# ------------------------------------------------------------------ writing
def write_file_set(
    folder: str | os.PathLike,
    files: Mapping[str, bytes],
    inputs: Sequence[tuple[str, str | os.PathLike]] = (),
    known: Sequence[str] = (),
    version: str = "",
) -> list[Path]:
    """Write ``files`` (name -> bytes) into ``folder`` as one set (module docstring).

    Returns the final paths in the order of ``files``. Raises
    :class:`OutputError` (one line naming the folder or the file) and leaves
    the folder as it was: an earlier complete set stays complete, a folder
    made for this set is removed again.
    """
    check_output_folder(folder, list(files), inputs, known)
    folder = Path(folder)
    names = list(files)
    if MANIFEST_NAME in files or any(Path(n).name != n or n.startswith(".") for n in names):
        raise ValueError(f"output names must be plain file names other than {MANIFEST_NAME}")
    made = not folder.exists()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{folder}: cannot make the output folder ({exc.strerror})") from None
    previous = read_manifest(folder)
    previous_bytes = (folder / MANIFEST_NAME).read_bytes() if previous else None
    listed = set(previous["files"]) if previous else set()
    with deferred_termination():
        for path in _stale_temps(folder, set(names) | set(known) | listed | {MANIFEST_NAME}):
            path.unlink(missing_ok=True)
    temps: dict[str, Path] = {}
    manifest_path = folder / MANIFEST_NAME
    try:
        _write_now(manifest_path, _manifest({n: None for n in sorted(listed | set(names))},
                                            False, version))
        for name, data in files.items():
            temps[name] = _temp_path(folder, name)  # registered before it exists
            _write_file(temps[name], data)
    except BaseException as exc:
        with deferred_termination():
            _abandon(folder, temps, manifest_path, previous_bytes, made)
        if isinstance(exc, OSError):
            where = exc.filename and Path(os.fsdecode(exc.filename))
            name = next((n for n, t in temps.items() if t == where), None)
            target = folder / name if name else manifest_path
            raise OutputError(f"{target}: cannot write the file ({exc.strerror or exc}); "
                              "no output was written") from None
        raise
    with deferred_termination():
        try:
            for name in names:
                os.replace(temps.pop(name), folder / name)
            for name in sorted(listed - set(names)):
                (folder / name).unlink(missing_ok=True)
            record = {n: {"bytes": len(d), "sha256": hashlib.sha256(d).hexdigest()}
                      for n, d in files.items()}
            _write_now(manifest_path, _manifest(record, True, version))
            _fsync_folder(folder)
        except OSError as exc:
            for tmp in temps.values():
                tmp.unlink(missing_ok=True)
            raise OutputError(f"{folder}: the outputs are incomplete ({exc.strerror or exc}; "
                              f"{MANIFEST_NAME} says so)") from None
    return [folder / name for name in names]


def _manifest(files: dict[str, object], complete: bool, version: str) -> bytes:
    doc = {"software": "coronary3d", "manifest_version": MANIFEST_VERSION, "version": version,
           "complete": complete, "files": files}
    return (json.dumps(doc, indent=2) + "\n").encode()


def _temp_path(folder: Path, name: str) -> Path:
    return folder / f".{name}.{os.getpid()}.{secrets.token_hex(4)}.tmp"


def _write_file(path: Path, data: bytes) -> None:
    """Create ``path`` (exclusively) holding ``data``, flushed to disk, with the usual mode."""
    umask = os.umask(0)
    os.umask(umask)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666 & ~umask)
    try:
        view = memoryview(data)
        while view:
            view = view[os.write(fd, view):]
        os.fsync(fd)
    except OSError as exc:
        exc.filename = exc.filename or os.fsencode(path)
        raise
    finally:
        os.close(fd)


def _write_now(path: Path, data: bytes) -> None:
    """Replace ``path`` by ``data`` through a temporary (removed if anything fails)."""
    tmp = _temp_path(path.parent, path.name)
    try:
        _write_file(tmp, data)
        os.replace(tmp, path)
    except BaseException:
        with deferred_termination():
            tmp.unlink(missing_ok=True)
        raise


def _abandon(folder: Path, temps: dict[str, Path], manifest_path: Path,
             previous_bytes: bytes | None, made: bool) -> None:
    """Undo a set that was not written: temporaries gone, the earlier manifest back."""
    for tmp in temps.values():
        tmp.unlink(missing_ok=True)
    with contextlib.suppress(OSError):
        if previous_bytes is not None:
            _write_now(manifest_path, previous_bytes)
        else:
            manifest_path.unlink(missing_ok=True)
    if made:
        with contextlib.suppress(OSError):
            folder.rmdir()


def _fsync_folder(folder: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)
