"""bench reconstruct --workers: the same cases through the Dask engine, the same figures."""

from __future__ import annotations

import pytest

from recon.bench import reconstruct


def test_the_cases_on_two_dask_workers_give_the_serial_rows() -> None:
    serial = reconstruct.run(cases=2, seed=0)
    on_dask = reconstruct.run(cases=2, seed=0, workers=2)
    assert on_dask["workers"] == 2 and serial["workers"] is None
    assert on_dask["cases"] == serial["cases"] == 2
    for a, b in zip(serial["rows"], on_dask["rows"], strict=True):  # in the cases' order
        assert (a["preset"], a["seed"]) == (b["preset"], b["seed"])
        # equal to rounding: a Dask worker runs its BLAS on one thread
        assert b["mld_mm"] == pytest.approx(a["mld_mm"], rel=1e-6)
        assert b["centerline_3d_rms_mm"] == pytest.approx(a["centerline_3d_rms_mm"], rel=1e-6)
    assert on_dask["cases_per_minute"] > 0
    assert "cases per minute on 2 Dask worker(s)" in reconstruct.format_table(on_dask)
