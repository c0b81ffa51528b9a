"""Load an angiogram (XA DICOM, or PNG/TIFF plus a geometry JSON) into an Angiogram.

Loading returns a :class:`recon.types.Angiogram`: one frame (H, W) float32 in
the MONOCHROME2 sense (contrast-filled vessels dark; MONOCHROME1 is inverted
on load; raw stored values, no rescale and no windowing), its
:class:`~recon.geometry.ViewGeometry` read from the positioner tags of the
project's C-arm convention, and why that frame was chosen (see
:mod:`recon.io.frames`).

Geometry follows the project's C-arm convention (``recon/geometry.py``): alpha =
PositionerPrimaryAngle (0018,1510), beta = PositionerSecondaryAngle
(0018,1511), SID = DistanceSourceToDetector (0018,1110), SOD =
DistanceSourceToPatient (0018,1111), pixel spacing (row, col) =
ImagerPixelSpacing (0018,1164). A user override always wins over the header.
Fallbacks, each recorded in ``Angiogram.geometry_notes``:

- SOD = SID / EstimatedRadiographicMagnificationFactor (0018,1114);
- detector spacing = PixelSpacing (0028,0030) x SID / SOD (PixelSpacing of a
  projection image is defined in the patient, at the isocenter);
- detector spacing = FieldOfViewDimensions (0018,1149) / (Rows, Columns).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from recon.errors import LoadError
from recon.geometry import ViewGeometry
from recon.io.dicom_read import read_dicom
from recon.io.frames import choose_frame
from recon.io.image_files import is_image_file, read_image_file
from recon.io.overrides import GEOMETRY_FIELDS, GeometryOverrides, spacing_pair
from recon.io.raw import RawFile
from recon.io.validate import check_geometry_value, check_image
from recon.types import Angiogram

__all__ = ["load_angiogram", "read_and_resolve"]


def load_angiogram(
    path: str | os.PathLike,
    *,
    frame: int | None = None,
    overrides: GeometryOverrides | None = None,
    geometry_json: str | os.PathLike | None = None,
) -> Angiogram:
    """Load one angiogram (XA DICOM, or an image file with a geometry JSON).

    Parameters
    ----------
    path : an XA DICOM file (single or multi-frame, 8-16 bit, uncompressed or
        JPEG Lossless / JPEG Baseline / what pylibjpeg decodes), or an image
        file Pillow or OpenCV reads (PNG, TIFF, ...; RGB is converted to grey
        by luminance) whose geometry comes from ``geometry_json`` or, when
        that is None, from a sidecar JSON with the same name and ".json".
    frame : 0-based frame index; None chooses one (see :mod:`recon.io.frames`).
    overrides : geometry values that replace the header's (or fill its gaps).
    geometry_json : a JSON with alpha_deg, beta_deg, sid_mm, sod_mm,
        pixel_spacing_mm [row, col]; for DICOM it acts as overrides (explicit
        ``overrides`` win over it).

    Returns
    -------
    Angiogram with image (H, W) float32 in the MONOCHROME2 sense.

    Raises
    ------
    LoadError : one line "<file>: <what is wrong>" for unreadable, non-XA, or
        undecodable files, a frame out of range, or missing geometry.
    """
    path_str = os.fspath(path)
    raw, index, reason, values, notes, problems = read_and_resolve(
        path_str, frame, overrides, geometry_json
    )
    geometry = _geometry(raw, values, problems, path_str)
    check_image(raw.frames, path_str)
    n = raw.frames.shape[0]
    return Angiogram(
        image=raw.frames[index],
        geometry=geometry,
        path=path_str,
        frame_index=index,
        frame_reason=reason,
        n_frames=n,
        frame_time_ms=raw.info.get("frame_time_ms"),
        frames=raw.frames if n > 1 else None,
        geometry_notes=tuple(notes),
        info=dict(raw.info),
    )


def read_and_resolve(
    path_str: str,
    frame: int | None,
    overrides: GeometryOverrides | None,
    geometry_json: str | os.PathLike | None,
) -> tuple:
    """Read a file, choose its frame and resolve its geometry (shared by load and describe).

    A geometry JSON given for a DICOM file acts as overrides, under the explicit ones.
    """
    json_str = os.fspath(geometry_json) if geometry_json is not None else None
    raw = _read_any(path_str, json_str)
    if json_str is not None and raw.info["format"] == "dicom":
        overrides = (overrides or GeometryOverrides()).merged_over(
            GeometryOverrides.from_json(json_str)
        )
    index, reason = choose_frame(raw, frame, path_str)
    values, notes, problems = _resolve_geometry(raw, overrides)
    return raw, index, reason, values, notes, problems


def _read_any(path: str, geometry_json: str | None) -> RawFile:
    p = Path(path)
    if not p.exists():
        raise LoadError(f"{path}: no such file")
    if p.is_dir():
        raise LoadError(f"{path}: is a folder, not an image file")
    if not p.is_file():  # a named pipe or a device would block or never end
        raise LoadError(f"{path}: is not a regular file")
    if is_image_file(p):
        return read_image_file(path, geometry_json)
    return read_dicom(path)


def _resolve_geometry(
    raw: RawFile, overrides: GeometryOverrides | None
) -> tuple[dict[str, Any], list[str], list[str]]:
    """Geometry values, notes and problems of a file.

    Returns ``values`` (key -> float / (row, col) / None), ``notes`` (how
    non-header values were obtained) and ``problems`` (one phrase per value
    that is missing, invalid or outside its range in :mod:`recon.io.validate`,
    naming the tag and how to supply it). A header value that is present but
    invalid is reported as such and never replaced by a fallback.
    """
    h = raw.header
    invalid: dict[str, str] = h.get("invalid", {})
    rows, cols = raw.frames.shape[1:]
    if raw.default_overrides is not None:
        ov = (overrides or GeometryOverrides()).merged_over(raw.default_overrides)
    else:
        ov = overrides or GeometryOverrides()
    ov_values = ov.values()
    values: dict[str, Any] = {}
    sources: dict[str, str] = {}
    notes: list[str] = []
    problems: list[str] = []
    reported: set[str] = set()  # keys with a problem already
    tags = {key: f"{keyword} {tag}" for key, keyword, tag, _ in GEOMETRY_FIELDS}
    flags = {key: flag for key, _, _, flag in GEOMETRY_FIELDS}

    def from_override(key: str, header_value: Any, label: str) -> bool:
        if key not in ov_values:
            return False
        src = _override_source(key, overrides, raw.default_overrides)
        value = ov_values[key]
        values[key] = value
        sources[key] = src
        if h["kind"] == "image":
            return True  # the JSON is the image's header: nothing to note
        shown = _fmt_value(value)
        if header_value is not None:
            notes.append(f"{label} {shown} from {src} (header says {_fmt_value(header_value)})")
        else:
            notes.append(f"{label} {shown} from {src}")
        return True

    def from_header(key: str, value: Any, where: str) -> Any:
        """A header (or derived) value inside its range, else None and a problem."""
        if value is None:
            return None
        try:
            checked = check_geometry_value(key, value, where)
        except LoadError as exc:
            problems.append(f"{exc}; give {flags[key]} or a geometry JSON")
            reported.add(key)
            return None
        sources[key] = where
        return checked

    def invalid_tag(key: str, keyword_tag: str, fallback_key: str | None = None) -> bool:
        """Record a present-but-invalid tag as a problem; True when there was one."""
        bad_key = fallback_key or key
        if bad_key not in invalid:
            return False
        problems.append(
            f"{keyword_tag} is invalid ({invalid[bad_key]}); give {flags[key]} or a geometry JSON"
        )
        reported.add(key)
        return True

    for key, label in (("alpha_deg", "primary angle"), ("beta_deg", "secondary angle")):
        if not from_override(key, h[key], label):
            values[key] = None if invalid_tag(key, tags[key]) else from_header(
                key, h[key], tags[key])
    if not from_override("sid_mm", h["sid_mm"], "SID"):
        values["sid_mm"] = None if invalid_tag("sid_mm", tags["sid_mm"]) else from_header(
            "sid_mm", h["sid_mm"], tags["sid_mm"])
    if not from_override("sod_mm", h["sod_mm"], "SOD"):
        values["sod_mm"] = None
        if not invalid_tag("sod_mm", tags["sod_mm"]):
            sod, where = h["sod_mm"], tags["sod_mm"]
            mag_tag = "EstimatedRadiographicMagnificationFactor (0018,1114)"
            if sod is None and values["sid_mm"] is not None and not invalid_tag(
                "sod_mm", f"{mag_tag} (for the missing SOD)", "magnification"
            ) and h["magnification"] is not None:
                mag = h["magnification"]
                sod = values["sid_mm"] / mag
                where = f"SOD from SID / {mag_tag} {mag:g}"
                notes.append(
                    f"SOD {sod:.1f} mm = SID / EstimatedRadiographicMagnificationFactor "
                    f"{mag:g} (DistanceSourceToPatient missing)"
                )
            values["sod_mm"] = from_header("sod_mm", sod, where)
    if not from_override("pixel_spacing_mm", h["pixel_spacing_mm"], "pixel spacing"):
        values["pixel_spacing_mm"] = None
        key = "pixel_spacing_mm"
        if not invalid_tag(key, tags[key]):
            spacing, where = h[key], tags[key]
            if spacing is None and h["patient_pixel_spacing_mm"]:
                iso = spacing_pair(h["patient_pixel_spacing_mm"])
                sid, sod = values["sid_mm"], values["sod_mm"]
                if iso is not None and sid is not None and sod is not None:
                    mag = sid / sod
                    spacing = (iso[0] * mag, iso[1] * mag)
                    where = "pixel spacing from PixelSpacing (0028,0030) x SID/SOD"
                    notes.append(
                        f"pixel spacing {_fmt_value(spacing)} mm = PixelSpacing "
                        f"{_fmt_value(iso)} mm x SID/SOD {mag:.4g} (ImagerPixelSpacing missing; "
                        f"PixelSpacing taken as calibrated at the isocenter)"
                    )
            elif spacing is None:
                invalid_tag(key, "PixelSpacing (0028,0030) (for the missing ImagerPixelSpacing)",
                            "patient_pixel_spacing_mm")
            if spacing is None and h["fov_mm"]:
                fov = h["fov_mm"]
                spacing = (fov[0] / rows, fov[-1] / cols)
                where = "pixel spacing from FieldOfViewDimensions (0018,1149) / image size"
                notes.append(
                    f"pixel spacing {_fmt_value(spacing)} mm from FieldOfViewDimensions "
                    f"{_fmt_value(fov)} mm / {rows}x{cols} px (ImagerPixelSpacing missing)"
                )
            elif spacing is None:
                invalid_tag(
                    key, "FieldOfViewDimensions (0018,1149) (for the missing ImagerPixelSpacing)",
                    "fov_mm")
            values[key] = from_header(key, spacing, where)

    for key, keyword, tag, flag in GEOMETRY_FIELDS:
        if values[key] is None and key not in reported:
            if h["kind"] == "image":
                json_name = h.get("json")
                if json_name:
                    problems.append(f"{key} is missing from {json_name}; add it or give {flag}")
                else:
                    problems.append(
                        f"{key} is missing: no geometry JSON (looked for "
                        f"{Path(raw.info['path']).with_suffix('.json').name}); give one or {flag}"
                    )
            else:
                problems.append(f"{keyword} {tag} is missing; give {flag} or a geometry JSON")
    if not problems and values["sod_mm"] is not None and values["sid_mm"] is not None:
        if not values["sod_mm"] < values["sid_mm"]:
            problems.append(
                f"invalid geometry: SOD {values['sod_mm']:g} mm ({sources['sod_mm']}) must be "
                f"below SID {values['sid_mm']:g} mm ({sources['sid_mm']})"
            )
    return values, notes, problems


def _override_source(
    key: str, overrides: GeometryOverrides | None, defaults: GeometryOverrides | None
) -> str:
    if overrides is not None and getattr(overrides, key) is not None:
        return overrides.source
    if defaults is not None:
        return defaults.source
    return "override"


def _fmt_value(value: Any) -> str:
    if isinstance(value, (tuple, list)):
        return "/".join(f"{float(v):g}" for v in value)
    return f"{float(value):g}"


def _geometry(raw: RawFile, values: dict[str, Any], problems: list[str], path: str) -> ViewGeometry:
    if problems:
        extra = ""
        if len(problems) > 1:
            others = [p.split(" is ")[0].split(" = ")[0].split(":")[0] for p in problems[1:]]
            extra = f" (also: {', '.join(others)})"
        raise LoadError(f"{path}: {problems[0]}{extra}")
    rows, cols = raw.frames.shape[1:]
    try:
        return ViewGeometry(
            alpha_deg=float(values["alpha_deg"]),
            beta_deg=float(values["beta_deg"]),
            sid_mm=float(values["sid_mm"]),
            sod_mm=float(values["sod_mm"]),
            pixel_spacing_mm=tuple(values["pixel_spacing_mm"]),
            rows=int(rows),
            cols=int(cols),
        )
    except ValueError as exc:
        raise LoadError(f"{path}: invalid geometry: {exc}") from None
