"""bench intervals (coverage bookkeeping, resumable checkpoint) and bench sections."""

from __future__ import annotations

import json

import numpy as np
import pytest

from recon.bench import intervals, sections


def _row(seed: int, covered: bool) -> dict:
    fig = {"value": 1.0, "true": 1.0 if covered else 2.0, "lo": 0.9, "hi": 1.1,
           "covered": covered, "width": 0.2, "z": 0.0 if covered else 19.6}
    return {"preset": "data1", "seed": seed, "stenosis_pct": 50.0, "correction": "full",
            "wall_ms": 1.0, "intervals_ms": 2.0, **{k: dict(fig) for k in intervals.KEYS}}


def test_a_checkpointed_case_is_not_run_again_and_counts(tmp_path) -> None:
    path = tmp_path / "cases.jsonl"
    outcomes = [[_row(0, True), None], [None, {"preset": "data2", "seed": 1, "error": "x"}],
                [_row(2, False), None]]
    presets = ("data1", "data2", "data3")
    for (row, fail), preset in zip(outcomes, presets, strict=True):
        (row or fail)["preset"] = preset
    path.write_text("".join(json.dumps(o) + "\n" for o in outcomes))
    result = intervals.run(cases=3, checkpoint=str(path))  # nothing left to run
    assert result["cases"] == 2 and len(result["failures"]) == 1
    assert result["coverage"] == {k: 0.5 for k in intervals.KEYS}
    assert result["median_width"]["mld_mm"] == pytest.approx(0.2)
    assert "mld_mm" in intervals.format_table(result)


def test_two_widths_leave_the_area_open() -> None:
    """A 2 x 1 mm ellipse at 30 degrees seen along 0 and 70 degrees: its area lies in the
    range of the ellipses fitting both widths, and that range is wide (the ambiguity)."""
    a, b, phi = 2.0, 1.0, np.deg2rad(30.0)

    def support(t: float) -> float:
        return float(np.sqrt(a**2 * np.cos(t - phi) ** 2 + b**2 * np.sin(t - phi) ** 2))

    theta = np.deg2rad(70.0)
    lo, hi = sections.feasible_area_range(np.array([support(0.0)]), np.array([support(theta)]),
                                          np.array([theta]), max_ratio=2.5)
    assert lo[0] <= np.pi * a * b <= hi[0]
    assert hi[0] / lo[0] > 1.3


def test_bench_sections_measures_the_error_per_eccentricity(monkeypatch) -> None:
    monkeypatch.setattr(sections, "_GEOMETRY_PER_IMAGE", 10_000)  # geometry only here
    result = sections.run(cases=600, seed=1)
    assert set(result["bins"]) == {"1.0-1.5", "1.5-2.0", "2.0-2.5"}
    assert sum(b["cases"] for b in result["bins"].values()) == result["cases"] == 600
    near_circle, flat = result["bins"]["1.0-1.5"], result["bins"]["2.0-2.5"]
    assert near_circle["median_abs_area_error_pct"] < flat["median_abs_area_error_pct"]
    assert near_circle["truth_in_ambiguity_range"] > 0.95
    assert result["images"]["cases"] == 0


def test_bench_sections_through_rendered_images(monkeypatch) -> None:
    monkeypatch.setattr(sections, "_GEOMETRY_PER_IMAGE", 10)
    result = sections.run(cases=20, seed=3)
    images = result["images"]
    assert images["cases"] + images["failed"] == 2
    assert images["cases"] >= 1 and images["calibrated_share"] == 1.0
    assert "through rendered images" in sections.format_table(result)
