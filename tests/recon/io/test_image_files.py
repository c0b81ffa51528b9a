"""recon.io.image_files: PNG/TIFF angiograms with a geometry JSON."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from recon.errors import LoadError
from recon.geometry import ViewGeometry
from recon.io.angiogram import load_angiogram
from recon.types import Angiogram


def _geometry_json(path: Path, **extra: object) -> None:
    data = {
        "alpha_deg": 30.7,
        "beta_deg": 23.6,
        "sid_mm": 976,
        "sod_mm": 720,
        "pixel_spacing_mm": [0.5, 0.4],
    }
    data.update(extra)
    path.write_text(json.dumps(data))


def test_png_with_sidecar_json(tmp_path: Path) -> None:
    pixels = (np.arange(70 * 64).reshape(70, 64) * 13).astype(np.uint16)
    png = tmp_path / "view.png"
    Image.fromarray(pixels).save(png)
    _geometry_json(tmp_path / "view.json", rows=70, cols=64)
    ang = load_angiogram(png)
    assert isinstance(ang, Angiogram)
    np.testing.assert_array_equal(ang.image, pixels.astype(np.float32))
    expected = ViewGeometry(30.7, 23.6, 976.0, 720.0, (0.5, 0.4), rows=70, cols=64)
    assert ang.geometry == expected
    assert ang.n_frames == 1 and ang.frame_reason == "single frame" and ang.frames is None


def test_rgb_tiff_with_named_json_is_grey(tmp_path: Path) -> None:
    grey = np.tile(np.arange(0, 250, 10, dtype=np.uint8), (64, 3))  # (64, 75)
    rgb = np.stack([grey, grey, grey], axis=-1)
    tif = tmp_path / "view.tif"
    Image.fromarray(rgb).save(tif)
    js = tmp_path / "geometry-a.json"
    _geometry_json(js)
    ang = load_angiogram(tif, geometry_json=js)
    np.testing.assert_allclose(ang.image, grey.astype(np.float32), atol=1e-3)
    assert ang.geometry.rows == 64 and ang.geometry.cols == 75


def test_png_geometry_problems(tmp_path: Path) -> None:
    png = tmp_path / "bare.png"
    Image.fromarray(np.zeros((10, 10), np.uint8)).save(png)
    with pytest.raises(LoadError, match=r"bare\.png: alpha_deg is missing"):
        load_angiogram(png)
    _geometry_json(tmp_path / "bare.json", rows=11)
    with pytest.raises(LoadError, match=r"bare\.json: rows is 11"):
        load_angiogram(png)
    _geometry_json(tmp_path / "bare.json", sid=900)
    with pytest.raises(LoadError, match=r"bare\.json: unknown key 'sid'"):
        load_angiogram(png)
    (tmp_path / "bare.json").write_text("{not json")
    with pytest.raises(LoadError, match=r"bare\.json: not valid JSON"):
        load_angiogram(png)
