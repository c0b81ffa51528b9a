"""The plain phantom is bit-identical to what it was before imaging chains and anatomy variants.

The hashes were computed from ``make_phantom(preset, seed)`` before those
options existed; every default argument must still give exactly those
images, clicks and truth (the regular benchmarks' figures stand on them).
"""

import hashlib

import numpy as np
import pytest

from recon.synth import make_phantom

#: sha256 of image_a bytes + image_b bytes + repr(seeds), and of the truth's
#: segment_X_world bytes + segment_radius_mm bytes.
EXPECTED = {
    ("static", 7): (
        "5406d8baef4d4e21340c95e3ad28295c3cdae6972422d83cf827e9bb6afb6e74",
        "f4471a9074c91a4e01f0fba9235e031926a528c3d60fcc6f2725a9afa50eb958",
    ),
    ("data2", 3): (
        "782020908931ac52193e47dd65f7f5a1cfb17db1f4caf59ca3833766ae956cff",
        "0302547e8c350b4affe187db05ef82112bf8c9f30fa54e523f48c70542ae1b53",
    ),
}


@pytest.mark.parametrize(("preset", "seed"), sorted(EXPECTED))
def test_the_plain_phantom_is_unchanged(preset: str, seed: int) -> None:
    case = make_phantom(preset, seed)
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(case.image_a).tobytes())
    h.update(np.ascontiguousarray(case.image_b).tobytes())
    h.update(repr(case.seeds).encode())
    truth = hashlib.sha256(
        np.ascontiguousarray(case.truth.segment_X_world).tobytes()
        + np.ascontiguousarray(case.truth.segment_radius_mm).tobytes()
    ).hexdigest()
    assert (h.hexdigest(), truth) == EXPECTED[(preset, seed)]
    assert case.chain is None and case.anatomy is None and case.catheter is None


def test_explicit_defaults_are_the_plain_phantom() -> None:
    a = make_phantom("data1", 5, render=False)
    b = make_phantom("data1", 5, render=False, chain=None, anatomy=None)
    assert a.seeds == b.seeds
    assert np.array_equal(a.truth.segment_X_world, b.truth.segment_X_world)
    assert a.view_a == b.view_a and a.view_b_true == b.view_b_true
