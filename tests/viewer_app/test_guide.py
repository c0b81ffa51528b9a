"""The guided order and the guide line (viewer_app.guide): a landmark pair asked for
first when view B's header is far off before Calibrate (issue 46's smaller points), and
the guide line saying what to do while two patients' files wait for a confirmation."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from recon.io import load_angiogram, load_seeds
from viewer_app.guide import LARGE_HEADER_ERROR_PX
from viewer_app.patients import CONFIRM_LABEL
from viewer_app.state import MarkState


@pytest.fixture()
def demo(demo_case: dict[str, Path]) -> tuple:
    a, b = load_angiogram(str(demo_case["a"])), load_angiogram(str(demo_case["b"]))
    return a.geometry, b.geometry, load_seeds(demo_case["seeds"])


def test_a_far_off_header_asks_for_a_landmark_pair_before_b_s_distal_end(demo: tuple) -> None:
    view_a, view_b, seeds = demo
    seg, feat = seeds.segments[0], seeds.features[0]
    # B's header 10 mm off along its ray (the demo's true geometry otherwise): the
    # segment's proximal end in B lies 37 px from its magenta line, as on IM7 / IM8.
    st = MarkState(view_a, replace(view_b, t_corr_mm=(0.0, 0.0, 10.0)),
                   header_check_px=LARGE_HEADER_ERROR_PX)
    st.click("a", *seg.a_px[0])
    st.click("a", *seg.a_px[-1])
    assert st.header_error_px() is None and st.guided_kind("b") == "proximal"
    st.click("b", *seg.b_px[0])
    assert st.header_error_px() > 30.0
    assert st.guided_kind("b") == "feature" and st.guided_kind("a") == "feature"
    text = st.guide_text()
    assert text.startswith("Next click in **A**: landmark · in **B**: landmark.")
    assert "View B's header geometry is off" in text and "Click a landmark pair" in text
    assert "press **Calibrate**" in text and "Segment ready" not in text
    assert st.click("a", *feat.a_px).kind == "feature"
    assert st.click("b", *feat.b_px).kind == "feature"
    assert st.guided_kind("b") == "distal"  # the pair is there: B's remaining end
    assert "Click a landmark pair" not in st.guide_text()
    assert st.click("b", *seg.b_px[-1]).kind == "distal"
    assert "✔ Segment ready: press **Calibrate**, then **Reconstruct**." in st.guide_text()
    st.set_calibrated_b(view_b)  # calibrated: the lines fit, nothing more to say
    assert st.header_error_px() is None
    text = st.guide_text()
    assert "✔ Segment ready: press **Reconstruct**." in text and "header" not in text


def test_a_good_header_keeps_the_order_ends_then_landmarks(demo: tuple) -> None:
    view_a, view_b, seeds = demo
    seg = seeds.segments[0]
    st = MarkState(view_a, view_b, header_check_px=LARGE_HEADER_ERROR_PX)
    for view, px in (("a", seg.a_px[0]), ("a", seg.a_px[-1]), ("b", seg.b_px[0])):
        st.click(view, *px)
    assert st.header_error_px() < LARGE_HEADER_ERROR_PX
    assert st.guided_kind("b") == "distal"
    assert "header" not in st.guide_text()
    off = MarkState(view_a, replace(view_b, t_corr_mm=(0.0, 0.0, 10.0)))  # no check asked
    for view, px in (("a", seg.a_px[0]), ("a", seg.a_px[-1]), ("b", seg.b_px[0])):
        off.click(view, *px)
    assert off.header_error_px() is None and off.guided_kind("b") == "distal"


def test_the_guide_line_says_what_to_do_while_reconstruct_would_be_refused(
        demo: tuple) -> None:
    view_a, view_b, seeds = demo
    st = MarkState(view_a, view_b)
    st.load_seeds(seeds)
    assert "✔ Segment ready: press **Reconstruct**." in st.guide_text()
    text = st.guide_text("confirm the patients")
    assert "✔ Segment marked; before Reconstruct: confirm the patients." in text
    assert "press **Reconstruct**" not in text


def test_the_page_s_guide_line_waits_for_the_two_patients_confirmation(
        app: object, demo_case: dict[str, Path], tmp_path: Path) -> None:
    from test_app import _other_patient_copy  # tests/viewer_app/test_app.py

    other = _other_patient_copy(demo_case["b"], tmp_path / "b_other.dcm")
    app.access.add_read_root(tmp_path)
    assert app.open_pair(str(demo_case["a"]), str(other))
    app.load_seeds(str(demo_case["seeds"]))
    guide = app.panels.marks.guide
    assert f"before Reconstruct: files A and B name different patients: press " \
           f"**{CONFIRM_LABEL}** above" in guide.content
    assert "Segment ready" not in guide.content
    app.confirm_one_patient()
    assert "✔ Segment ready: press **Reconstruct**." in guide.content
