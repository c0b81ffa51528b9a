"""make_phantom: determinism, independence of the streams, bad requests (recon/synth/case.py)."""

from pathlib import Path

import numpy as np
import pytest

import recon.synth
from recon.errors import CoronaryError
from recon.synth import PhantomError, make_phantom


def test_same_seed_same_case_and_other_seed_differs():
    a = make_phantom("data2", 11, render=False)
    b = make_phantom("data2", 11, render=False)
    c = make_phantom("data2", 12, render=False)
    assert a.seeds == b.seeds
    assert np.array_equal(a.truth.segment_X_world, b.truth.segment_X_world)
    assert np.array_equal(a.truth.correction_t_mm, b.truth.correction_t_mm)
    assert not np.array_equal(a.truth.correction_t_mm, c.truth.correction_t_mm)
    assert a.image_a is None and a.image_b is None


def test_stenosis_percentage_does_not_change_the_tree():
    a = make_phantom("static", 4, stenosis_pct=30.0, render=False)
    b = make_phantom("static", 4, stenosis_pct=70.0, render=False)
    assert a.seeds == b.seeds
    assert np.array_equal(a.truth.segment_X_world, b.truth.segment_X_world)
    assert a.truth.mld_mm > b.truth.mld_mm


def test_bad_requests_raise_value_errors():
    with pytest.raises(ValueError, match="unknown phantom preset"):
        make_phantom("data9")
    with pytest.raises(ValueError, match="stenosis_pct"):
        make_phantom("data1", stenosis_pct=100.0)


def test_bad_requests_are_coronary_errors():
    assert issubclass(PhantomError, CoronaryError)
    with pytest.raises(PhantomError, match="n_frames"):
        make_phantom("data1", n_frames=0)


def test_the_package_touches_no_files():
    """recon.synth returns arrays and dataclasses: no json, pydicom or file writing."""
    for path in Path(recon.synth.__file__).parent.glob("*.py"):
        text = path.read_text(encoding="utf-8")
        banned = ("import json", "pydicom", "open(", "write_bytes", "write_text", "from recon.io")
        for word in banned:
            assert word not in text, (path.name, word)
