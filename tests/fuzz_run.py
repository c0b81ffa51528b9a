"""A larger fuzz run: ``python tests/fuzz_run.py --n 2000`` prints the counts by outcome.

The cases are those of the suite's fuzz test (tests/fuzz_cases.py), with ``--n``
random draws on top of the fixed ones, each run in-process through
``recon.cli.main``; a case is counted as a pass when it is refused in one line
with exit 2 and no output (or, for byte-flipped files, ends without a traceback).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from fuzz_cases import failure, make_cases, run_in_process  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=2000, help="random cases beyond the fixed ones")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        cases = make_cases(Path(tmp), n_random=args.n, seed=args.seed)
        outcomes: Counter[str] = Counter()
        by_family: Counter[tuple[str, str]] = Counter()
        failures = []
        t0 = time.perf_counter()
        for case in cases:
            outcome = run_in_process(case)
            reason = failure(case, outcome)
            kind = ("traceback" if outcome.traceback else f"exit {outcome.code}") if reason \
                else ("refused (exit 2)" if outcome.code == 2 else f"read (exit {outcome.code})")
            outcomes["fail: " + reason if reason else kind] += 1
            by_family[(case.family, "fail" if reason else "ok")] += 1
            if reason:
                failures.append(f"{case.family} / {case.label}: {reason}")
        elapsed = time.perf_counter() - t0
    print(f"{len(cases)} cases in {elapsed:.1f} s")
    for key, count in sorted(outcomes.items()):
        print(f"  {key}: {count}")
    for (family, result), count in sorted(by_family.items()):
        print(f"  {family:<16} {result}: {count}")
    for line in failures[:30]:
        print("FAIL", line)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
