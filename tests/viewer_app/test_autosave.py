"""Marks are never lost: a crash, a restart, a damaged autosave (real processes)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from viewer_app import ViewerApp

CRASHING_VIEWER = """
import os, signal, sys
import pytest

from viewer_app import ViewerApp
a, b, seeds, autosave = sys.argv[1:5]
app = ViewerApp(a, b, seeds, host="127.0.0.1", port=0, autosave_path=autosave)
app.set_mode("feature")
app.click("a", 150.0, 160.0)  # a landmark still waiting for its partner in B
app.new_segment("RCA distal")
os.kill(os.getpid(), signal.SIGKILL)  # no stop(), no final autosave
"""


def test_marks_and_their_names_survive_a_crash_and_a_restart(
    demo_case: dict[str, Path], tmp_path: Path
) -> None:
    autosave = tmp_path / "auto.json"
    args = [str(demo_case["a"]), str(demo_case["b"]), str(demo_case["seeds"]), str(autosave)]
    proc = subprocess.run([sys.executable, "-c", CRASHING_VIEWER, *args], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == -signal.SIGKILL, proc.stderr
    assert not list(tmp_path.glob(".*tmp"))
    app = ViewerApp(*args[:3], host="127.0.0.1", port=0, autosave_path=autosave)
    try:
        assert app.restored_autosave
        seeds_names = json.loads(demo_case["seeds"].read_text())
        expected = [f["name"] for f in seeds_names["features"]]
        assert [f.name for f in app.seeds().features] == expected  # not "feature N"
        assert "RCA distal" in app.state.segment_names
        assert any(m.kind == "feature" and m.view == "a" and m.raw_px == (150.0, 160.0)
                   for m in app.state.marks)
    finally:
        app.stop()


def test_a_damaged_autosave_does_not_stop_the_viewer_and_is_announced(
    demo_case: dict[str, Path], tmp_path: Path
) -> None:
    autosave = tmp_path / "auto.json"
    autosave.write_bytes(b'{"viewer": {"marks": ["\xff\xfe"]}}')
    app = ViewerApp(str(demo_case["a"]), str(demo_case["b"]), str(demo_case["seeds"]),
                    host="127.0.0.1", port=0, autosave_path=autosave)
    try:
        level, title, body = app.notifications[-1]
        assert level == "warning" and title == "Autosave kept aside"
        kept = app.autosave.kept_aside
        assert kept is not None and str(kept) in body and "not UTF-8" in body
        assert kept.read_bytes() == b'{"viewer": {"marks": ["\xff\xfe"]}}'
        assert app.autosave_notices == [body]  # every page that connects is told
        app.click("a", 100.0, 100.0)
        assert json.loads(autosave.read_text())["autosave_version"] == 2
        assert kept.read_bytes() == b'{"viewer": {"marks": ["\xff\xfe"]}}'
    finally:
        app.stop()


def test_coronary3d_view_starts_with_a_deeply_nested_autosave(
    demo_case: dict[str, Path], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, start_view
) -> None:
    from viewer_app.autosave import default_autosave_path

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    path = default_autosave_path(demo_case["a"], demo_case["b"])
    path.parent.mkdir(parents=True)
    path.write_text('{"viewer": ' + "[" * 100000 + "]" * 100000 + "}")
    view = start_view(cache_dir=tmp_path / "cache")
    assert view.url is not None, (view.line, view.stop())
    assert "Traceback" not in view.stop()
    assert [p.name for p in path.parent.glob("*.damaged-*.json")]


def test_a_tree_survives_load_save_autosave_and_a_restart(
    demo_case: dict[str, Path], tmp_path: Path
) -> None:
    """Issue 15: the viewer saved a branch's marks without its parent and bifurcation."""
    doc = json.loads(demo_case["seeds"].read_text())
    bif = doc["features"][0]
    doc["version"] = 2
    doc["segments"].append({"name": "D1", "parent": doc["segments"][0]["name"],
                            "bifurcation": bif["name"], "a": [bif["a"], [250.0, 330.0]],
                            "b": [bif["b"], [300.0, 330.0]]})
    seeds_path = tmp_path / "tree.json"
    seeds_path.write_text(json.dumps(doc))
    autosave = tmp_path / "auto.json"
    links = [(s["name"], s.get("parent"), s.get("bifurcation")) for s in doc["segments"]]
    app = ViewerApp(str(demo_case["a"]), str(demo_case["b"]), str(seeds_path),
                    host="127.0.0.1", port=0, autosave_path=autosave, out_dir=tmp_path)
    try:
        saved = app.save_seeds(tmp_path / "saved.json")
        assert [(s["name"], s.get("parent"), s.get("bifurcation"))
                for s in json.loads(saved.read_text())["segments"]] == links
        app.set_mode("feature")
        app.click("a", 150.0, 160.0)  # a change: autosaved
        assert [(s["name"], s.get("parent"), s.get("bifurcation"))
                for s in json.loads(autosave.read_text())["segments"]] == links
    finally:
        app.stop()
    app = ViewerApp(str(demo_case["a"]), str(demo_case["b"]), None, host="127.0.0.1",
                    port=0, autosave_path=autosave)
    try:
        assert app.restored_autosave
        assert [(s.name, s.parent, s.bifurcation) for s in app.seeds().segments] == links
    finally:
        app.stop()
