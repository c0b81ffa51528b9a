"""The `coronary3d bench` command: its arguments, and which benchmark a command line runs.

The command line (:mod:`recon.cli`) prints and writes; this module only says what to run
(:func:`bench_call`), refusing a combination no benchmark has with a ValueError whose
message is the one-line error.
"""

from __future__ import annotations

import argparse
import importlib
from collections.abc import Callable

from recon.cli_inputs import number_arg

__all__ = ["BENCHES", "add_bench_parser", "bench_call"]

BENCHES = ("centerline", "calibration", "matching", "reconstruct", "speed", "intervals",
           "sections", "optimal-view", "calibration-modes", "ffr")
COUNT = number_arg(int, 1)
INDEX = number_arg(int, 0)


def add_bench_parser(sub) -> None:
    """The ``bench`` subcommand's arguments, on the command line's subparsers ``sub``."""
    p = sub.add_parser(
        "bench",
        help="accuracy and speed benchmarks against phantom ground truth",
        description="Run a benchmark on synthetic phantom cases, print a table, and write "
        "the figures as JSON.",
    )
    p.add_argument("name", choices=BENCHES)
    p.add_argument("--json", metavar="PATH", help="write the result here")
    p.add_argument(
        "--cases",
        type=COUNT,
        help="number of cases (per geometry for calibration, per imaging chain for "
        "--suite varied; repetitions for speed)",
    )
    p.add_argument("--seed", type=number_arg(int, 0, 2**32 - 1), default=0)
    p.add_argument(
        "--suite",
        choices=("regular", "varied", "tree", "tree-varied"),
        default="regular",
        help="regular: the plain phantom (default); varied: every imaging chain (detector, "
        "mapping, blur, glare, noise, background, bit depth) x harder anatomy (centerline "
        "and reconstruct only); tree: phantom trees with bifurcation lesions at Table-1 and "
        "random geometries, every branch reconstructed (reconstruct only); tree-varied: the "
        "same trees rendered through the imaging chains",
    )
    p.add_argument(
        "--jitter",
        type=INDEX,
        default=0,
        metavar="N",
        help="reconstruct only: N more runs per case with every click moved up to 2 px; "
        "reports the spread of MLD, %%DS and the MLD site",
    )
    p.add_argument(
        "--workers",
        type=COUNT,
        metavar="N",
        help="reconstruct, regular suite: run the cases on a local Dask cluster of N "
        "worker processes (the engine of `coronary3d batch`)",
    )
    p.add_argument("--tracer", choices=("2d", "3d"), default="2d",
                   help="reconstruct (every suite): the pipeline's tracer")


def bench_call(args: argparse.Namespace) -> tuple[Callable[..., dict], Callable[[dict], str],
                                                   dict]:
    """The benchmark's run function, its table formatter and the run's keyword arguments
    for the parsed ``bench`` command line; ValueError (one line) for a combination that no
    benchmark has."""
    tree_suite = args.name == "reconstruct" and args.suite.startswith("tree")
    if args.suite.startswith("tree") and args.name != "reconstruct":
        raise ValueError(f"bench {args.name} has no --suite {args.suite} (reconstruct has)")
    suites = ("centerline", "reconstruct", "calibration-modes")
    if args.name not in suites and args.suite != "regular":
        raise ValueError(f"bench {args.name} has no --suite {args.suite} "
                         f"({', '.join(suites)} have)")
    if args.jitter and (args.name != "reconstruct" or tree_suite):
        raise ValueError("--jitter N (N >= 1) is for bench reconstruct (regular and varied "
                         "suites)")
    if args.workers is not None and (args.workers < 1 or not (
            args.name in ("intervals", "calibration-modes") or (
            args.name == "reconstruct" and args.suite == "regular"))):
        raise ValueError("--workers N (N >= 1) is for bench reconstruct (regular suite), "
                         "intervals and calibration-modes")
    if args.tracer != "2d" and args.name != "reconstruct":
        raise ValueError("--tracer is for bench reconstruct")
    if tree_suite:  # the tree suites' end-to-end bench has its own module
        module = importlib.import_module("recon.bench.tree")
        return (module.run_tree, module.format_tree,
                {"cases": args.cases, "seed": args.seed, "suite": args.suite,
                 "tracer": args.tracer})
    module = importlib.import_module(f"recon.bench.{args.name.replace('-', '_')}")
    kwargs = {"cases": args.cases, "seed": args.seed}
    if args.name in suites:
        kwargs["suite"] = args.suite
    if args.jitter:
        kwargs["jitter"] = args.jitter
    if args.workers is not None:
        kwargs["workers"] = args.workers
    if args.tracer != "2d":
        kwargs["tracer"] = args.tracer
    return module.run, module.format_table, kwargs
