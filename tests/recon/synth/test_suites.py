"""The varied suite: chains x cases, geometries and anatomy cycling (recon/synth/suites.py)."""

from collections import Counter

import numpy as np

from recon.synth import ANATOMIES, CHAINS, PRESETS, VARIED_CHAINS, varied_cases
from recon.synth.suites import MIN_SEPARATION_DEG, make_suite_case


def test_the_varied_suite_has_every_chain_and_variant():
    cases = varied_cases()
    assert len(cases) == 8 * len(VARIED_CHAINS) and len(VARIED_CHAINS) >= 7
    assert set(CHAINS) < set(VARIED_CHAINS)
    per_chain = Counter(c.chain for c in cases)
    assert set(per_chain) == set(VARIED_CHAINS) and set(per_chain.values()) == {8}
    assert set(Counter(c.anatomy for c in cases)) == set(ANATOMIES)
    for chain in VARIED_CHAINS:  # every chain meets the plain tree and every harder variant
        assert {c.anatomy for c in cases if c.chain == chain} == set(ANATOMIES)
    table1 = {c.preset for c in cases if isinstance(c.preset, str)}
    assert table1 == set(PRESETS)
    assert sum(not isinstance(c.preset, str) for c in cases) == 4 * len(VARIED_CHAINS)
    assert len({(c.preset_name, c.seed) for c in cases}) == len(cases)
    assert varied_cases() == cases  # seeded: the same list every time
    assert varied_cases(seed=1) != cases


def test_random_geometries_are_at_least_30_degrees_apart():
    for c in varied_cases(8, seed=3):
        if isinstance(c.preset, str):
            continue
        da, db = c.preset.view_a.nominal_axes[2], c.preset.view_b.nominal_axes[2]
        sep = np.degrees(np.arccos(np.clip(da @ db, -1, 1)))
        assert sep >= MIN_SEPARATION_DEG
        assert c.to_dict()["geometry"]["a"]["alpha_deg"] == c.preset.view_a.alpha_deg


def test_a_suite_case_is_made_with_its_chain_and_anatomy():
    spec = varied_cases(2)[1]  # a random geometry
    case = make_suite_case(spec, render=False)
    assert case.preset == spec.preset_name and case.seed == spec.seed
    assert case.chain.name == spec.chain and case.anatomy == spec.anatomy
