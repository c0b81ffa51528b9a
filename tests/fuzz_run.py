"""A larger fuzz run: ``python tests/fuzz_run.py --n 2000`` prints the counts by outcome.

The cases are those of the suite's fuzz test (tests/fuzz_cases.py), with ``--n``
random draws on top of the fixed ones, each run in-process through
``recon.cli.main``; a case is counted as a pass when it is refused in one line
with exit 2 and no output (or, for byte-flipped files, ends without a traceback).

``--signals N`` adds N real ``coronary3d reconstruct --demo`` processes, all into
one output folder, each sent SIGTERM, SIGINT or SIGKILL at a random moment of
its run (most of them within the writing of the outputs): a pass when no
traceback is printed, no temporary file is left (after a SIGKILL: once the next
run has swept it) and the folder holds one complete set that matches its
manifest, or the earlier one, or nothing, or (when an earlier SIGKILL left it
so) a set its manifest marks incomplete.

Each in-process case is timed (the count over 60 s and the longest are
printed: a hang would show there). A SIGTERM that reaches this process while
the in-process cases run is not taken by the command under test: a thread
waits for it (``sigwaitinfo``) and the run prints who sent it (pid and
command line), so an exit 143 can never go unexplained; a case that returns
143 with no such SIGTERM recorded is a failure of its own.
"""

from __future__ import annotations

import argparse
import signal
import sys
import tempfile
import threading
import time
from collections import Counter
from pathlib import Path

# tests/ holds a folder named recon (the tests of the package, no __init__.py): on the path
# first, it would be imported as the package under an editable install. The package is
# imported first, then tests/ goes on the path for fuzz_cases.
_TESTS = Path(__file__).resolve().parent
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != _TESTS]
import recon.io  # noqa: E402, F401

sys.path.append(str(_TESTS))
from fuzz_cases import failure, make_cases, run_in_process  # noqa: E402


def _set_state(out: Path, pid: int | None = None) -> str:
    """'absent', 'complete' (files match the manifest) or why the folder is not one set.

    With ``pid``, the temporaries of other processes (a SIGKILLed earlier run's, which
    the next run that writes sweeps) are not counted; the process's own are."""
    import hashlib
    import json

    if not out.exists():
        return "absent"
    temps = sorted(p.name for p in out.glob(".*.tmp"))
    own = [t for t in temps if pid is None or f".{pid}." in t]
    if own:
        return f"temporary files {own}"
    try:
        manifest = json.loads((out / "outputs.json").read_text())
    except (OSError, ValueError) as exc:
        return f"no manifest ({exc})"
    if manifest.get("complete") is not True:
        return "manifest says incomplete"
    names = sorted(p.name for p in out.iterdir() if p.name not in temps)
    if names != sorted([*manifest["files"], "outputs.json"]):
        return f"files {names} differ from the manifest"
    for name, entry in manifest["files"].items():
        if hashlib.sha256((out / name).read_bytes()).hexdigest() != entry["sha256"]:
            return f"{name} differs from the manifest"
    return "complete"


def signal_runs(n: int, seed: int, folder: Path) -> Counter[str]:
    """N demo reconstructions into one folder, each signalled at a random moment."""
    import os
    import signal
    import subprocess

    import numpy as np

    rng = np.random.default_rng(seed)
    out = folder / "signal-out"
    env = {k: v for k, v in os.environ.items() if k != "CORONARY3D_DEBUG"}
    argv = [sys.executable, "-m", "recon.cli", "reconstruct", "--demo", "--out", str(out),
            "--quiet"]
    counts: Counter[str] = Counter()
    t0 = time.perf_counter()  # one undisturbed run: how long a run takes, when it writes
    first = subprocess.run(argv, capture_output=True, text=True, env=env)
    duration = time.perf_counter() - t0
    assert first.returncode == 0, first.stderr
    sigs = (signal.SIGTERM, signal.SIGINT, signal.SIGKILL)
    for k in range(n):
        sig = sigs[k % 3]
        # a quarter anywhere in the run, the rest from the moment a temporary appears
        when = "anytime" if rng.random() < 0.25 else "writing"
        before = _set_state(out)
        proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True, env=env)
        if when == "anytime":
            time.sleep(float(rng.uniform(0.0, duration * 1.1)))
        else:
            delay = float(rng.uniform(0.0, 0.05))
            while proc.poll() is None and not list(out.glob(f".*.{proc.pid}.*.tmp")):
                time.sleep(0.001)
            time.sleep(delay)
        if proc.poll() is None:
            proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=300)
        state = _set_state(out, proc.pid)
        if state == "complete" and _set_state(out) != "complete":
            state = "complete, beside an earlier SIGKILL's temporaries"
        name = signal.Signals(sig).name
        if "Traceback" in stderr:
            counts[f"fail: traceback after {name}"] += 1
        elif sig == signal.SIGKILL and state != "complete" and state != "absent":
            counts[f"{name}: left for the next run ({state[:30]})"] += 1
        elif sig != signal.SIGKILL and before not in ("complete", "absent") and (
                state == "manifest says incomplete" or _set_state(out) == before):
            # an earlier SIGKILL broke the set; this run, stopped, made it no worse (its own
            # temporaries gone, the earlier ones swept if it got that far)
            counts[f"{name} {when}: exit {proc.returncode}, still incomplete from the "
                   f"earlier SIGKILL"] += 1
        elif state not in ("complete", "absent"):  # "complete, beside ...": not swept
            counts[f"fail: {name} {when}: {state}"] += 1
        else:
            counts[f"{name} {when}: exit {proc.returncode}, set {state}"] += 1
    final = subprocess.run(argv, capture_output=True, text=True, env=env)
    state = _set_state(out)
    counts[f"final run: exit {final.returncode}, set {state}"] += 1
    return counts


def _sender(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as fh:
            return fh.read().replace(b"\0", b" ").decode(errors="replace").strip() or "?"
    except OSError:
        return "gone"


def watch_sigterm(received: list[str]) -> None:
    """Block SIGTERM in this thread and the ones it starts; a watcher thread records each
    one that arrives, with its sender (call before any other thread starts)."""
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})

    def watch() -> None:
        while True:
            info = signal.sigwaitinfo({signal.SIGTERM})
            received.append(f"SIGTERM from pid {info.si_pid} ({_sender(info.si_pid)}) "
                            f"at {time.strftime('%H:%M:%S')}")

    threading.Thread(target=watch, daemon=True, name="sigterm-watch").start()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=2000, help="random cases beyond the fixed ones")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--signals", type=int, default=0,
                        help="real processes signalled while they run (see the docstring)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        cases = make_cases(Path(tmp), n_random=args.n, seed=args.seed)
        outcomes: Counter[str] = Counter()
        by_family: Counter[tuple[str, str]] = Counter()
        failures = []
        received: list[str] = []
        watch_sigterm(received)
        slow: list[tuple[float, str]] = []
        t0 = time.perf_counter()
        for case in cases:
            before = len(received)
            t_case = time.perf_counter()
            outcome = run_in_process(case)
            slow.append((time.perf_counter() - t_case, f"{case.family} / {case.label}"))
            reason = failure(case, outcome)
            if outcome.code == 143:
                reason = (f"exit 143 after {received[before]}" if len(received) > before
                          else "exit 143 with no SIGTERM received")
            kind = ("traceback" if outcome.traceback else f"exit {outcome.code}") if reason \
                else ("refused (exit 2)" if outcome.code == 2 else f"read (exit {outcome.code})")
            outcomes["fail: " + reason if reason else kind] += 1
            by_family[(case.family, "fail" if reason else "ok")] += 1
            if reason:
                failures.append(f"{case.family} / {case.label}: {reason}")
        elapsed = time.perf_counter() - t0
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGTERM})  # the signalled runs
        print(f"{len(cases)} cases in {elapsed:.1f} s")
        longest = max(slow)
        print(f"  cases over 60 s: {sum(t > 60.0 for t, _ in slow)}; the longest "
              f"{longest[0]:.1f} s ({longest[1]})")
        print(f"  SIGTERM received by the runner: {len(received)}")
        for line in received:
            print(f"    {line}")
        for key, count in sorted(outcomes.items()):
            print(f"  {key}: {count}")
        for (family, result), count in sorted(by_family.items()):
            print(f"  {family:<16} {result}: {count}", flush=True)
        signal_counts = signal_runs(args.signals, args.seed, Path(tmp)) if args.signals \
            else Counter()
    if signal_counts:
        print(f"{args.signals} signalled processes (+1 final run):")
        for key, count in sorted(signal_counts.items()):
            print(f"  {key}: {count}")
    for line in failures[:30]:
        print("FAIL", line)
    signal_failed = any(key.startswith("fail") or (key.startswith("final") and
                        not key.endswith("complete")) for key in signal_counts)
    return 1 if failures or signal_failed else 0


if __name__ == "__main__":
    sys.exit(main())
