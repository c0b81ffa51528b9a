"""Running many cases on Dask: a local cluster, or an existing one by its address.

:func:`dask_client` opens a ``dask.distributed`` client: with no scheduler
address, on a ``LocalCluster`` of ``workers`` processes with one thread each
(the pipeline is single-threaded numpy; one case per process is what
scales); with ``scheduler="tcp://host:8786"``, on that cluster's workers,
which must have coronary3d installed and see the case files at the same
paths. :func:`run_batch` is `coronary3d batch`: it skips the cases already
recorded, runs the others as tasks of :func:`recon.io.batch.run_case`,
reports each as it completes and writes the results table.
:func:`map_ordered` is the same engine for the benchmarks.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from recon.errors import CoronaryError
from recon.io.batch import (
    batch_lock,
    failed_record,
    read_record,
    run_case,
    sweep_leftovers,
    write_case_folder,
    write_results,
)
from recon.io.manifest import BatchCase

__all__ = ["EngineError", "BatchSummary", "dask_client", "run_batch", "map_ordered"]


class EngineError(CoronaryError):
    """A cluster that cannot be reached or started; one line naming the address."""


@dataclass
class BatchSummary:
    """What one `coronary3d batch` run did, and every case's record in manifest order."""

    run: int = 0
    skipped: int = 0
    done: int = 0
    failed: int = 0
    dashboard: str | None = None
    swept: list[str] = field(default_factory=list)
    records: list[dict] = field(default_factory=list)
    tables: list[Path] = field(default_factory=list)


@contextlib.contextmanager
def dask_client(workers: int | None = None, scheduler: str | None = None) -> Iterator[Any]:
    """A connected ``distributed.Client`` (closed, with its local cluster, on exit).

    Raises :class:`EngineError` when the scheduler cannot be reached or
    ``workers`` is below 1.
    """
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as exc:
            text = " ".join(str(exc).split())
            raise EngineError(f"{scheduler}: cannot reach the Dask scheduler ({text})") from None
        try:
            yield client
        finally:
            client.close()
        return
    n = 1 if workers is None else int(workers)
    if n < 1:
        raise EngineError(f"--workers {n}: give at least 1")
    with LocalCluster(
        n_workers=n,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0" if _has_dashboard() else None,
        silence_logs=logging.ERROR,
    ) as cluster, Client(cluster) as client:
        yield client


def run_batch(
    cases: Sequence[BatchCase],
    out_dir: Path,
    *,
    formats: tuple[str, ...] = ("stl",),
    sr: bool = False,
    workers: int | None = None,
    scheduler: str | None = None,
    retry_failed: bool = False,
    on_start: Callable[[BatchSummary, int], None] | None = None,
    on_case: Callable[[dict, int, int], None] | None = None,
    limits: tuple[float | None, float | None] = (None, None),
) -> BatchSummary:
    """Run the cases that have no record yet (and the failed ones with ``retry_failed``).

    ``on_start(summary, n_to_run)`` is called once the client is up (its
    dashboard address is in ``summary.dashboard``), ``on_case(record,
    completed, n_to_run)`` as each case completes. The results table
    (:func:`recon.io.batch.write_results`) covers every case of the
    manifest that has a record. ``limits`` is (``--max-memory-gb``,
    ``--max-cpu-s``) of every case (None: the default for its image size).

    The folder is held (:func:`recon.io.batch.batch_lock`) for the whole run,
    and what a killed earlier run left in it is swept first
    (:func:`recon.io.batch.sweep_leftovers`; their names in ``summary.swept``).
    """
    out_dir = Path(out_dir)
    with batch_lock(out_dir):
        return _run_batch(cases, out_dir, formats, sr, workers, scheduler, retry_failed,
                          on_start, on_case, limits)


def _run_batch(
    cases: Sequence[BatchCase],
    out_dir: Path,
    formats: tuple[str, ...],
    sr: bool,
    workers: int | None,
    scheduler: str | None,
    retry_failed: bool,
    on_start: Callable[[BatchSummary, int], None] | None,
    on_case: Callable[[dict, int, int], None] | None,
    limits: tuple[float | None, float | None],
) -> BatchSummary:
    summary = BatchSummary()
    summary.swept = sweep_leftovers(out_dir, [case.id for case in cases])
    todo: list[BatchCase] = []
    for case in cases:
        record = read_record(out_dir, case.id)
        if record is None or (retry_failed and record["status"] == "failed"):
            todo.append(case)
        else:
            summary.skipped += 1
    fresh: dict[str, dict] = {}
    if todo:
        with dask_client(workers, scheduler) as client:
            summary.dashboard = _dashboard(client)
            if on_start is not None:
                on_start(summary, len(todo))
            fresh = _run_on(client, todo, out_dir, formats, sr, limits, on_case)
    elif on_start is not None:
        on_start(summary, 0)
    summary.run = len(fresh)
    for case in cases:
        record = fresh.get(case.id) or read_record(out_dir, case.id)
        if record is not None:
            summary.records.append(record)
    summary.done = sum(r["status"] == "done" for r in summary.records)
    summary.failed = sum(r["status"] == "failed" for r in summary.records)
    summary.tables = write_results(out_dir, summary.records)
    return summary


def _run_on(client, todo, out_dir, formats, sr, limits, on_case) -> dict[str, dict]:
    from distributed import as_completed

    futures = {
        client.submit(run_case, case, str(out_dir), formats, sr, limits, key=f"case-{case.id}-{k}",
                      pure=False): case
        for k, case in enumerate(todo)
    }
    records: dict[str, dict] = {}
    for future in as_completed(futures):
        case = futures[future]
        try:
            record = future.result()
        except Exception as exc:  # the worker died, or the case folder could not be written
            text = " ".join(str(exc).split()) or type(exc).__name__
            record = failed_record(case.id, f"{type(exc).__name__}: {text}")
            with contextlib.suppress(CoronaryError):
                write_case_folder(out_dir, case.id, {}, record)
        records[case.id] = record
        if on_case is not None:
            on_case(record, len(records), len(todo))
    return records


def map_ordered(
    fn: Callable[[Any], Any], items: Sequence[Any], workers: int = 1, scheduler: str | None = None
) -> list[Any]:
    """``[fn(x) for x in items]`` computed as Dask tasks, in the items' order.

    ``fn`` must be a module-level function the workers can import.
    """
    with dask_client(workers, scheduler) as client:
        futures = client.map(fn, list(items), pure=False)
        return client.gather(futures)


def _has_dashboard() -> bool:
    try:
        import bokeh  # noqa: F401  (the dashboard needs it: the [batch] extra)
    except ImportError:
        return False
    return True


def _dashboard(client) -> str | None:
    if not _has_dashboard():
        return None
    try:
        return str(client.dashboard_link)
    except (AttributeError, KeyError):
        return None
