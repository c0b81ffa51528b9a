"""One job in a child process of its own, so that its limits apply in full.

The memory and CPU-time limits of :mod:`recon.io.limits` are process-wide
(``RLIMIT_DATA``, ``RLIMIT_CPU``) and the CPU limit needs the main thread;
a Dask worker runs its task in a worker thread, and the viewer runs
Reconstruct in a server thread. :func:`run_isolated` runs a job in a child
forked, for that job alone, from a multiprocessing fork server (a
single-threaded process started once, with the pipeline already imported,
so a job does not pay the ~1.2 s of imports). In the child's main thread
:func:`recon.io.limits.job_limits` works exactly as for ``coronary3d
reconstruct``, including the watchdog that ends a process stuck at a limit
in native code; reaching a limit ends only the child, never the worker or
the viewer.

The parent sends ``(target, args)`` (``target`` is "module:function"); the
child sends back frames on a pipe: ``("progress", stage, fraction)`` for
each progress call, then ``("result", value)`` or ``("error", kind, class
path, message)``. Its standard error goes to a second pipe, so a child that
ends without a frame (the limit watchdog, a kill) is told apart by its exit
status and last stderr line. Pickles pass only between this process and the
children it started.
"""

from __future__ import annotations

import contextlib
import importlib
import multiprocessing
import os
import pickle
import signal
import struct
import subprocess
import sys
import threading
from collections.abc import Callable, Iterable, Iterator
from typing import IO, TYPE_CHECKING, Any

from recon.errors import CoronaryError
from recon.io.limits import LimitError

if TYPE_CHECKING:
    from recon.pipeline import Reconstruction, ReconstructionOptions
    from recon.seeds import Seeds
    from recon.trace.centerline import VesselnessMap
    from recon.tree import TreeReconstruction
    from recon.types import Angiogram

__all__ = ["JobFailed", "run_isolated", "start_fork_server", "reconstruct_limited",
           "reconstruct_tree_limited"]

Progress = Callable[[str, float], None]
_HEADER = struct.Struct("!Q")  # the length of each frame's pickle (fresh interpreter)


class JobFailed(Exception):
    """An error that is not the project's (a bug) inside the child: its type and message."""

    def __init__(self, type_name: str, message: str) -> None:
        super().__init__(f"{type_name}: {message}")
        self.type_name = type_name
        self.message = message


def run_isolated(target: str, args: tuple, progress: Progress | None = None,
                 what: str = "the reconstruction") -> Any:
    """``target(*args)`` ("module:function") computed in a child process; its value.

    The function gets a ``progress`` keyword when ``progress`` is given (its
    calls are relayed here). A :class:`~recon.errors.CoronaryError` in the
    child is raised here as the same class with the same one line (a limit
    reached is a :class:`~recon.io.limits.LimitError` saying which); another
    exception is a :class:`JobFailed`; a child killed by a signal is a
    :class:`CoronaryError` naming ``what`` and the signal.
    """
    if multiprocessing.current_process().daemon:
        return _run_fresh(target, args, progress, what)
    ctx = _fork_server()
    frames_in, frames_out = ctx.Pipe(duplex=False)
    err_in, err_out = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(frames_out, err_out, target, args,
                                            progress is not None), daemon=True)
    stderr_lines: list[bytes] = []
    reader = threading.Thread(target=_collect, args=(err_in, stderr_lines), daemon=True)
    outcome: tuple | None = None
    try:
        proc.start()
        frames_out.close()
        err_out.close()
        reader.start()
        outcome = _relay(_received(frames_in), progress)
    except BaseException:
        if proc.pid is not None:
            proc.kill()
        raise
    finally:
        if proc.pid is not None:
            proc.join()
        frames_in.close()
    reader.join(timeout=5.0)
    code = proc.exitcode if proc.exitcode is not None else 1
    return _outcome(outcome, code, stderr_lines, what)


def _received(conn: Any) -> Iterator[tuple]:
    """The frames arriving on a pipe's end, until the child closes it."""
    while True:
        try:
            yield conn.recv()
        except (EOFError, OSError):
            return


def _relay(frames: Iterable[tuple], progress: Progress | None) -> tuple | None:
    """Pass the progress frames on; the last frame (result or error), or None if the
    child ended without one."""
    for frame in frames:
        if frame[0] != "progress":
            return frame
        if progress is not None:
            progress(frame[1], frame[2])
    return None


def _outcome(outcome: tuple | None, code: int, stderr_lines: list[bytes], what: str) -> Any:
    """The job's value, or its error raised, from its last frame, exit status and stderr."""
    if outcome is not None and outcome[0] == "result":
        return outcome[1]
    if outcome is not None:
        _, kind, cls_path, message, *whole = outcome
        if kind == "coronary":
            raise _project_error(cls_path, message, whole[0] if whole else None)
        raise JobFailed(cls_path, message)
    last = next((ln.decode(errors="replace").strip() for ln in reversed(stderr_lines)
                 if ln.strip()), "")
    prefix = "coronary3d: error: "
    if code == 2 and last.startswith(prefix):  # the limits watchdog's line
        raise LimitError(last[len(prefix):])
    if code < 0:
        name = signal.Signals(-code).name if -code in signal.Signals._value2member_map_ \
            else str(-code)
        extra = " (the system may have run out of memory)" if -code == signal.SIGKILL else ""
        raise CoronaryError(f"{what} was ended by {name}{extra}")
    raise CoronaryError(f"{what} ended with exit code {code}" + (f": {last}" if last else ""))


def _run_fresh(target: str, args: tuple, progress: Progress | None,
               what: str) -> Any:
    """:func:`run_isolated` in a fresh interpreter (``python -m recon.io.isolated``), for
    a daemonic process (a Dask worker), which may not start a fork server."""
    env = dict(os.environ)
    env.pop("CORONARY3D_DEBUG", None)
    proc = subprocess.Popen([sys.executable, "-m", "recon.io.isolated"],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env)
    stderr_lines: list[bytes] = []
    reader = threading.Thread(target=_collect_stream, args=(proc.stderr, stderr_lines),
                              daemon=True)
    reader.start()
    outcome: tuple | None = None
    try:
        with contextlib.suppress(BrokenPipeError):  # a child that died at once
            proc.stdin.write(pickle.dumps((target, args, progress is not None)))
            proc.stdin.close()
        outcome = _relay(iter(lambda: _read_frame(proc.stdout), None), progress)
    except BaseException:
        proc.kill()
        raise
    finally:
        code = proc.wait()
        reader.join(timeout=5.0)
        proc.stdout.close()
    return _outcome(outcome, code, stderr_lines, what)


_SERVER: list = []  # the multiprocessing context of this process's fork server, once made


def start_fork_server() -> None:
    """Start the fork server now (it takes about a second, the imports), so that the
    first :func:`run_isolated` does not wait for it; nothing in a daemonic process."""
    if not multiprocessing.current_process().daemon:
        from multiprocessing import forkserver

        _fork_server()
        forkserver.ensure_running()


def _fork_server() -> Any:
    """The "forkserver" multiprocessing context, its server preloading the pipeline."""
    if not _SERVER:
        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(["recon.io.isolated", "recon.pipeline", "recon.tree",
                                    "recon.io.limits"])
        _SERVER.append(ctx)
    return _SERVER[0]


def _project_error(cls_path: str, message: str, whole: bytes | None = None) -> CoronaryError:
    """The child's error: unpickled whole where it came so (with its attributes), else its
    class (the base class if that cannot be rebuilt) with its one line."""
    if whole is not None:
        try:
            exc = pickle.loads(whole)
            if isinstance(exc, CoronaryError) and str(exc) == message:
                return exc
        except Exception:  # noqa: BLE001 - fall back to the class and the line
            pass
    module, _, name = cls_path.rpartition(".")
    try:
        cls = getattr(importlib.import_module(module), name)
        if isinstance(cls, type) and issubclass(cls, CoronaryError):
            return cls(message)
    except Exception:  # noqa: BLE001 - any class that cannot be rebuilt is the base class
        pass
    return CoronaryError(message)


def _collect(conn: Any, lines: list[bytes]) -> None:
    """The last lines a child wrote to its standard error (``conn``: the pipe's end)."""
    pending = b""
    fd = conn.fileno()
    while True:
        try:
            chunk = os.read(fd, 65536)
        except OSError:
            break
        if not chunk:
            break
        pending += chunk
        *done, pending = pending.split(b"\n")
        lines.extend(done)
        del lines[:-20]  # the last lines say why a child ended
    if pending:
        lines.append(pending)
    conn.close()


def _collect_stream(stream: IO[bytes], lines: list[bytes]) -> None:
    for line in stream:
        lines.append(line)
        del lines[:-20]  # the last lines say why a child ended
    stream.close()


def _read_frame(stream: IO[bytes]) -> tuple | None:
    head = stream.read(_HEADER.size)
    if len(head) < _HEADER.size:
        return None
    (size,) = _HEADER.unpack(head)
    body = stream.read(size)
    if len(body) < size:
        return None
    return pickle.loads(body)


def _write_frame(stream: IO[bytes], frame: tuple) -> None:
    body = pickle.dumps(frame, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(body)) + body)
    stream.flush()


def _die_with_parent() -> None:
    """Ask Linux to end this child when its parent dies (a killed worker leaves no orphan)."""
    with contextlib.suppress(Exception):
        import ctypes

        pr_set_pdeathsig = 1
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(pr_set_pdeathsig, signal.SIGKILL)


def _run_target(target: str, args: tuple, wants_progress: bool,
                send: Callable[[tuple], None]) -> int:
    """Run ``target(*args)`` in a child and ``send`` its frames; the exit status (0 done,
    2 after a project error, 1 after another)."""
    kwargs = {}
    if wants_progress:
        kwargs["progress"] = lambda stage, fraction: send(
            ("progress", str(stage), float(fraction)))
    try:
        module, _, name = target.partition(":")
        value = getattr(importlib.import_module(module), name)(*args, **kwargs)
    except CoronaryError as exc:
        cls = type(exc)
        try:  # the error itself too, where it pickles (a TraceError's view and place)
            whole = pickle.dumps(exc, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # noqa: BLE001 - its class and line are enough then
            whole = None
        send(("error", "coronary", f"{cls.__module__}.{cls.__qualname__}",
              " ".join(str(exc).split()), whole))
        return 2
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which decides
        send(("error", "internal", type(exc).__name__, " ".join(str(exc).split())))
        return 1
    send(("result", value))
    return 0


def _child(frames: Any, err: Any, target: str, args: tuple, wants_progress: bool) -> None:
    """A forked child's main (``frames``, ``err``: the pipes' ends)."""
    _die_with_parent()
    os.dup2(err.fileno(), 2)  # standard error (the limit watchdog's line) to the parent
    os.dup2(2, 1)  # stray prints too
    code = _run_target(target, args, wants_progress, frames.send)
    sys.stderr.flush()
    if code:
        os._exit(code)


def _fresh_child() -> int:
    """A fresh interpreter's main: the job on stdin, the frames on stdout."""
    _die_with_parent()
    frames = os.fdopen(os.dup(1), "wb")  # the frames' channel; stray prints go to stderr
    os.dup2(2, 1)
    target, args, wants_progress = pickle.loads(sys.stdin.buffer.read())
    return _run_target(target, args, wants_progress, lambda f: _write_frame(frames, f))


def _viewer_job_limits(angio_a: Angiogram, angio_b: Angiogram, memory_gb: float | None,
                       cpu_s: float | None):
    """A viewer job's limits in its child process: for views of this size (or the ones
    given); a breach ends the process (``hard_exit``)."""
    from recon.io.limits import job_limits, limits_for

    pixels = max(angio_a.image.size, angio_b.image.size)
    return job_limits(limits_for(pixels, memory_gb, cpu_s), hard_exit=True)


def reconstruct_limited(angio_a: Angiogram, angio_b: Angiogram, seeds: Seeds,
                        options: ReconstructionOptions,
                        vesselness: tuple[VesselnessMap, VesselnessMap] | None = None,
                        memory_gb: float | None = None, cpu_s: float | None = None,
                        progress: Progress | None = None) -> Reconstruction:
    """``reconstruct_pair`` under the job's limits (for views of this size, or the ones
    given): the viewer's Reconstruct, through :func:`run_isolated`."""
    from recon.pipeline import reconstruct_pair

    with _viewer_job_limits(angio_a, angio_b, memory_gb, cpu_s):
        return reconstruct_pair(angio_a, angio_b, seeds, options, progress=progress,
                                vesselness=vesselness)


def reconstruct_tree_limited(angio_a: Angiogram, angio_b: Angiogram, seeds: Seeds,
                             options: ReconstructionOptions,
                             vesselness: tuple[VesselnessMap, VesselnessMap] | None = None,
                             memory_gb: float | None = None, cpu_s: float | None = None,
                             progress: Progress | None = None) -> TreeReconstruction:
    """``reconstruct_tree`` (every segment of ``seeds``) under the job's limits, as
    :func:`reconstruct_limited`: the viewer's Reconstruct of several segments."""
    from recon.tree import reconstruct_tree

    with _viewer_job_limits(angio_a, angio_b, memory_gb, cpu_s):
        return reconstruct_tree(angio_a, angio_b, seeds, options, progress=progress,
                                vesselness=vesselness)


if __name__ == "__main__":
    sys.exit(_fresh_child())
