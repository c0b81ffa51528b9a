"""The phantom's case files: a.dcm, b.dcm, seeds.json and truth.json.

b.dcm carries view B's NOMINAL header although its image was rendered with
the true geometry (see :mod:`recon.synth`).

truth.json schema (version 1; all lengths mm, points in the world frame)
------------------------------------------------------------------------
::

    {"version": 1, "preset": str, "seed": int,
     "frame_index": int (0-based frame of a cine the truth holds for),
     "view_a": ViewGeometry dict (true = header),
     "view_b_nominal": ViewGeometry dict (the b.dcm header),
     "view_b_true": ViewGeometry dict (nominal with the correction applied),
     "correction_rotvec": [3] rad, "correction_t_mm": [3],
     "vessels": [{"name": str, "X_world": [[x, y, z], ...], "radius_mm": [...]}],
                                   (0 = main vessel, proximal first; 0.1 mm steps)
     "segment": {"name": "main", "X_world": [[...]], "radius_mm": [...], "s_mm": [...],
                 "start_s_mm": float (position of the segment on vessel 0),
                 "volume_mm3": float},
     "stenosis": {"s_mm": float (centre, along the segment), "length_mm": float,
                  "diameter_pct": float, "mld_mm": float, "reference_diameter_mm": float},
     "features": [{"name": str, "X_world": [x, y, z]}]}
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from recon.io.dicom_write import write_xa_dicom
from recon.io.files import atomic_write_bytes
from recon.io.seeds_file import save_seeds
from recon.synth import PhantomCase, PhantomError, PhantomTruth

__all__ = ["write_phantom_case", "load_truth"]


def write_phantom_case(case: PhantomCase, out_dir: str | os.PathLike) -> dict[str, Path]:
    """Write a.dcm, b.dcm, seeds.json and truth.json into ``out_dir``.

    b.dcm carries view B's NOMINAL header although its image was rendered
    with the true geometry. A rendered case is required. A case made with
    an imaging chain is written with the chain's bits stored and its
    PixelIntensityRelationship tag (none when the chain has none), and
    truth.json records the chain's values and the anatomy variant.

    Returns
    -------
    dict with keys "a", "b", "seeds", "truth" -> written paths.
    """
    if case.image_a is None or case.image_b is None:
        raise PhantomError("write_phantom_case needs a rendered case (make_phantom(render=True))")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = {
        "a": out / "a.dcm",
        "b": out / "b.dcm",
        "seeds": out / "seeds.json",
        "truth": out / "truth.json",
    }
    for key, view, image, frames in (
        ("a", case.view_a, case.image_a, case.frames_a),
        ("b", case.view_b_nominal, case.image_b, case.frames_b),
    ):
        data = frames if frames is not None else image
        bits = 12 if case.chain is None else case.chain.bits_stored
        pixels = np.clip(np.round(data), 0, (1 << bits) - 1).astype(np.uint16)
        kwargs = {}
        if case.chain is not None:
            kwargs["pixel_intensity_relationship"] = case.chain.tag
        if frames is not None:
            kwargs = {
                "frame_time_ms": 66.6667,
                "r_wave_frames": [case.frame_index],
                "representative_frame": case.frame_index,
            }
        write_xa_dicom(
            paths[key],
            pixels,
            view.nominal(),
            bits_stored=bits,
            series_description=f"coronary3d phantom {case.preset} seed {case.seed} view {key}",
            **kwargs,
        )
    save_seeds(case.seeds, paths["seeds"])
    doc = {
        "version": 1,
        "preset": case.preset,
        "seed": case.seed,
        "frame_index": case.frame_index,
        "view_a": case.view_a.to_dict(),
        "view_b_nominal": case.view_b_nominal.to_dict(),
        "view_b_true": case.view_b_true.to_dict(),
        **case.truth.to_dict(),
    }
    if case.chain is not None:
        doc["chain"] = case.chain.to_dict()
    if case.anatomy is not None:
        doc["anatomy"] = {"name": case.anatomy, **_jsonable(case.anatomy_info)}
    # One top-level key per line: readable, and the long arrays stay compact.
    body = ",\n".join(f" {json.dumps(k)}: {json.dumps(v)}" for k, v in doc.items())
    atomic_write_bytes(paths["truth"], ("{\n" + body + "\n}\n").encode())
    return paths


def _jsonable(info: dict) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in info.items()}


def load_truth(path: str | os.PathLike) -> PhantomTruth:
    """Read truth.json (schema in the module docstring) back into a PhantomTruth.

    An unreadable or malformed file raises :class:`~recon.synth.PhantomError`
    with one line naming it.
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
        seg = doc["segment"]
        sten = doc["stenosis"]
        vessels = tuple(
            (np.asarray(v["X_world"], float).reshape(-1, 3), np.asarray(v["radius_mm"], float))
            for v in doc["vessels"]
        )
        return PhantomTruth(
            vessels=vessels,
            segment_X_world=np.asarray(seg["X_world"], float).reshape(-1, 3),
            segment_radius_mm=np.asarray(seg["radius_mm"], float),
            segment_s_mm=np.asarray(seg["s_mm"], float),
            stenosis_s_mm=float(sten["s_mm"]),
            stenosis_length_mm=float(sten["length_mm"]),
            stenosis_diameter_pct=float(sten["diameter_pct"]),
            mld_mm=float(sten["mld_mm"]),
            reference_diameter_mm=float(sten["reference_diameter_mm"]),
            features_world=np.asarray([f["X_world"] for f in doc["features"]], float).reshape(
                -1, 3
            ),
            feature_names=tuple(str(f["name"]) for f in doc["features"]),
            correction_rotvec=np.asarray(doc["correction_rotvec"], float),
            correction_t_mm=np.asarray(doc["correction_t_mm"], float),
            segment_volume_mm3=float(seg["volume_mm3"]),
            segment_start_s_mm=float(seg.get("start_s_mm", 0.0)),
            vessel_names=tuple(str(v.get("name", "")) for v in doc["vessels"]),
        )
    except OSError as exc:
        raise PhantomError(f"{p}: cannot read ({exc.strerror or exc})") from None
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as exc:
        raise PhantomError(f"{p}: not a valid phantom truth file ({exc})") from None
