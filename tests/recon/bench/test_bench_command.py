"""`coronary3d bench`'s arguments to the bench function and its keywords
(recon.bench.command.bench_call)."""

from __future__ import annotations

import argparse

import pytest

from recon.bench.command import add_bench_parser, bench_call


def _call(*argv: str):
    parser = argparse.ArgumentParser()
    add_bench_parser(parser.add_subparsers(dest="command"))
    return bench_call(parser.parse_args(["bench", *argv]))


@pytest.mark.parametrize("suite", ["tree", "tree-varied"])
def test_the_tree_suites_take_the_tracer(suite: str) -> None:
    run, _, kwargs = _call("reconstruct", "--suite", suite, "--tracer", "3d", "--seed", "7")
    assert run.__name__ == "run_tree"
    assert kwargs == {"cases": None, "seed": 7, "suite": suite, "tracer": "3d"}
    _, _, kwargs = _call("reconstruct", "--suite", suite)
    assert kwargs["tracer"] == "2d"


def test_the_varied_suite_takes_the_tracer() -> None:
    run, _, kwargs = _call("reconstruct", "--suite", "varied", "--tracer", "3d")
    assert run.__name__ == "run" and kwargs["tracer"] == "3d"


@pytest.mark.parametrize("name", ["speed", "centerline", "ffr"])
def test_the_tracer_is_refused_by_other_benches(name: str) -> None:
    with pytest.raises(ValueError, match="--tracer is for bench reconstruct"):
        _call(name, "--tracer", "3d")
