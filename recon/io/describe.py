"""What ``coronary3d info`` says about a file: header facts, geometry, chosen frame.

Missing, invalid or out-of-range geometry is reported, never raised, so that a user can see at once
which values a file lacks and which option supplies each one.
"""

from __future__ import annotations

import os
from typing import Any

from recon.io.angiogram import read_and_resolve
from recon.io.overrides import GeometryOverrides

__all__ = ["describe_file", "format_description"]


def describe_file(
    path: str | os.PathLike,
    *,
    show_patient: bool = False,
    frame: int | None = None,
    overrides: GeometryOverrides | None = None,
    geometry_json: str | os.PathLike | None = None,
) -> dict:
    """What ``coronary3d info`` prints about a file, as a JSON-ready dict.

    Missing geometry is reported (value None, listed under "missing"), never
    raised; unreadable files and a frame out of range raise :class:`LoadError`.
    Patient name and ID are included only when ``show_patient``.
    """
    path_str = os.fspath(path)
    raw, index, reason, values, notes, problems = read_and_resolve(
        path_str, frame, overrides, geometry_json
    )
    geometry = {k: (list(v) if isinstance(v, tuple) else v) for k, v in values.items()}
    info = raw.info
    desc: dict[str, Any] = {
        "path": path_str,
        "format": info["format"],
        "sop_class": info["sop_class"],
        "sop_class_name": info["sop_class_name"],
        "modality": info["modality"],
        "rows": info["rows"],
        "cols": info["cols"],
        "n_frames": info["n_frames"],
        "frame_time_ms": info["frame_time_ms"],
        "bits_stored": info["bits_stored"],
        "photometric": info["photometric"],
        "transfer_syntax": info.get("transfer_syntax_name") or info["transfer_syntax"],
        "geometry": geometry,
        "geometry_notes": notes,
        "missing": problems,
        "r_wave_pointer": info["r_wave_pointer"],
        "r_wave_frames": info["r_wave_frames"],
        "representative_frame_number": info["representative_frame_number"],
        "frame_index": index,
        "frame_reason": reason,
    }
    if show_patient:
        desc["patient_name"] = raw.patient.get("name", "")
        desc["patient_id"] = raw.patient.get("id", "")
    return desc


def format_description(desc: dict) -> str:
    """Human-readable multi-line text of a :func:`describe_file` dict."""
    g = desc["geometry"]

    def val(key: str, unit: str, fmt: str = "g") -> str:
        v = g.get(key)
        if v is None:
            return "missing"
        if isinstance(v, (list, tuple)):
            return " x ".join(f"{float(x):{fmt}}" for x in v) + f" {unit} (row x col)"
        return f"{float(v):{fmt}} {unit}"

    name = desc["sop_class_name"] or desc["sop_class"] or "?"
    if desc["modality"]:
        name += f" ({desc['modality']})"
    frames = f"{desc['n_frames']}"
    if desc["frame_time_ms"] is not None:
        frames += f", frame time {desc['frame_time_ms']:g} ms"
    lines = [
        f"{desc['path']}",
        f"  type            {name}",
        f"  size            {desc['rows']} x {desc['cols']} px (rows x cols)",
        f"  frames          {frames}",
    ]
    if desc["bits_stored"] is not None or desc["photometric"]:
        lines.append(
            f"  pixels          {desc['bits_stored'] or '?'} bit, {desc['photometric']}"
            + (f", {desc['transfer_syntax']}" if desc["transfer_syntax"] else "")
        )
    lines += [
        f"  primary angle   {val('alpha_deg', 'deg')}",
        f"  secondary angle {val('beta_deg', 'deg')}",
        f"  SID             {val('sid_mm', 'mm')}",
        f"  SOD             {val('sod_mm', 'mm')}",
        f"  pixel spacing   {val('pixel_spacing_mm', 'mm')}",
    ]
    for note in desc["geometry_notes"]:
        lines.append(f"  note            {note}")
    for problem in desc["missing"]:
        label = "missing" if " is missing" in problem else "problem"
        lines.append(f"  {label:<15} {problem}")
    if desc["r_wave_pointer"]:
        lines.append(
            "  R waves         frames "
            + ", ".join(str(k) for k in desc["r_wave_frames"])
            + " (0-based; R Wave Pointer "
            + ", ".join(str(k) for k in desc["r_wave_pointer"])
            + ")"
        )
    lines.append(f"  chosen frame    {desc['frame_index']} (0-based): {desc['frame_reason']}")
    if "patient_name" in desc:
        lines.append(f"  patient         {desc['patient_name']} (ID {desc['patient_id']})")
    return "\n".join(lines)
