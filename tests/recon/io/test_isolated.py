"""recon.io.isolated: a job in a child process of its own, under the job's limits; and the
limits of a batch case (run_case, as a Dask worker runs it)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from support import DEMO

from recon.errors import CoronaryError, LoadError
from recon.io.batch import run_case
from recon.io.isolated import JobFailed, run_isolated
from recon.io.limits import LimitError
from recon.io.manifest import BatchCase


def test_the_value_and_the_errors_come_back_from_the_child() -> None:
    assert run_isolated("recon.io.limits:limits_for", (512 * 512, 0.5, 7.0)).cpu_s == 7.0
    with pytest.raises(LoadError, match=r"^nope\.dcm: no such file$"):
        run_isolated("recon.io.angiogram:load_angiogram", ("nope.dcm",))
    with pytest.raises(JobFailed, match=r"^ModuleNotFoundError: No module named 'nowhere'"):
        run_isolated("nowhere:f", ())
    from recon.io.demo import demo_paths

    angio = run_isolated("recon.io.angiogram:load_angiogram", (str(demo_paths()["a"]),))
    assert angio.image.shape == (512, 512)


def test_a_refused_trace_comes_back_with_its_view_and_place() -> None:
    """A TraceError from the child keeps what the viewer rings: the view and the place."""
    import numpy as np

    from recon.trace.trace_error import TraceError

    blank = np.full((60, 60), 100.0)  # no vessel: the first click is refused
    with pytest.raises(TraceError, match=r"^view A: click 1 \(proximal end\): ") as info:
        run_isolated("recon.trace.centerline:trace_segment", (blank, [(10.0, 12.0), (40.0, 45.0)]))
    assert info.value.view == "A"
    np.testing.assert_allclose(info.value.near_px, (10.0, 12.0))


def _demo():
    from recon.io.angiogram import load_angiogram
    from recon.io.demo import demo_paths
    from recon.io.seeds_file import load_seeds
    from recon.pipeline import ReconstructionOptions

    demo = demo_paths()
    return (load_angiogram(str(demo["a"])), load_angiogram(str(demo["b"])),
            load_seeds(str(demo["seeds"])), ReconstructionOptions())


def test_the_viewers_reconstruction_runs_under_its_limits_and_relays_progress() -> None:
    seen: list[tuple[str, float]] = []
    rec = run_isolated("recon.io.isolated:reconstruct_limited", (*_demo(), None),
                       progress=lambda stage, f: seen.append((stage, f)))
    assert 1.0 < rec.measurements.mld_mm < 2.0 and len(rec.surface.mesh.faces) > 100
    assert seen[-1][1] == 1.0 and len({s for s, _ in seen}) > 3
    # The demo's job takes ~0.4 s of CPU on a fast idle machine (its trace alone).
    with pytest.raises(LimitError, match=r"CPU-time limit of 0\.1 s \(--max-cpu-s\)$"):
        run_isolated("recon.io.isolated:reconstruct_limited", (*_demo(), None, None, 0.1))
    with pytest.raises(LimitError, match=r"limit of 0\.02 GB \(--max-memory-gb"):
        run_isolated("recon.io.isolated:reconstruct_limited", (*_demo(), None, 0.02, None))


def test_a_child_ended_by_a_signal_says_so() -> None:
    with pytest.raises(CoronaryError, match=r"^the job was ended by SIGABRT$"):
        run_isolated("os:abort", (), what="the job")


def _case(tmp_path: Path, case_id: str) -> BatchCase:
    for name in ("a.dcm", "b.dcm", "seeds.json"):
        if not (tmp_path / name).exists():
            shutil.copy(DEMO / name, tmp_path / name)
    return BatchCase(id=case_id, a=str(tmp_path / "a.dcm"), b=str(tmp_path / "b.dcm"),
                     seeds=str(tmp_path / "seeds.json"), line=2)


def test_a_batch_case_past_its_memory_limit_fails_saying_which(tmp_path: Path) -> None:
    record = run_case(_case(tmp_path, "m"), str(tmp_path / "out"), ("stl",), False,
                      (0.02, None))
    assert record["status"] == "failed"
    assert "needed more memory than its limit of 0.02 GB (--max-memory-gb" in record["error"]
    assert record["error"].count("\n") == 0
    assert sorted(p.name for p in (tmp_path / "out" / "m").iterdir()) == ["case.json"]
