"""`coronary3d bench speed` with one repetition: every key, positive and finite."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import pytest

from recon.cli import main

KEYS = ("floor_s", "cold_s", "cold_over_floor", "warm_ms", "viewer_reconstruct_ms",
        "click_ms", "peak_mb", "floor_cpu_s", "cold_cpu_s", "cold_over_floor_cpu")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="ru_maxrss in kB (Linux)")
def test_bench_speed_one_repetition_writes_every_figure(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / "speed.json"
    assert main(["bench", "speed", "--cases", "1", "--json", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["repetitions"] == 1
    for key in KEYS:
        value = result[key]
        assert isinstance(value, float) and math.isfinite(value) and value > 0, (key, value)
        if not key.startswith("cold_over_floor"):
            assert len(result["runs"][key]) == 1
    assert result["cold_over_floor"] == pytest.approx(result["cold_s"] / result["floor_s"])
    # the cold job does more than importing the floor's modules, and the peak is a process's
    assert result["cold_s"] > result["floor_s"]
    assert result["cold_cpu_s"] > result["floor_cpu_s"]
    # the cold process's own peak (VmHWM), above the floor's ~0.1 GB of libraries
    assert 100.0 < result["peak_mb"] < 4000.0
    stages = result["stages_ms"]
    assert {"trace", "calibrate", "match", "triangulate", "surface", "measure"} <= set(stages)
    assert all(math.isfinite(v) and v >= 0 for v in stages.values())
    assert sum(stages.values()) == pytest.approx(result["warm_ms"], rel=0.01, abs=0.1)
    assert set(result["thread_env"]) == {"OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                         "MKL_NUM_THREADS"}
    assert "median cold_over_floor" in capsys.readouterr().out
