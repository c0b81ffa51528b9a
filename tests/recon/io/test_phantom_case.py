"""The phantom's case files (recon/io/phantom_case.py)."""

import json

import numpy as np
import pytest

from recon.geometry import ViewGeometry
from recon.io import load_angiogram, load_seeds
from recon.io.phantom_case import load_truth, write_phantom_case
from recon.synth import PhantomError, make_phantom


@pytest.fixture(scope="module")
def rendered():
    return make_phantom("data1", 3, stenosis_pct=50.0)


def test_write_phantom_case_round_trip(rendered, tmp_path):
    paths = write_phantom_case(rendered, tmp_path / "case")
    assert set(paths) == {"a", "b", "seeds", "truth"}
    assert load_seeds(paths["seeds"]) == rendered.seeds
    truth = load_truth(paths["truth"])
    assert np.allclose(truth.segment_X_world, rendered.truth.segment_X_world, atol=1e-5)
    assert np.allclose(truth.correction_rotvec, rendered.truth.correction_rotvec)
    assert truth.feature_names == rendered.truth.feature_names
    assert truth.segment_volume_mm3 == pytest.approx(rendered.truth.segment_volume_mm3)
    doc = json.loads(paths["truth"].read_text())
    assert ViewGeometry.from_dict(doc["view_b_true"]) == rendered.view_b_true
    assert ViewGeometry.from_dict(doc["view_b_nominal"]) == rendered.view_b_nominal

    for key, view, image in (
        ("a", rendered.view_a, rendered.image_a),
        ("b", rendered.view_b_nominal, rendered.image_b),
    ):
        angio = load_angiogram(paths[key])
        assert angio.geometry == view  # the NOMINAL header for b
        assert np.array_equal(np.asarray(angio.image, dtype=np.float32), image)


def test_load_truth_names_the_bad_file(tmp_path):
    bad = tmp_path / "truth.json"
    bad.write_text("{}")
    with pytest.raises(PhantomError, match="truth.json"):
        load_truth(bad)


def test_load_truth_names_a_missing_file(tmp_path):
    missing = tmp_path / "nowhere" / "truth.json"
    with pytest.raises(PhantomError, match=r"truth\.json: cannot read"):
        load_truth(missing)


def test_write_phantom_case_needs_a_rendered_case(tmp_path):
    case = make_phantom("data1", 3, render=False)
    with pytest.raises(PhantomError, match="rendered"):
        write_phantom_case(case, tmp_path / "case")
    assert not (tmp_path / "case").exists()
