"""One case of a batch, its record, and the batch's results table.

:func:`run_case` reconstructs one manifest row and writes its outputs into
``DIR/<id>/`` as a whole: the files are written into a hidden temporary
folder, its record ``case.json`` last, and the folder is renamed into place,
so ``DIR/<id>/`` either holds a complete case or does not exist (a crash
midway leaves a hidden ``DIR/.<id>.*`` folder that the next run ignores).
A failed case leaves ``DIR/<id>/case.json`` alone, with its one-line error.
``case.json`` is what makes a rerun resumable: a case with one is skipped.

The record and the results table carry no patient data: ids, statuses,
errors (which name files, never patient fields), measurements, calibration
figures, timings, the worker, the software version.
"""

from __future__ import annotations

import csv
import io
import json
import os
import resource
import shutil
import socket
import tempfile
import time
from pathlib import Path

from recon import __version__
from recon.errors import CoronaryError, OutputError
from recon.io.files import atomic_write_bytes
from recon.io.manifest import BatchCase

__all__ = [
    "CASE_RECORD",
    "RESULT_COLUMNS",
    "run_case",
    "failed_record",
    "read_record",
    "write_results",
]

CASE_RECORD = "case.json"

MEASUREMENT_KEYS = (
    "mld_mm",
    "reference_diameter_mm",
    "diameter_stenosis_pct",
    "area_stenosis_pct",
    "mla_mm2",
    "lesion_length_mm",
    "segment_length_mm",
)

RESULT_COLUMNS = (
    "id",
    "status",
    "error",
    *MEASUREMENT_KEYS,
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


def run_case(case: BatchCase, out_dir: str, formats: tuple[str, ...], sr: bool) -> dict:
    """Reconstruct one case into ``out_dir/<id>/``; its record (a dict of RESULT_COLUMNS).

    Never raises for a case's own failure: a :class:`CoronaryError` (a bad
    file, click or geometry) becomes a failed record with its message, any
    other exception a failed record "internal error: Type: message". An
    output folder that cannot be written raises :class:`OutputError`.
    """
    t0 = time.perf_counter()
    try:
        record, files = _reconstruct(case, formats, sr)
    except CoronaryError as exc:
        record, files = failed_record(case.id, str(exc)), {}
    except Exception as exc:  # a bug in one case must not stop a thousand-case batch
        text = " ".join(str(exc).split())
        record, files = failed_record(case.id, f"internal error: {type(exc).__name__}: {text}"), {}
    record["case_s"] = round(time.perf_counter() - t0, 3)
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


def _reconstruct(case: BatchCase, formats: tuple[str, ...], sr: bool) -> tuple[dict, dict]:
    from recon.io.angiogram import load_angiogram
    from recon.io.outputs import outputs_as_bytes
    from recon.io.seeds_file import load_seeds
    from recon.pipeline import ReconstructionOptions, reconstruct_pair

    opt = case.options
    angio_a = load_angiogram(case.a, frame=opt.get("frame_a"), geometry_json=opt.get("geometry_a"))
    angio_b = load_angiogram(case.b, frame=opt.get("frame_b"), geometry_json=opt.get("geometry_b"))
    seeds = load_seeds(case.seeds)
    sources = None
    if sr:
        from recon.io.sr import read_sr_sources

        frames = (angio_a.frame_index + 1, angio_b.frame_index + 1)
        sources = read_sr_sources(case.a, case.b, frames)
    keys = ("matcher", "optimizer", "segment", "self_calibration", "intensity_a", "intensity_b")
    options = ReconstructionOptions(**{k: opt[k] for k in keys if k in opt})
    rec = reconstruct_pair(angio_a, angio_b, seeds, options)
    files = outputs_as_bytes(rec, formats, sources)
    files.pop("seeds.json")
    report = json.loads(files["report.json"])
    cal = report["calibration"]
    record: dict = dict.fromkeys(RESULT_COLUMNS)
    record.update({key: report["measurements"][key] for key in MEASUREMENT_KEYS})
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
    return record, files


def write_case_folder(out_dir: Path, case_id: str, files: dict[str, bytes], record: dict) -> None:
    """``out_dir/<id>/`` holding ``files`` and ``case.json``, replaced as a whole.

    Raises :class:`OutputError` naming the folder when it cannot be written.
    """
    final = out_dir / case_id
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{case_id}.", dir=out_dir))
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
    """``results.csv`` and, when pyarrow is installed, ``results.parquet``: one row per case.

    Returns the paths written.
    """
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=RESULT_COLUMNS, extrasaction="ignore",
                            lineterminator="\n")
    writer.writeheader()
    for record in records:
        writer.writerow({k: ("" if record.get(k) is None else record[k]) for k in RESULT_COLUMNS})
    paths = [Path(out_dir) / "results.csv"]
    atomic_write_bytes(paths[0], buf.getvalue().encode())
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:  # the [batch] extra is not installed
        return paths
    table = pa.Table.from_pylist(
        [{k: r.get(k) for k in RESULT_COLUMNS} for r in records], schema=_parquet_schema(pa)
    )
    sink = io.BytesIO()
    pq.write_table(table, sink)
    paths.append(Path(out_dir) / "results.parquet")
    atomic_write_bytes(paths[1], sink.getvalue())
    return paths


def _parquet_schema(pa):
    text = ("id", "status", "error", "worker", "software_version")
    ints = ("calibration_iterations", "warnings")
    return pa.schema(
        [
            (name, pa.string() if name in text else pa.int64() if name in ints else pa.float64())
            for name in RESULT_COLUMNS
        ]
    )


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask
