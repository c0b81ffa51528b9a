"""`coronary3d bench speed`: the whole job on the demo case against its floor.

One run measures, alternating (one of each per repetition, so that a
change in the machine's load falls on all of them alike):

- ``floor``: a fresh interpreter that imports only the numerical stack the
  job really needs (:data:`FLOOR_IMPORTS`, fixed here so that it cannot
  drift with the code) and exits;
- ``cold``: ``coronary3d reconstruct --demo`` as a fresh process (imports,
  reading the DICOM files, the pipeline, writing the outputs: ``python -c``
  running ``recon.cli`` as ``__main__``), its wall time and its peak
  resident memory (the process's ``VmHWM``, written at its exit);
- both children's CPU time (user + system) as well, which a shared
  machine's load disturbs less than their wall time;
- ``warm``: :func:`recon.pipeline.reconstruct_pair` in this process on the
  already loaded demo angiograms, its total and its per-stage
  ``timings_ms`` (the vesselness maps are part of ``trace``);
- ``viewer``: the viewer's Reconstruct (:meth:`viewer_app.ViewerApp.reconstruct`,
  server time: the pipeline on the cached vesselness maps plus drawing the
  scene and the panels) and a click-to-epipolar round trip
  (:meth:`viewer_app.ViewerApp.click` of a feature mark in view A, which
  snaps it, draws the marks and view B's epipolar line and autosaves; the
  mark is undone after each). The viewer runs in-process on a real viser
  server on a free port with no browser connected; ``viewer_app`` is
  imported inside :func:`run` only, so ``recon`` stays pure.

Every figure is the median over the repetitions. ``cases`` is the number
of repetitions (default :data:`REPETITIONS`); ``seed`` is unused (the demo
case is fixed) and kept for the common bench signature.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from recon.startup import THREAD_VARIABLES

REPETITIONS = 5  # repetitions of each measurement when run(cases=None)

#: The import floor: the modules the numerical job needs (fixed; see the module docstring).
FLOOR_IMPORTS = "numpy, scipy.ndimage, scipy.optimize, scipy.interpolate, skimage.measure, " \
    "pydicom, trimesh"

#: Targets of issue 19 (medians).
TARGETS = {
    "cold_over_floor": 1.5,
    "warm_ms": 250.0,
    "viewer_reconstruct_ms": 400.0,
    "click_ms": 20.0,
    "peak_mb": 400.0,
}

_ROOT = Path(__file__).resolve().parents[2]  # the folder that holds the recon package


def _child_env() -> dict[str, str]:
    """The environment of a child process, with this source tree first on its path."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(_ROOT), env.get("PYTHONPATH")) if p)
    return env


def _run_child(argv: list[str], env: dict[str, str]) -> tuple[float, float]:
    """(wall s, CPU s: user + system) of one child process; raises if it fails."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(argv, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall_s = time.perf_counter() - t0
    proc.returncode = os.waitstatus_to_exitcode(status)
    stderr = proc.stderr.read().decode(errors="replace") if proc.stderr else ""
    if proc.stderr:
        proc.stderr.close()
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(argv[:4])}... exited {proc.returncode}: "
                           f"{stderr.strip().splitlines()[-1:]}")
    return wall_s, usage.ru_utime + usage.ru_stime


#: ``python -c`` body that runs ``python -m recon.cli ...`` and, at exit, writes the
#: process's peak resident memory (VmHWM, kB) to the file named by $CORONARY3D_PEAK_FILE.
#: (The child's ``ru_maxrss`` would not do: it keeps the peak of the forked copy of this
#: large benchmark process from before the exec.)
_COLD_MAIN = """import atexit, os, runpy
def _peak():
    text = open('/proc/self/status').read()
    kb = [line.split()[1] for line in text.splitlines() if line.startswith('VmHWM:')]
    open(os.environ['CORONARY3D_PEAK_FILE'], 'w').write(kb[0] if kb else '')
atexit.register(_peak)
runpy.run_module('recon.cli', run_name='__main__', alter_sys=True)
"""


def _feature_click_px(app) -> tuple[float, float]:
    """A pixel of view A on the demo's vessel (the first clicked end of its segment)."""
    seg = app.seeds().segments[0]
    col, row = seg.a[0]
    return float(col) + 1.0, float(row) - 0.5


def run(cases: int | None = None, seed: int = 0) -> dict:
    """Measure the floor, the cold job, the warm pipeline, the viewer; medians and all runs."""
    from recon.io import demo_paths, load_angiogram, load_seeds
    from recon.pipeline import reconstruct_pair
    from viewer_app import ViewerApp

    reps = REPETITIONS if cases is None else max(1, int(cases))
    env = _child_env()
    demo = demo_paths()
    angio_a, angio_b = load_angiogram(str(demo["a"])), load_angiogram(str(demo["b"]))
    seeds = load_seeds(demo["seeds"])

    floor_s: list[float] = []
    cold_s: list[float] = []
    floor_cpu_s: list[float] = []
    cold_cpu_s: list[float] = []
    peak_mb: list[float] = []
    warm_ms: list[float] = []
    stages: dict[str, list[float]] = {}
    viewer_ms: list[float] = []
    click_ms: list[float] = []
    with tempfile.TemporaryDirectory(prefix="coronary3d-bench-speed-") as tmp:
        peak_file = Path(tmp) / "peak_kb.txt"
        cold_env = {**env, "CORONARY3D_PEAK_FILE": str(peak_file)}
        app = ViewerApp(port=0, autosave_path=Path(tmp) / "autosave.json")
        try:
            app.wait_ready()
            reconstruct_pair(angio_a, angio_b, seeds)  # warm-up: caches, first-call costs
            app.reconstruct()
            click_px = _feature_click_px(app)
            for _ in range(reps):
                wall, cpu = _run_child([sys.executable, "-c", f"import {FLOOR_IMPORTS}"], env)
                floor_s.append(wall)
                floor_cpu_s.append(cpu)

                wall, cpu = _run_child([sys.executable, "-c", _COLD_MAIN, "reconstruct",
                                        "--demo", "--quiet", "--out", str(Path(tmp) / "out")],
                                       cold_env)
                cold_s.append(wall)
                cold_cpu_s.append(cpu)
                peak_mb.append(float(peak_file.read_text()) / 1024.0)

                rec = reconstruct_pair(angio_a, angio_b, seeds)
                for name, ms in rec.timings_ms.items():
                    if name != "total":
                        stages.setdefault(name, []).append(float(ms))
                warm_ms.append(float(rec.timings_ms["total"]))

                t0 = time.perf_counter()
                done = app.reconstruct()
                viewer_ms.append((time.perf_counter() - t0) * 1e3)
                if done is None:
                    raise RuntimeError(f"viewer Reconstruct failed: {app.notifications[-1:]}")

                app.set_mode("feature")
                t0 = time.perf_counter()
                mark = app.click("a", *click_px)
                click_ms.append((time.perf_counter() - t0) * 1e3)
                if mark is None or app.epipolar_segments["b"] is None:
                    raise RuntimeError("viewer click drew no epipolar line in view B")
                app.undo()
        finally:
            app.stop()

    floor = float(np.median(floor_s))
    cold = float(np.median(cold_s))
    return {
        "repetitions": reps,
        "floor_imports": FLOOR_IMPORTS,
        "floor_s": floor,
        "cold_s": cold,
        "cold_over_floor": cold / floor,
        "warm_ms": float(np.median(warm_ms)),
        "stages_ms": {k: float(np.median(v)) for k, v in stages.items()},
        "viewer_reconstruct_ms": float(np.median(viewer_ms)),
        "click_ms": float(np.median(click_ms)),
        "peak_mb": float(np.median(peak_mb)),
        # CPU time (user + system) of the children: steadier than wall time on a shared machine
        "floor_cpu_s": float(np.median(floor_cpu_s)),
        "cold_cpu_s": float(np.median(cold_cpu_s)),
        "cold_over_floor_cpu": float(np.median(cold_cpu_s) / np.median(floor_cpu_s)),
        "runs": {
            "floor_s": floor_s,
            "cold_s": cold_s,
            "floor_cpu_s": floor_cpu_s,
            "cold_cpu_s": cold_cpu_s,
            "peak_mb": peak_mb,
            "warm_ms": warm_ms,
            "stages_ms": stages,
            "viewer_reconstruct_ms": viewer_ms,
            "click_ms": click_ms,
        },
        "targets": TARGETS,
        # the BLAS / OpenMP thread counts this process and its children ran with
        # (recon.startup: the command line sets 1 unless the user set them)
        "thread_env": {k: os.environ.get(k) for k in THREAD_VARIABLES},
        "cpus": os.cpu_count(),
        "load_average": list(os.getloadavg()),
    }


def format_table(result: dict) -> str:
    """Plain-text summary of a :func:`run` result: each median, its spread, the target."""
    runs = result["runs"]
    t = result["targets"]

    def spread(values: list[float]) -> str:
        return f"{min(values):.3g}-{max(values):.3g}"

    rows = [
        ("floor_s", "s", runs["floor_s"]),
        ("cold_s", "s", runs["cold_s"]),
        ("cold_over_floor", "", None),
        ("floor_cpu_s", "s", runs["floor_cpu_s"]),
        ("cold_cpu_s", "s", runs["cold_cpu_s"]),
        ("cold_over_floor_cpu", "", None),
        ("warm_ms", "ms", runs["warm_ms"]),
        ("viewer_reconstruct_ms", "ms", runs["viewer_reconstruct_ms"]),
        ("click_ms", "ms", runs["click_ms"]),
        ("peak_mb", "MB", runs["peak_mb"]),
    ]
    threads = ", ".join(f"{k}={v}" for k, v in result.get("thread_env", {}).items())
    lines = [f"speed benchmark: demo case, {result['repetitions']} repetition(s), "
             f"{result['cpus']} CPU(s), load {result['load_average'][0]:.2f}; {threads}",
             f"floor: python -c 'import {result['floor_imports']}'"]
    for key, unit, values in rows:
        value = result[key]
        target = f"  (target <= {t[key]:g}: {'ok' if value <= t[key] else 'MISSED'})" \
            if key in t else ""
        where = f"  [{spread(values)}]" if values else ""
        lines.append(f"median {key:<22}{value:10.3f} {unit:<3}{where}{target}")
    stages = ", ".join(f"{k} {v:.0f}" for k, v in result["stages_ms"].items())
    lines.append(f"warm stages (ms, medians): {stages}")
    return "\n".join(lines)
