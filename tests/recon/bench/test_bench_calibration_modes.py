"""bench calibration-modes: the scale-free 3D error per calibration mode against the header."""

from __future__ import annotations

import numpy as np
import pytest

from recon.bench import calibration_modes as cm
from recon.bench.common import scale_free_error_mm


def test_the_baseline_scale_is_removed_and_nothing_else() -> None:
    rng = np.random.default_rng(0)
    source = np.array([0.0, -800.0, 0.0])
    X = rng.uniform(-30.0, 30.0, (50, 3))
    scaled = source + 1.02 * (X - source)
    err, k = scale_free_error_mm(scaled, X, source)
    assert err == pytest.approx(0.0, abs=1e-9) and k == pytest.approx(1 / 1.02)
    shifted = X + np.array([0.5, 0.0, 0.0])  # a shift across the rays is an error
    assert scale_free_error_mm(shifted, X, source)[0] > 0.3


def _row(seed: int, errors: dict) -> dict:
    return {"chain": "regular", "preset": "data1", "seed": seed, "features": 4,
            **{m: {"error_mm": e, "scale": 1.0, "rotation_error_deg": 1.0,
                   "pose_error_mm": 5.0, "ms": 1.0,
                   "extra": "full" if m == "supported" else None}
               for m, e in errors.items()}}


def test_the_fractions_count_the_margin() -> None:
    rows = [_row(0, {"header": 1.0, "full": 1.05, "supported": 1.0, "curves": 0.5}),
            _row(1, {"header": 1.0, "full": 1.2, "supported": 0.9, "curves": 0.5}),
            {"chain": "regular", "preset": "data2", "seed": 2, "error": "TraceError: x"}]
    result = cm.summarise(rows, "regular")
    assert result["cases"] == 2 and len(result["failures"]) == 1
    full = result["modes"]["full"]
    assert full["no_worse_fraction"] == 0.5 and full["lower_fraction"] == 0.0
    assert full["worse_cases"] == ["data1/1"]
    assert result["modes"]["curves"]["median_change_mm"] == pytest.approx(-0.5)
    assert result["supported_chose"] == {"full": 2}
    assert "curves" in cm.format_table(result)


def test_two_phantom_cases_run_in_every_mode() -> None:
    result = cm.run(cases=2, workers=1)
    assert result["cases"] + len(result["failures"]) == 2
    assert set(result["modes"]) == set(cm.MODES)
    assert result["modes"]["header"]["no_worse_fraction"] == 1.0
    for row in result["rows"]:
        assert row["header"]["rotation_error_deg"] > 0.5  # the phantom's header is off


def test_the_command_line_takes_the_bench_and_the_curves_mode() -> None:
    from recon.cli import build_parser

    args = build_parser().parse_args(["bench", "calibration-modes", "--suite", "varied",
                                      "--workers", "2", "--cases", "1"])
    assert (args.name, args.suite, args.workers) == ("calibration-modes", "varied", 2)
    args = build_parser().parse_args(["reconstruct", "--demo", "--out", "o",
                                      "--calibration", "curves"])
    assert args.calibration == "curves"
