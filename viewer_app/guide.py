"""The guided order of the marks and the page's guide line (a part of
:class:`viewer_app.state.MarkState`, its base class, kept in its own module).

In the guided mode a click in a view places the first thing that view still lacks: the
current segment's proximal end, then its distal end, then landmarks. When view B's header
geometry is far off before Calibrate (a correspondence already clicked lies at least
:data:`LARGE_HEADER_ERROR_PX` from its magenta line: 39-45 px on IM7 / IM8), the magenta
lines cannot guide B's ends; the order then asks for a landmark pair before B's remaining
end and the guide line says to press Calibrate, which corrects the lines.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from recon.geometry import epipolar_lines
from viewer_app.marks import KIND_WORDS, VIEWS, check_view, other_view

if TYPE_CHECKING:
    from collections.abc import Callable

    from recon.geometry import ViewGeometry
    from recon.seeds import Seeds
    from viewer_app.marks import Mark

__all__ = ["LARGE_HEADER_ERROR_PX", "PAIRING_DOUBT_PX", "GuidedOrder"]

#: A landmark paired at least this far (px) from its partner's epipolar line, and at
#: most half as far from that of another landmark still waiting, is doubted.
PAIRING_DOUBT_PX = 12.0
#: Before Calibrate, a correspondence this far (px) from its magenta line means view B's
#: header geometry is off by more than the lines can guide (snapped clicks on a good
#: header lie within a few px: the demo's 3).
LARGE_HEADER_ERROR_PX = 15.0  # (the page's MarkState.header_check_px)


class GuidedOrder:
    """What a guided click places, the guide line, and the landmark pairs' checks."""

    # the state these methods use (MarkState's)
    marks: list[Mark]
    mode: str
    current_segment: int
    view_b_calibrated: ViewGeometry | None
    _guide_id: int | None
    #: a correspondence this far (px) from its magenta line before Calibrate puts a
    #: landmark pair first and the guide line says so; None: never (the page's state
    #: takes LARGE_HEADER_ERROR_PX)
    header_check_px: float | None

    # ... and its methods
    geometry: Callable[[str], ViewGeometry]
    mark_by_id: Callable[[int | None], Mark | None]
    partner: Callable[[Mark], Mark | None]
    label: Callable[[Mark], str]
    marks_by_group: Callable[..., Mark]
    to_seeds: Callable[[], Seeds]
    _feature_group_for: Callable[..., int]

    def _has(self, kind: str, view: str, group: int) -> bool:
        return any(m.kind == kind and m.view == view and m.group == group for m in self.marks)

    def header_error_px(self) -> float | None:
        """Before Calibrate, how far (px) the correspondences clicked in B (the current
        segment's ends, the landmark pairs) lie from their magenta (epipolar) lines of
        A under the header geometry, the largest; None once calibrated, before any, or
        without :attr:`header_check_px`."""
        if self.view_b_calibrated is not None or self.header_check_px is None:
            return None
        pairs = [(m, p) for m in self.marks if m.view == "a" and m.kind != "waypoint"
                 and (m.kind == "feature" or m.group == self.current_segment)
                 and (p := self.partner(m)) is not None]
        if not pairs:
            return None
        lines = epipolar_lines(np.array([m.point_px for m, _ in pairs]), self.geometry("a"),
                               self.geometry("b"))
        b_px = np.array([[*p.point_px, 1.0] for _, p in pairs])
        return float(np.max(np.abs(np.sum(lines * b_px, axis=1))))

    def _header_far_off(self) -> float | None:
        """The header's error (px, :meth:`header_error_px`) when it is at least
        :attr:`header_check_px`, else None."""
        error = self.header_error_px()
        return error if error is not None and error >= self.header_check_px else None

    def _landmark_first(self) -> bool:
        """Whether a landmark pair is to come before the ends still missing: the header is
        far off and no landmark pair is complete yet."""
        return (self._header_far_off() is not None
                and not any(m.kind == "feature" and self.partner(m) is not None
                            for m in self.marks))

    def guided_kind(self, view: str) -> str:
        """What a guided click in ``view`` places: the current segment's proximal end,
        then its distal end, then a landmark; a landmark before a missing end while the
        header is far off and no landmark pair is complete (module docstring)."""
        first = None
        for end in ("proximal", "distal"):
            if not self._has(end, check_view(view), self.current_segment):
                first = end
                break
        if first is None or (first == "distal" and self._landmark_first()):
            return "feature"
        return first

    def _guide_after(self, mark: Mark) -> int | None:
        """The mark whose epipolar line shows where the next click in the other view
        belongs: the partner-to-be of what that click will place."""
        other = other_view(mark.view)
        kind = self.guided_kind(other)
        if kind == "feature":
            group = self._feature_group_for(other)
            cand = [m for m in self.marks if m.kind == "feature" and m.group == group
                    and m.view == mark.view]
        else:
            cand = [m for m in self.marks if m.kind == kind and m.group == self.current_segment
                    and m.view == mark.view]
        return cand[-1].id if cand else mark.id

    def next_clicks(self) -> dict[str, str]:
        """What the next click in each view places, in words ({"a": "distal end", ...})."""
        if self.mode == "guided":
            return {v: KIND_WORDS[self.guided_kind(v)] for v in VIEWS}
        return {v: KIND_WORDS[self.mode] for v in VIEWS}

    def guide_text(self, blocked: str | None = None) -> str:
        """One line for the page: what to click next in A and in B, whether the current
        segment is ready to reconstruct and, while the header is far off, to press
        Calibrate. ``blocked``: why Reconstruct would be refused now (files of two
        patients unconfirmed), said in place of "press Reconstruct"."""
        nxt = self.next_clicks()
        ends_done = all(self._has(e, v, self.current_segment)
                        for e in ("proximal", "distal") for v in VIEWS)
        text = f"Next click in **A**: {nxt['a']} · in **B**: {nxt['b']}."
        guide = self.mark_by_id(self._guide_id)
        if guide is not None and self.partner(guide) is None:
            text += (f" The magenta line in {other_view(guide.view).upper()} shows where "
                     f"{self.label(guide)} lies there.")
        for view in VIEWS:
            waiting = [f"F{g + 1}" for g in self.waiting_landmarks(view)]
            if len(waiting) == 1:
                text += (f" Landmark {waiting[0]} waits for its partner in "
                         f"{other_view(view).upper()} (on the magenta line).")
            elif waiting:
                text += (f" Landmarks {', '.join(waiting)} wait for their partners in "
                         f"{other_view(view).upper()}, in that order: the next landmark "
                         f"clicked there pairs with {waiting[0]} (on the magenta line).")
        error = self._header_far_off()
        far = error is not None
        if far:
            text += (f" ⚠ View B's header geometry is off: a mark in B lies {error:.0f} px "
                     "from its magenta line, so the lines are only a rough guide there. "
                     + ("Click a landmark pair (a branch point in A, then in B) next; "
                        if self._landmark_first() else "")
                     + "press **Calibrate** once the segment's ends are in both views: it "
                     "corrects the lines.")
        if ends_done:
            n = len(self.to_seeds().features)
            then = "press **Calibrate**, then **Reconstruct**" if far else \
                "press **Reconstruct**"
            text += (f" ✔ Segment marked; before Reconstruct: {blocked}." if blocked else
                     f" ✔ Segment ready: {then}.")
            text += (f" {n} landmark pair(s): branch points seen in both views make the "
                     f"calibration firmer ({2 + n} of 5 correspondences).")
        return text

    def waiting_landmarks(self, view: str) -> list[int]:
        """The landmark groups placed in ``view`` only, oldest first: the next landmark
        clicked in the other view pairs with the first."""
        return sorted({m.group for m in self.marks if m.kind == "feature" and m.view == view
                       and self.partner(m) is None})

    def pairing_doubt(self, mark: Mark) -> str | None:
        """When ``mark``, a landmark that has just been paired, lies much nearer the
        magenta (epipolar) line of another landmark still waiting than that of its
        partner: one line saying so (the clicks may be out of order), else None."""
        partner = self.partner(mark) if mark.kind == "feature" else None
        if partner is None:
            return None
        others = [self.marks_by_group(g, partner.view) for g in
                  self.waiting_landmarks(partner.view)]
        if not others:
            return None
        src, dst = self.geometry(partner.view), self.geometry(mark.view)
        lines = epipolar_lines(np.asarray([partner.point_px] + [o.point_px for o in others]),
                               src, dst)
        p = np.array([*mark.point_px, 1.0])
        dist = np.abs(lines @ p) / np.hypot(lines[:, 0], lines[:, 1])
        k = int(np.argmin(dist[1:])) + 1
        if dist[0] < PAIRING_DOUBT_PX or dist[k] > 0.5 * dist[0]:
            return None
        near = self.label(others[k - 1])
        return (f"{self.label(mark)} in {mark.view.upper()} was paired with "
                f"{self.label(partner)} in {partner.view.upper()} (landmarks pair in click "
                f"order) but lies {dist[0]:.0f} px off its magenta line and {dist[k]:.0f} px "
                f"off {near}'s: if it is {near}'s partner, press Undo and click "
                f"{self.label(partner)}'s partner first, or drag the marks where they belong")
