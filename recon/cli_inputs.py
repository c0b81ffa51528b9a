"""What the command line reads: finite numbers in range (every numeric option), the files
no output of `coronary3d reconstruct` may replace, its --segment, and the FFR model's
options (with the FFR's words in its summary line)."""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

__all__ = ["number_arg", "segment_choice", "file_bytes", "input_files", "add_ffr_options",
           "ffr_words"]


def segment_choice(text: str | None, seeds, seeds_path: str) -> int | None:
    """--segment as an index into the seeds' segments (None: all of them). Raises
    ValueError (the one-line message) when the name or index does not exist."""
    if text is None:
        return None
    names = [s.name for s in seeds.segments]
    if text in names:
        return names.index(text)
    if text.strip().isdigit() and int(text) < len(names):
        return int(text)
    shown = ", ".join(repr(n) for n in names[:10]) or "none"
    raise ValueError(f"argument --segment: no segment {text!r} in {seeds_path} "
                     f"(segments: {shown}; or an index from 0 to {len(names) - 1})")


def file_bytes(path: str) -> int:
    try:
        return os.stat(path).st_size
    except OSError:
        return 0  # the loader says what is wrong with it


def input_files(file_a: str, file_b: str, seeds: str, geometry_json: str | None,
                 geometry_a: str | None = None,
                 geometry_b: str | None = None) -> list[tuple[str, str]]:
    """(role, path) of every file a reconstruction reads, which no output may replace."""
    found = [("file A", file_a), ("file B", file_b), ("seeds file", seeds)]
    for role, path in (("geometry JSON", geometry_json), ("geometry JSON of file A", geometry_a),
                       ("geometry JSON of file B", geometry_b)):
        if path:
            found.append((role, path))
    for role, path in (("A", file_a), ("B", file_b)):
        sidecar = Path(path).with_suffix(".json")
        if sidecar != Path(path):
            found.append((f"geometry JSON of file {role}", str(sidecar)))
    return found


def number_arg(kind: type, low: float | None = None, high: float | None = None,
            below_high: bool = False):
    """An argparse type: a finite ``kind`` (int or float) in [low, high] (or
    [low, high) when ``below_high``), refused in one line otherwise."""

    def parse(text: str):
        try:
            value = kind(text)
        except (TypeError, ValueError):
            raise argparse.ArgumentTypeError(
                f"{text!r} is not {'an integer' if kind is int else 'a number'}"
            ) from None
        if kind is float and not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text!r} is not a finite number")
        top_ok = high is None or (value < high if below_high else value <= high)
        if (low is not None and value < low) or not top_ok:
            lo = "" if low is None else f"{low:g}" if kind is float else str(low)
            hi = "" if high is None else f"{high:g}" if kind is float else str(high)
            if high is None:
                span = f"at least {lo}"
            elif below_high:
                span = f"from {lo} to below {hi}"
            else:
                span = f"from {lo} to {hi}"
            raise argparse.ArgumentTypeError(f"{text} is out of range ({span})")
        return value

    parse.__name__ = kind.__name__
    return parse


def ffr_words(rec) -> str:
    """", FFR 0.82 (95 % 0.78-0.86; model estimate)" for the summary line ("" without one)."""
    ffr = getattr(rec, "ffr", None)
    if ffr is None:
        return ""
    ci = f"95 % {ffr.ci95[0]:.2f}-{ffr.ci95[1]:.2f}; " if ffr.ci95 is not None else ""
    return f", FFR {ffr.distal:.2f} ({ci}model estimate for research)"


def add_ffr_options(p: argparse.ArgumentParser) -> None:
    """The FFR model's options (recon.lumen.ffr; a model estimate for research)."""
    from recon.lumen.ffr import (
        PRESSURE_RANGE_MMHG,
        SPLIT_EXPONENT_RANGE,
        VELOCITY_RANGE_M_S,
        FFRModel,
    )

    g = p.add_argument_group("FFR model (a model estimate for research, not validated against "
                             "a pressure wire; docs/ffr.md)")
    g.add_argument("--aortic-pressure", type=number_arg(float, *PRESSURE_RANGE_MMHG),
                   default=FFRModel.aortic_pressure_mmhg, metavar="MMHG",
                   help="mean aortic pressure driving the hyperemic flow, mmHg (default "
                   f"{FFRModel.aortic_pressure_mmhg:g})")
    g.add_argument("--ffr-velocity", type=number_arg(float, *VELOCITY_RANGE_M_S),
                   default=FFRModel.velocity_m_s, metavar="M_S",
                   help="hyperemic mean velocity of a healthy vessel of the proximal "
                   f"reference area, m/s (default {FFRModel.velocity_m_s:g}); sets the "
                   "distal resistance")
    g.add_argument("--ffr-split-exponent", type=number_arg(float, *SPLIT_EXPONENT_RANGE),
                   default=FFRModel.split_exponent, metavar="K",
                   help="a bifurcation splits the flow by diameter^K (default 7/3, Huo and "
                   "Kassab; 3 is Murray's law)")
