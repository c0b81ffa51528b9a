"""One case of a batch, its record, and the batch's results table.

:func:`run_case` reconstructs one manifest row and writes its outputs into
``DIR/<id>/`` as a whole: the files are written into a hidden temporary
folder, its record ``case.json`` last, and the folder is renamed into place,
so ``DIR/<id>/`` either holds a complete case or does not exist. A process
killed midway (SIGKILL, a lost node) leaves its hidden temporary folder
``DIR/.<id>.tmp-<host>-<pid>-<random>``: :func:`sweep_leftovers`, called by
the next batch in the folder before any case runs, removes those whose
writer is gone (a process of this host that no longer exists; any of
another host, since :func:`batch_lock` says no other batch is writing).
A failed case leaves ``DIR/<id>/case.json`` alone, with its one-line error.
``case.json`` is what makes a rerun resumable: a case with one is skipped.

The record and the results table carry no patient data: ids, statuses,
errors (which name files, never patient fields), measurements, calibration
figures, timings, the worker, the software version.
"""

from __future__ import annotations

import contextlib
import csv
import fcntl
import io
import json
import os
import re
import resource
import secrets
import shutil
import socket
import time
from collections.abc import Iterable, Iterator
from pathlib import Path

from recon import __version__
from recon.errors import CoronaryError, LoadError, OutputError
from recon.io.files import atomic_write_bytes
from recon.io.manifest import BatchCase
from recon.io.output_set import _alive

__all__ = [
    "CASE_RECORD",
    "RESULT_COLUMNS",
    "FFR_KEYS",
    "ffr_columns",
    "run_case",
    "batch_lock",
    "sweep_leftovers",
    "failed_record",
    "read_record",
    "write_results",
    "result_rows",
    "reconstruct_case",
]

CASE_RECORD = "case.json"

# .<id>.tmp-<host>-<pid>-<8 hex>: a case folder being written (write_case_folder)
_TEMP_DIR_RE = re.compile(
    r"^\.(?P<id>[A-Za-z0-9_\-][A-Za-z0-9_.\-]*)\.tmp-(?P<host>[A-Za-z0-9-]+)-(?P<pid>\d+)"
    r"-[0-9a-f]{8}$"
)
# .<id>.<8 chars>: tempfile.mkdtemp's name, used before the host and pid were in the name
_OLD_TEMP_DIR_RE = re.compile(r"^\.(?P<id>.+)\.[a-z0-9_]{8}$")
# .results.csv.<random>.tmp: atomic_write_bytes of the results table
_TABLE_TEMP_RE = re.compile(r"^\.results\.(?:csv|parquet)\.[A-Za-z0-9_]+\.tmp$")

MEASUREMENT_KEYS = (
    "mld_mm",
    "reference_diameter_mm",
    "diameter_stenosis_pct",
    "area_stenosis_pct",
    "mla_mm2",
    "lesion_length_mm",
    "segment_length_mm",
)
#: The FFR (recon.lumen.ffr; a model estimate for research) at the segment's distal end and
#: its 95 % interval, from report.json's ``ffr`` block; empty where it was not computed.
FFR_KEYS = ("ffr_distal", "ffr_ci95_lo", "ffr_ci95_hi")

RESULT_COLUMNS = (
    "id",
    "status",
    "error",
    "branch_id",
    "branch",
    "parent",
    *MEASUREMENT_KEYS,
    *FFR_KEYS,
    "calibration_error_before_px",
    "calibration_error_after_px",
    "calibration_rotation_deg",
    "calibration_iterations",
    "warnings",
    "pipeline_ms",
    "case_s",
    "worker_peak_rss_mb",
    "worker",
    "software_version",
)


def run_case(case: BatchCase, out_dir: str, formats: tuple[str, ...], sr: bool,
             limits: tuple[float | None, float | None] = (None, None)) -> dict:
    """Reconstruct one case into ``out_dir/<id>/``; its record (a dict of RESULT_COLUMNS,
    and ``branches`` for a done case).

    The case runs in a child process of its own (:mod:`recon.io.isolated`)
    under the job's limits, ``limits`` = (``--max-memory-gb``, ``--max-cpu-s``),
    None for the defaults of its image size (:func:`recon.io.limits.limits_for`):
    a case that reaches one fails with the line saying which, and the worker
    goes on. Never raises for a case's own failure: a :class:`CoronaryError`
    (a bad file, click or geometry, a limit) becomes a failed record with its
    message, any other exception a failed record "internal error: Type:
    message". An output folder that cannot be written raises
    :class:`OutputError`.
    """
    from recon.io.isolated import JobFailed, run_isolated

    t0 = time.perf_counter()
    try:
        record, files = run_isolated("recon.io.batch:reconstruct_case",
                                     (case, tuple(formats), sr, *limits),
                                     what=f"case {case.id}")
    except CoronaryError as exc:
        record, files = failed_record(case.id, str(exc)), {}
    except JobFailed as exc:  # a bug in one case must not stop a thousand-case batch
        record, files = failed_record(case.id, f"internal error: {exc}"), {}
    except Exception as exc:  # the same, on this side of the child
        text = " ".join(str(exc).split())
        record, files = failed_record(case.id, f"internal error: {type(exc).__name__}: {text}"), {}
    record["case_s"] = round(time.perf_counter() - t0, 3)
    if record.get("worker_peak_rss_mb") is None:  # no case process got far enough to say
        peak_kib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss  # Linux: KiB
        record["worker_peak_rss_mb"] = round(peak_kib / 1024, 1)
    record["worker"] = f"{socket.gethostname()}:{os.getpid()}"
    write_case_folder(Path(out_dir), case.id, files, record)
    return record


def failed_record(case_id: str, error: str) -> dict:
    """The record of a failed case: every column present, the error on one line."""
    record: dict = dict.fromkeys(RESULT_COLUMNS)
    record.update(id=case_id, status="failed", error=" ".join(error.split()),
                  software_version=__version__)
    return record


def reconstruct_case(case: BatchCase, formats: tuple[str, ...], sr: bool,
                     memory_gb: float | None = None,
                     cpu_s: float | None = None) -> tuple[dict, dict[str, bytes]]:
    """One case's record and output files (name -> bytes), as ``coronary3d reconstruct``
    makes them: loading and reconstruction each under the job's limits (the ones given,
    else the defaults for the files' and images' sizes), every segment of the seeds as
    one tree unless the manifest's ``segment`` names one. Runs in the main thread of a
    case's own process (:func:`run_case`)."""
    from recon.io.angiogram import load_angiogram
    from recon.io.limits import job_limits, limits_for
    from recon.io.outputs import outputs_as_bytes
    from recon.io.seeds_file import load_seeds
    from recon.pipeline import ReconstructionOptions, reconstruct_pair
    from recon.tree import reconstruct_tree

    opt = case.options
    file_px = max(_file_bytes(case.a), _file_bytes(case.b)) // 2  # as the command line
    with job_limits(limits_for(file_px, memory_gb, cpu_s), "loading", hard_exit=True):
        angio_a = load_angiogram(case.a, frame=opt.get("frame_a"),
                                 geometry_json=opt.get("geometry_a"))
        angio_b = load_angiogram(case.b, frame=opt.get("frame_b"),
                                 geometry_json=opt.get("geometry_b"))
    seeds = load_seeds(case.seeds)
    segment = opt.get("segment")
    if segment is not None and not 0 <= int(segment) < len(seeds.segments):
        raise LoadError(f"{case.seeds}: no segment {segment} (the manifest's segment column; "
                        f"segments 0 to {len(seeds.segments) - 1})")
    sources = None
    if sr:
        from recon.io.sr import read_sr_sources

        frames = (angio_a.frame_index + 1, angio_b.frame_index + 1)
        sources = read_sr_sources(case.a, case.b, frames)
    keys = ("matcher", "optimizer", "self_calibration", "intensity_a", "intensity_b")
    options = ReconstructionOptions(segment=int(segment or 0),
                                    **{k: opt[k] for k in keys if k in opt})
    pixels = max(angio_a.image.size, angio_b.image.size)
    with job_limits(limits_for(pixels, memory_gb, cpu_s), hard_exit=True):
        if segment is None:
            rec = reconstruct_tree(angio_a, angio_b, seeds, options)
        else:
            rec = reconstruct_pair(angio_a, angio_b, seeds, options)
        files = outputs_as_bytes(rec, formats, sources)
    files.pop("seeds.json")
    report = json.loads(files["report.json"])
    cal = report["calibration"]
    record: dict = dict.fromkeys(RESULT_COLUMNS)
    record.update({key: report["measurements"][key] for key in MEASUREMENT_KEYS})
    record.update(ffr_columns(report))
    record.update(
        id=case.id,
        status="done",
        error="",
        calibration_error_before_px=cal["error_before_px"],
        calibration_error_after_px=cal["error_after_px"],
        calibration_rotation_deg=cal["rotation_deg"],
        calibration_iterations=cal["iterations"],
        warnings=len(report["warnings"]),
        pipeline_ms=report["timings_ms"]["total"],
        software_version=__version__,
    )
    entries = report.get("branches") or [dict(report, branch_id=options.segment, parent=None)]
    record["branches"] = [
        {"branch_id": e["branch_id"], "branch": e["inputs"]["segment"], "parent": e["parent"],
         **{key: e["measurements"][key] for key in MEASUREMENT_KEYS}, **ffr_columns(e)}
        for e in entries
    ]
    record["worker_peak_rss_mb"] = round(
        resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1)  # this case's process
    return record, files


def ffr_columns(entry: dict) -> dict:
    """``ffr_distal``, ``ffr_ci95_lo``, ``ffr_ci95_hi`` of one report.json entry (the top
    level or one of ``branches``): its ``ffr`` block's ``distal`` and ``ci95``; None (an
    empty cell) where the FFR was not computed or has no interval."""
    block = entry.get("ffr") or {}
    ci = block.get("ci95") or (None, None)
    return {"ffr_distal": block.get("distal"), "ffr_ci95_lo": ci[0], "ffr_ci95_hi": ci[1]}


def _file_bytes(path: str) -> int:
    try:
        return os.stat(path).st_size
    except OSError:
        return 0  # the loader says what is wrong with it


def write_case_folder(out_dir: Path, case_id: str, files: dict[str, bytes], record: dict) -> None:
    """``out_dir/<id>/`` holding ``files`` and ``case.json``, replaced as a whole.

    Raises :class:`OutputError` naming the folder when it cannot be written.
    """
    final = out_dir / case_id
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        tmp = out_dir / f".{case_id}.tmp-{_host()}-{os.getpid()}-{secrets.token_hex(4)}"
        tmp.mkdir(mode=0o700)
    except OSError as exc:
        raise OutputError(f"{final}: cannot write the case ({exc.strerror or exc})") from None
    try:
        for name, data in files.items():
            atomic_write_bytes(tmp / name, data)
        atomic_write_bytes(tmp / CASE_RECORD, (json.dumps(record, indent=2) + "\n").encode())
        os.chmod(tmp, 0o777 & ~_umask())
        if final.exists():  # an earlier failed attempt (--retry-failed)
            shutil.rmtree(final)
        os.rename(tmp, final)
    except OSError as exc:
        raise OutputError(f"{final}: cannot write the case ({exc.strerror or exc})") from None
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)


@contextlib.contextmanager
def batch_lock(out_dir: Path) -> Iterator[None]:
    """Hold the batch folder (made if missing) for one batch: an exclusive ``flock`` on
    the folder itself, so no lock file is left behind. Raises :class:`OutputError` when
    the folder cannot be made or another batch holds it."""
    out_dir = Path(out_dir)
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(out_dir, os.O_RDONLY | os.O_DIRECTORY)
    except OSError as exc:
        raise OutputError(f"{out_dir}: cannot use the batch folder "
                          f"({exc.strerror or exc})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise OutputError(f"{out_dir}: another coronary3d batch is writing into this "
                              "folder; wait for it to end or give another --out") from None
        yield
    finally:
        os.close(fd)


def sweep_leftovers(out_dir: Path, case_ids: Iterable[str]) -> list[str]:
    """Remove the temporaries a killed earlier batch left in ``out_dir``; their names.

    Case folders being written (``.<id>.tmp-<host>-<pid>-...``) are removed
    unless their writer is a live process of this host; the older
    ``.<id>.<random>`` folders only for ids in ``case_ids``; the results
    table's temporaries always. Call it under :func:`batch_lock`.
    """
    ids, host, removed = set(case_ids), _host(), []
    try:
        entries = sorted(os.scandir(out_dir), key=lambda e: e.name)
    except FileNotFoundError:
        return removed
    except OSError as exc:
        raise OutputError(f"{out_dir}: cannot read the batch folder "
                          f"({exc.strerror or exc})") from None
    for entry in entries:
        if not entry.name.startswith("."):
            continue
        if entry.is_dir(follow_symlinks=False):
            m = _TEMP_DIR_RE.match(entry.name)
            if m is not None:
                pid = int(m["pid"])
                if m["host"] == host and pid != os.getpid() and _alive(pid):
                    continue  # a worker of this host is writing it right now
            else:
                old = _OLD_TEMP_DIR_RE.match(entry.name)
                if old is None or old["id"] not in ids:
                    continue
            shutil.rmtree(entry.path, ignore_errors=True)
        elif _TABLE_TEMP_RE.match(entry.name) and entry.is_file(follow_symlinks=False):
            with contextlib.suppress(FileNotFoundError):
                os.unlink(entry.path)
        else:
            continue
        removed.append(entry.name)
    return removed


def read_record(out_dir: Path, case_id: str) -> dict | None:
    """A case's record from an earlier run, or None when it has none (or an unreadable one)."""
    path = Path(out_dir) / case_id / CASE_RECORD
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(record, dict) or record.get("status") not in ("done", "failed"):
        return None
    return record


def write_results(out_dir: Path, records: list[dict]) -> list[Path]:
    """``results.csv`` and, when pyarrow is installed, ``results.parquet``: one row per
    case and branch (:func:`result_rows`).

    Returns the paths written.
    """
    rows = result_rows(records)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=RESULT_COLUMNS, extrasaction="ignore",
                            lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if row.get(k) is None else row[k]) for k in RESULT_COLUMNS})
    paths = [Path(out_dir) / "results.csv"]
    atomic_write_bytes(paths[0], buf.getvalue().encode())
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:  # the [batch] extra is not installed
        return paths
    table = pa.Table.from_pylist(
        [{k: r.get(k) for k in RESULT_COLUMNS} for r in rows], schema=_parquet_schema(pa)
    )
    sink = io.BytesIO()
    pq.write_table(table, sink)
    paths.append(Path(out_dir) / "results.parquet")
    atomic_write_bytes(paths[1], sink.getvalue())
    return paths


def result_rows(records: list[dict]) -> list[dict]:
    """The table's rows: a done case has one row per branch of its tree (``branch_id``
    its segment's index in seeds.json, ``branch`` its name, ``parent`` its parent's, the
    measurements the branch's; the case's columns repeated), in the seeds' order; a
    failed case, or a record written before branches, one row with them empty."""
    rows = []
    for record in records:
        branches = record.get("branches") or [{}]
        for branch in branches:
            row = {k: v for k, v in record.items() if k != "branches"}
            row.update({k: branch[k] for k in ("branch_id", "branch", "parent",
                                               *MEASUREMENT_KEYS, *FFR_KEYS) if k in branch})
            rows.append(row)
    return rows


def _parquet_schema(pa):
    text = ("id", "status", "error", "branch", "parent", "worker", "software_version")
    ints = ("branch_id", "calibration_iterations", "warnings")
    return pa.schema(
        [
            (name, pa.string() if name in text else pa.int64() if name in ints else pa.float64())
            for name in RESULT_COLUMNS
        ]
    )


def _host() -> str:
    """This host's name as it goes into a temporary folder's name (letters, digits, -)."""
    return re.sub(r"[^A-Za-z0-9-]", "-", socket.gethostname()) or "host"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
