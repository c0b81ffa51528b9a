"""The FFR model (recon.lumen.ffr) against closed forms: a tube, a narrowing, a bifurcation;
its interval from draws; and the inputs it refuses."""

from __future__ import annotations

import numpy as np
import pytest

from recon.lumen.ffr import (
    MMHG_PA,
    FFRError,
    FFRModel,
    FFRVessel,
    Lumen,
    loss_coefficients,
    tree_ffr,
    vessel_ffr,
)
from recon.lumen.measure import lumen_profile

MODEL = FFRModel()
STEP = 0.1


def tube(length_mm: float, radius_mm, reference_mm: float | None = None) -> Lumen:
    s = np.arange(0.0, length_mm + STEP / 2, STEP)
    r = np.broadcast_to(np.asarray(radius_mm, dtype=float), s.shape) if np.ndim(radius_mm) == 0 \
        else np.asarray(radius_mm, dtype=float)
    ref = float(r[0]) if reference_mm is None else reference_mm
    return Lumen(s, np.pi * r**2, np.full(s.shape, np.pi * ref**2))


def poiseuille_mmhg_s_ml(length_mm: float, radius_mm: float) -> float:
    """8 mu L / (pi r^4) in mmHg s / mL."""
    si = 8.0 * MODEL.viscosity_pa_s * length_mm * 1e-3 / (np.pi * (radius_mm * 1e-3) ** 4)
    return si * 1e-6 / MMHG_PA


def cosine_narrowing(pct: float, length_mm: float = 40.0, lesion_mm: float = 10.0,
                     r0: float = 1.5) -> Lumen:
    s = np.arange(0.0, length_mm + STEP / 2, STEP)
    x = (s - length_mm / 2) / lesion_mm
    bump = np.where(np.abs(x) < 0.5, 0.5 * (1.0 + np.cos(2.0 * np.pi * x)), 0.0)
    return tube(length_mm, r0 * (1.0 - pct / 100.0 * bump), r0)


def test_a_straight_tube_gives_poiseuille_at_the_pressure_driven_flow():
    result = vessel_ffr(lumen_profile(*_tube_profile(50.0, 1.6)))
    a = poiseuille_mmhg_s_ml(50.0, 1.6)
    resistance = 100.0 / (0.35 * np.pi * 1.6**2)
    q = 100.0 / (resistance + a)
    assert result.flow_ml_s == pytest.approx(q, rel=1e-6)
    assert result.distal == pytest.approx(resistance * q / 100.0, rel=1e-6)
    assert result.ffr[0] == pytest.approx(1.0)
    # linear along a uniform tube
    np.testing.assert_allclose(result.ffr, 1.0 - a * q * result.s_mm / 50.0 / 100.0, atol=1e-6)


def _tube_profile(length_mm: float, radius_mm: float) -> tuple[np.ndarray, np.ndarray]:
    s = np.arange(0.0, length_mm + STEP / 2, STEP)
    return s, np.full(s.shape, np.pi * radius_mm**2)


@pytest.mark.parametrize("pct", [40.0, 60.0, 75.0])
def test_a_cosine_narrowing_gives_the_closed_form(pct):
    lumen = cosine_narrowing(pct)
    result = tree_ffr([FFRVessel(lumen)], MODEL)[0]
    p, r0, a0 = pct / 100.0, 1.5, np.pi * (1.5e-3) ** 2
    al, be = 1.0 - p / 2.0, p / 2.0
    i4 = np.pi * al * (2 * al**2 + 3 * be**2) / (al**2 - be**2) ** 3.5
    a = 8.0 * np.pi * MODEL.viscosity_pa_s / a0**2 * (0.030 + 0.010 / (2 * np.pi) * i4)
    a *= 1e-6 / MMHG_PA
    b = 0.5 * 1.52 * 1060.0 * (1.0 / (1.0 - p) ** 2 - 1.0) ** 2 / a0**2 * 1e-12 / MMHG_PA
    resistance = 100.0 / (0.35 * np.pi * r0**2)
    q = (-(a + resistance) + np.sqrt((a + resistance) ** 2 + 400.0 * b)) / (2.0 * b)
    assert result.flow_ml_s == pytest.approx(q, rel=1e-5)
    assert result.distal == pytest.approx(resistance * q / 100.0, rel=1e-5)
    # the pressure falls along the vessel, most across the narrowing
    assert np.all(np.diff(result.ffr) <= 1e-12)
    s = result.s_mm
    inside = (s > 15.0) & (s < 25.0)
    assert result.ffr[inside][0] - result.ffr[inside][-1] > 0.5 * (1.0 - result.distal)


def test_a_severe_narrowing_lowers_the_flow_it_does_not_drive_the_pressure_negative():
    healthy = tree_ffr([FFRVessel(cosine_narrowing(0.0))], MODEL)[0]
    severe = tree_ffr([FFRVessel(cosine_narrowing(85.0))], MODEL)[0]
    assert severe.flow_ml_s < 0.6 * healthy.flow_ml_s
    assert 0.0 < severe.distal < 0.5
    # the same narrowing at the healthy (fixed) flow would lose more than Pa
    a, b = loss_coefficients(cosine_narrowing(85.0), MODEL)
    assert a[-1] * healthy.flow_ml_s + b[-1] * healthy.flow_ml_s**2 > 100.0


def test_loss_coefficients_separate_at_the_narrowing_only():
    a, b = loss_coefficients(cosine_narrowing(50.0), MODEL)
    s = np.arange(0.0, 40.0 + STEP / 2, STEP)
    assert np.all(np.diff(a) > 0) and np.all(np.diff(b) >= 0)
    assert np.all(b[s <= 20.0] == 0.0)  # spread from the throat to the narrowing's end
    assert b[s >= 25.0].min() == pytest.approx(b[-1])
    assert loss_coefficients(tube(40.0, 1.5), MODEL)[1][-1] == 0.0


def test_a_bifurcation_splits_by_diameter_to_the_k_and_matches_the_linear_network():
    parent = tube(40.0, 1.5)
    child = tube(20.0, 1.0)
    vessels = [FFRVessel(parent, name="main"),
               FFRVessel(child, parent=0, join_s_mm=15.0, name="side")]
    main, side = tree_ffr(vessels, MODEL)
    # closed form: linear network (no narrowing), outlets by the healthy split
    k = 7.0 / 3.0
    q0 = 0.35 * np.pi * 1.5**2
    share = 1.0**k / (1.0**k + 1.5**k)
    r_main, r_side = 100.0 / (q0 * (1 - share)), 100.0 / (q0 * share)
    a1, a2 = poiseuille_mmhg_s_ml(15.0, 1.5), poiseuille_mmhg_s_ml(25.0, 1.5)
    a3 = poiseuille_mmhg_s_ml(20.0, 1.0)
    r_down = 1.0 / (1.0 / (a2 + r_main) + 1.0 / (a3 + r_side))
    q = 100.0 / (a1 + r_down)
    p_join = 100.0 - a1 * q
    q_main, q_side = p_join / (a2 + r_main), p_join / (a3 + r_side)
    assert main.flow_ml_s == pytest.approx(q, rel=1e-6)
    assert side.flow_ml_s == pytest.approx(q_side, rel=1e-6)
    assert main.distal == pytest.approx(r_main * q_main / 100.0, rel=1e-6)
    assert side.distal == pytest.approx(r_side * q_side / 100.0, rel=1e-6)
    assert side.ffr[0] == pytest.approx(p_join / 100.0, rel=1e-6)  # starts at the join
    # Murray's exponent gives the side branch a smaller share
    murray = tree_ffr(vessels, FFRModel(split_exponent=3.0))
    assert murray[1].flow_ml_s < side.flow_ml_s


def test_a_narrowed_branch_takes_less_of_the_flow():
    vessels = [FFRVessel(tube(40.0, 1.5)), FFRVessel(tube(20.0, 1.2), 0, 15.0)]
    healthy = tree_ffr(vessels, MODEL)
    narrowed = tree_ffr([vessels[0], FFRVessel(cosine_narrowing(70.0, 20.0, 6.0, 1.2), 0,
                                               15.0)], MODEL)
    assert narrowed[1].flow_ml_s < 0.85 * healthy[1].flow_ml_s
    assert narrowed[1].distal < healthy[1].distal - 0.1
    assert narrowed[0].distal > healthy[0].distal  # the main keeps more of the pressure


def test_the_interval_spreads_with_the_draws_and_the_band_is_over_the_flow():
    nominal = cosine_narrowing(55.0)
    same = tree_ffr([FFRVessel(nominal, draws=(nominal,) * 8)], MODEL)[0]
    assert same.ci95 == pytest.approx((same.distal, same.distal), abs=1e-9)
    rng = np.random.default_rng(3)
    lesion = (nominal.s_mm > 15.0) & (nominal.s_mm < 25.0)  # the draws move the narrowing's area
    draws = tuple(Lumen(nominal.s_mm, nominal.area_mm2 * np.where(lesion, f, 1.0),
                        nominal.reference_area_mm2) for f in rng.normal(1.0, 0.08, 32))
    spread = tree_ffr([FFRVessel(nominal, draws=draws)], MODEL)[0]
    lo, hi = spread.ci95
    assert lo < spread.distal < hi and hi - lo > 0.02
    assert spread.n_draws == 32 and np.all(spread.ffr_lo <= spread.ffr_hi)
    # a higher velocity means more flow and a lower FFR; the band brackets the 0.35 m/s value
    slow, fast = spread.band[:, -1]
    assert fast < spread.distal < slow
    report = spread.to_dict()
    assert report["flow_band"]["velocity_m_s"] == [0.25, 0.45]
    assert "not a confidence interval" in report["flow_band"]["label"]
    assert report["ci95"] == [round(lo, 4), round(hi, 4)]
    assert "not validated" in report["research_use"]


def test_a_closed_lumen_is_refused_naming_the_place():
    lumen = cosine_narrowing(50.0)
    area = lumen.area_mm2.copy()
    area[200] = 0.0
    with pytest.raises(FFRError, match=r"segment 'LAD': the lumen closes at 20\.0 mm"):
        tree_ffr([FFRVessel(Lumen(lumen.s_mm, area, lumen.reference_area_mm2), name="LAD")])


def test_a_segment_too_short_is_refused():
    with pytest.raises(FFRError, match=r"is 4\.0 mm long; at least 5 mm"):
        tree_ffr([FFRVessel(tube(4.0, 1.5))])
    tree_ffr([FFRVessel(tube(5.0, 1.5))])  # long enough


@pytest.mark.parametrize("kwargs, words", [
    ({"aortic_pressure_mmhg": 20.0}, "aortic pressure 20 mmHg is outside"),
    ({"aortic_pressure_mmhg": float("nan")}, "aortic pressure nan"),
    ({"velocity_m_s": 0.0}, "velocity 0 m/s is outside"),
    ({"velocity_m_s": 3.0}, "velocity 3 m/s is outside"),
    ({"split_exponent": 4.0}, "split exponent 4"),
])
def test_values_outside_a_physical_range_are_refused(kwargs, words):
    with pytest.raises(FFRError, match=words):
        FFRModel(**kwargs)


def test_the_distal_resistance_follows_the_aortic_pressure():
    lumen = tube(40.0, 1.5)
    a = poiseuille_mmhg_s_ml(40.0, 1.5)
    for pa in (70.0, 100.0, 140.0):
        resistance = pa / (0.35 * np.pi * 1.5**2)  # R = Pa / (v A_ref)
        result = tree_ffr([FFRVessel(lumen)], FFRModel(aortic_pressure_mmhg=pa))[0]
        assert result.distal == pytest.approx(resistance / (resistance + a), rel=1e-6)
    # the same healthy velocity at a lower pressure: the narrowing's loss is a larger share
    narrowed = cosine_narrowing(60.0)
    assert tree_ffr([FFRVessel(narrowed)], FFRModel(aortic_pressure_mmhg=70.0))[0].distal < \
        tree_ffr([FFRVessel(narrowed)], MODEL)[0].distal - 0.03


def test_the_separation_loss_of_many_narrowings_is_their_sum():
    """A noisy lumen (many short runs below its reference): b, vectorised, equals the sum
    over the narrowings written out one by one."""
    rng = np.random.default_rng(5)
    s = np.arange(0.0, 60.0, 0.25)
    ref = np.pi * 1.4**2 * np.ones_like(s)
    area = ref * (1.0 + 0.06 * rng.standard_normal(len(s)))
    area[100:130] *= 0.4
    _, b = loss_coefficients(Lumen(s, area, ref), MODEL)
    expected = np.zeros_like(s)
    below = np.flatnonzero(area < ref)
    runs = np.split(below, np.flatnonzero(np.diff(below) > 1) + 1)
    assert len(runs) > 10
    for run in runs:
        throat, last = run[np.argmin(area[run])], run[-1]
        a0, amin = ref[throat] * 1e-6, area[throat] * 1e-6
        c = 0.5 * 1.52 * 1060.0 * (a0 / amin - 1.0) ** 2 / a0**2 * 1e-12 / MMHG_PA
        ramp = np.clip((s - s[throat]) / (s[last] - s[throat]), 0, 1) if last > throat else \
            (s >= s[throat]).astype(float)
        expected += c * ramp
    np.testing.assert_allclose(b, expected, rtol=1e-12, atol=1e-15)


def _wide_start_tube(wide_mm: float = 3.5, r0: float = 1.5) -> Lumen:
    """A 40 mm tube of radius r0 whose first ``wide_mm`` have twice the radius (a trace
    that starts on the guiding catheter), its reference r0 throughout."""
    s = np.arange(0.0, 40.0 + STEP / 2, STEP)
    r = np.where(s <= wide_mm, 2.0 * r0, r0)
    return Lumen(s, np.pi * r**2, np.full(s.shape, np.pi * r0**2))


def test_a_ref_from_the_reference_ignores_a_wrong_first_millimetre():
    """R = Pa / (v A_ref): from the lumen (the default, as the issue defines it) A_ref is
    the mean area of the first 3 mm, 4 pi r0^2 here, a quarter of the resistance; from
    the fitted reference (inlet_area="reference") it is pi r0^2 however wide they are."""
    lumen = _wide_start_tube()
    assert FFRModel().inlet_area == "lumen"
    for source, area_ref in (("reference", np.pi * 1.5**2), ("lumen", 4.0 * np.pi * 1.5**2)):
        result = tree_ffr([FFRVessel(lumen)], FFRModel(inlet_area=source))[0]
        resistance = 100.0 / (0.35 * area_ref)
        assert result.distal * 100.0 / result.flow_ml_s == pytest.approx(resistance, rel=1e-6)
        # the distal pressure is R Q; the loss the lumen's viscous integral at that flow
        a, b = loss_coefficients(lumen, MODEL)
        q = result.flow_ml_s
        assert b[-1] == 0.0
        assert q == pytest.approx(100.0 / (resistance + a[-1]), rel=1e-6)
    # on a healthy tube the two agree
    healthy = tube(40.0, 1.5)
    assert tree_ffr([FFRVessel(healthy)], FFRModel(inlet_area="reference"))[0].distal == \
        pytest.approx(tree_ffr([FFRVessel(healthy)])[0].distal, rel=1e-12)


def test_a_ref_from_the_reference_averages_a_tapering_reference():
    """A tapering reference d(s) = 3.2 - 0.02 s mm: A_ref is the mean of pi d^2 / 4 over the
    points of the first 3 mm (s = 0, 0.1, ..., 3.0), not the lumen's area there."""
    s = np.arange(0.0, 40.0 + STEP / 2, STEP)
    d = 3.2 - 0.02 * s
    lumen = Lumen(s, np.pi / 4.0 * (0.9 * d) ** 2, np.pi / 4.0 * d**2)
    first = np.arange(31) * 0.1
    expected = float(np.mean(np.pi / 4.0 * (3.2 - 0.02 * first) ** 2))
    assert lumen.inlet_area_mm2(3.0, "reference") == pytest.approx(expected, rel=1e-12)
    assert lumen.inlet_area_mm2(3.0) == pytest.approx(0.81 * expected, rel=1e-12)
    result = tree_ffr([FFRVessel(lumen)], FFRModel(inlet_area="reference"))[0]
    assert result.distal * 100.0 / result.flow_ml_s == pytest.approx(
        100.0 / (0.35 * expected), rel=1e-6)


def test_an_unknown_inlet_area_is_refused():
    with pytest.raises(FFRError, match="inlet area 'raw' is not one of lumen, reference"):
        FFRModel(inlet_area="raw")


def test_one_vessels_coefficients_give_the_solvers_ffr_in_closed_form():
    """vessel_coefficients + distal_ffr (no solver) equal tree_ffr's distal FFR on a 65 %
    cosine narrowing, for both sources of A_ref; R is Pa / (v pi r0^2)."""
    from recon.lumen.ffr import distal_ffr, vessel_coefficients

    lumen = cosine_narrowing(65.0)
    for source in ("lumen", "reference"):
        model = FFRModel(inlet_area=source)
        r, a, b = vessel_coefficients(lumen, model)
        assert r == pytest.approx(100.0 / (0.35 * np.pi * 1.5**2), rel=1e-9)
        assert a > 0.0 and b > 0.0
        assert distal_ffr(r, a, b, 100.0) == pytest.approx(
            tree_ffr([FFRVessel(lumen)], model)[0].distal, abs=1e-8)
