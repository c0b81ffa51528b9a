"""A small deterministic generator of bad inputs for the `coronary3d` command.

Each case is a :class:`FuzzCase`: a family name, the argv to give
``recon.cli.main`` and what is expected: ``"refused"`` (exit 2, one line
``coronary3d: error: ...``, no output folder) or ``"no_traceback"`` (odd
input that may be read or refused, but never with a traceback; used for
byte-flipped files, where a flip may land somewhere harmless). The files a
case needs are written under the folder given to :func:`make_cases`.

Families (issue 17): DICOM header values out of range or invalid, odd DICOM
values, corrupted bytes, broken seeds files, broken geometry / sidecar JSON,
absurd command-line values, argparse usage errors, output folders that must
be refused and left as they were (``outputs``, ``outputs-random``) and jobs
past their memory or CPU-time limit (``limits``). Signals during a run are
real processes: :func:`signal_run` (tests/fuzz_run.py ``--signals N``).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pydicom
from PIL import Image

from recon.geometry import ViewGeometry
from recon.io.dicom_write import write_xa_dicom

DEMO = Path(__file__).resolve().parents[1] / "assets" / "demo"
SIZE_PX = 96

# Bad values per DICOM geometry tag (strings go in as raw DS text)
_BAD_HEADER = {
    "DistanceSourceToDetector": ["0", "-1", "NaN", "abc", "1e9", "1e308", "1e-9", "5000", "100",
                                 "699.9", "1300.5", "inf"],
    "DistanceSourceToPatient": ["0", "-1", "NaN", "abc", "0.001", "1", "399", "976", "2000"],
    "ImagerPixelSpacing": ["0.1\\10", "1e-9", "1e9", "0", "NaN", "a\\b", "0.1\\0.2\\0.3", "-0.3",
                           "600", "0.04"],
    "PositionerPrimaryAngle": ["1e9", "200", "-181", "NaN", "abc", "inf"],
    "PositionerSecondaryAngle": ["91", "-90.5", "1e9", "NaN", "xyz"],
}
# Fallback tags, tried with the tag they stand in for removed
_BAD_FALLBACK = {
    ("EstimatedRadiographicMagnificationFactor", "DistanceSourceToPatient"):
        ["1e9", "0", "-1", "abc", "NaN", "1", "0.5", "100"],
    ("PixelSpacing", "ImagerPixelSpacing"): ["1e9", "0", "x", "1e-9", "5\\5", "NaN"],
    ("FieldOfViewDimensions", "ImagerPixelSpacing"): ["1e9", "0\\0", "x", "1\\1", "1e6\\1e6"],
}
_BAD_FLAGS = {
    "--sid-mm": ["5000", "0", "-1", "nan", "inf", "1e308", "x", "699", "1301"],
    "--sod-mm": ["0", "-5", "1e9", "nan", "399", "1500"],
    "--pixel-spacing-mm": ["0", "-0", "600", "5000", "1e9", "1e-9", "nan", "-inf", "0.01", "abc"],
    "--alpha-deg": ["1e9", "X", "nan", "181", "-500"],
    "--beta-deg": ["91", "-1e9", "inf", "q"],
    "--frame-a": ["-1", "x", "1.5"],
    "--segment": ["-1", "z"],
    "--max-memory-gb": ["-1", "nan", "x"],
    "--max-cpu-s": ["-5", "inf"],
}


@dataclass(frozen=True)
class FuzzCase:
    """One generated bad input: its family, a short label, the argv, and the expectation."""

    family: str
    label: str
    argv: tuple[str, ...]
    expect: str = "refused"  # or "no_traceback"
    names: str = ""  # what the error line must name (a file, a flag); "" for no check
    keep: str = ""  # a folder whose content the case must leave as it was


def _base_geometry() -> ViewGeometry:
    return ViewGeometry(-29.3, 25.5, 976.0, 720.0, (0.390625, 0.390625), SIZE_PX, SIZE_PX)


def _base_frames(rng: np.random.Generator) -> np.ndarray:
    frame = rng.normal(2000.0, 40.0, size=(SIZE_PX, SIZE_PX))
    frame[:, SIZE_PX // 2 - 2 : SIZE_PX // 2 + 2] -= 600.0
    return np.clip(frame, 0, 4095).astype(np.uint16)


def _mutated_dicom(base: Path, out: Path, set_values: dict[str, object],
                   remove: tuple[str, ...] = ()) -> Path:
    """A copy of ``base`` with raw tag values set (unvalidated) and tags removed."""
    ds = pydicom.dcmread(base)
    for keyword in remove:
        if keyword in ds:
            del ds[keyword]
    for keyword, value in set_values.items():
        tag = pydicom.datadict.tag_for_keyword(keyword)
        vr = pydicom.datadict.dictionary_VR(tag)
        if isinstance(value, str) and vr in ("DS", "IS"):
            raw = value.encode("ascii")
            if len(raw) % 2:
                raw += b" "
            ds[tag] = pydicom.dataelem.RawDataElement(tag, vr, len(raw), raw, 0, False, True)
        else:
            ds.add_new(tag, vr, value)
    with pydicom.config.disable_value_validation():
        ds.save_as(out, enforce_file_format=True)
    return out


def _flip_bytes(base: Path, out: Path, rng: np.random.Generator, n_flips: int) -> Path:
    data = bytearray(base.read_bytes())
    header_end = min(len(data), 1200)
    for _ in range(n_flips):
        k = int(rng.integers(132, header_end))
        data[k] ^= 1 << int(rng.integers(0, 8))
    out.write_bytes(bytes(data))
    return out


def _png_with_json(folder: Path, name: str, size: int, json_bytes: bytes | None) -> Path:
    png = folder / f"{name}.png"
    Image.fromarray(np.full((size, size), 180, np.uint8)).save(png)
    if json_bytes is not None:
        (folder / f"{name}.json").write_bytes(json_bytes)
    return png


def _good_geometry_json(**changes: object) -> dict:
    data: dict[str, object] = {"alpha_deg": 30.7, "beta_deg": 23.6, "sid_mm": 976,
                               "sod_mm": 720, "pixel_spacing_mm": 0.39}
    data.update(changes)
    return data


def _nested(depth: int) -> str:
    return "[" * depth + "1" + "]" * depth


def make_cases(folder: Path, n_random: int = 0, seed: int = 0) -> list[FuzzCase]:
    """The fixed bad inputs of every family, then ``n_random`` more drawn with ``seed``.

    Files go under ``folder``; each case's output folder is ``folder/out-<k>``
    (never created when the case is refused).
    """
    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True, exist_ok=True)
    base = folder / "base.dcm"
    write_xa_dicom(base, _base_frames(rng), _base_geometry())
    good_b = str(DEMO / "b.dcm")
    good_seeds = str(DEMO / "seeds.json")
    cases: list[FuzzCase] = []
    counter = iter(range(10**9))

    def recon_case(family: str, label: str, a: str, b: str = good_b, seeds: str = good_seeds,
                   extra: tuple[str, ...] = (), expect: str = "refused", names: str = "") -> None:
        out = folder / f"out-{next(counter)}"
        argv = ("reconstruct", a, b, "--seeds", seeds, "--out", str(out), "--quiet", *extra)
        if not names:
            names = extra[0] if extra else (seeds if seeds != good_seeds else a)
        if names.startswith("--") and family != "flags-random" and extra[1][:1].isalpha():
            names = "argument " + names
        cases.append(FuzzCase(family, label, argv, expect, names))

    def dicom(label: str, set_values: dict[str, object], remove: tuple[str, ...] = ()) -> str:
        name = f"d{len(cases)}.dcm"
        return str(_mutated_dicom(base, folder / name, set_values, remove))

    # 1. header geometry out of range or invalid
    for keyword, bad in _BAD_HEADER.items():
        for value in bad:
            recon_case("header", f"{keyword}={value}", dicom(keyword, {keyword: value}))
    for (keyword, missing), bad in _BAD_FALLBACK.items():
        remove = (missing,) if keyword != "FieldOfViewDimensions" else (missing, "PixelSpacing")
        for value in bad:
            path = dicom(keyword, {keyword: value}, remove)
            recon_case("header-fallback", f"{keyword}={value} without {missing}", path)
    # 2. odd DICOM values
    recon_case("dicom-odd", "RepresentativeFrameNumber=[1,2]",
               dicom("rfn", {"RepresentativeFrameNumber": [1, 2]}))
    for bits in (1, 7, 10):
        recon_case("dicom-odd", f"BitsStored={bits} on 12-bit data",
                   dicom("bits", {"BitsStored": bits, "HighBit": bits - 1}))
    for size in (1, 8, 63):
        tiny = folder / f"tiny{size}.dcm"
        geometry = ViewGeometry(-29.3, 25.5, 976.0, 720.0, (0.39, 0.39), size, size)
        write_xa_dicom(tiny, np.full((size, size), 100, np.uint16), geometry)
        recon_case("dicom-odd", f"{size}x{size} image", str(tiny))
    recon_case("dicom-odd", "an empty file", str(_write(folder / "empty.dcm", b"")))
    recon_case("dicom-odd", "text as DICOM", str(_write(folder / "t.dcm", b"not dicom" * 50)))
    recon_case("dicom-odd", "a truncated file", str(_write(
        folder / "trunc.dcm", base.read_bytes()[:700])))
    recon_case("dicom-odd", "a folder", str(folder))
    recon_case("dicom-odd", "/dev/zero as view A", "/dev/zero")
    recon_case("dicom-odd", "no such file", str(folder / "missing.dcm"))
    # 3. images with a geometry sidecar
    recon_case("sidecar", "sidecar of invalid UTF-8",
               str(_png_with_json(folder, "utf8", 96, b'{"sid_mm": "\xff\xfe"}')),
               names="utf8.json")
    for label, data in (
        ("pixel_spacing_mm true", _good_geometry_json(pixel_spacing_mm=True)),
        ("sid_mm 5000", _good_geometry_json(sid_mm=5000)),
        ("sod_mm above sid", _good_geometry_json(sod_mm=1000)),
        ("sid_mm text", _good_geometry_json(sid_mm="abc")),
        ("pixel_spacing_mm [0.1, 10]", _good_geometry_json(pixel_spacing_mm=[0.1, 10])),
        ("pixel_spacing_mm 3 values", _good_geometry_json(pixel_spacing_mm=[0.1, 0.1, 0.1])),
        ("alpha_deg 1e9", _good_geometry_json(alpha_deg=1e9)),
        ("beta_deg list", _good_geometry_json(beta_deg=[1, 2])),
        ("sid_mm missing", {k: v for k, v in _good_geometry_json().items() if k != "sid_mm"}),
        ("a typo key", _good_geometry_json(sid=976)),
    ):
        png = _png_with_json(folder, f"j{len(cases)}", 96, json.dumps(data).encode())
        recon_case("sidecar", label, str(png), names=png.stem)
    deep = _png_with_json(folder, "deep", 96, ('{"sid_mm": ' + _nested(5000) + "}").encode())
    recon_case("sidecar", "sidecar nested 5000 deep", str(deep), names="deep.json")
    nan_json = _png_with_json(folder, "nanj", 96, b'{"sid_mm": NaN, "alpha_deg": 1}')
    recon_case("sidecar", "sidecar NaN", str(nan_json), names="nanj.json")
    recon_case("sidecar", "1x1 png", str(_png_with_json(
        folder, "one", 1, json.dumps(_good_geometry_json()).encode())))
    nan_tif = folder / "nan.tif"
    pixels = np.full((96, 96), 100.0, np.float32)
    pixels[10:20, 10:20] = np.nan
    Image.fromarray(pixels, mode="F").save(nan_tif)
    (folder / "nan.json").write_text(json.dumps(_good_geometry_json()))
    recon_case("sidecar", "float TIFF with a NaN patch", str(nan_tif))
    # 4. seeds files
    seeds_docs: list[tuple[str, bytes]] = [
        ("segments a number", b'{"segments": 5}'),
        ("features a number", b'{"features": 7}'),
        ("segments a string", b'{"segments": "LAD"}'),
        ("features an object", b'{"features": {"a": [1, 2]}}'),
        ("401-digit integer", ('{"features": [{"a": [' + "9" * 401 + ', 1], "b": [1, 1]}]}')
         .encode()),
        ("5000-digit integer", ('{"features": [{"a": [' + "9" * 5000 + ', 1], "b": [1, 1]}]}')
         .encode()),
        ("1000-deep nesting", ('{"segments": ' + _nested(1000) + "}").encode()),
        ("100-deep nesting", ('{"segments": ' + _nested(100) + "}").encode()),
        ("20000 waypoints", json.dumps({"segments": [
            {"a": [[float(i % 500), 3.0] for i in range(20000)], "b": [[1, 2], [3, 4]]}]}
        ).encode()),
        ("2000 features", json.dumps({"features": [
            {"a": [1, 2], "b": [3, 4]} for _ in range(2000)]}).encode()),
        ("invalid UTF-8", b'{"segments": [], "name": "\xc3\x28"}'),
        ("NaN coordinate", b'{"features": [{"a": [NaN, 1], "b": [1, 1]}]}'),
        ("Infinity coordinate", b'{"features": [{"a": [Infinity, 1], "b": [1, 1]}]}'),
        ("boolean coordinate", b'{"features": [{"a": [true, 1], "b": [1, 1]}]}'),
        ("string coordinate", b'{"features": [{"a": ["1", 1], "b": [1, 1]}]}'),
        ("three coordinates", b'{"features": [{"a": [1, 1, 1], "b": [1, 1]}]}'),
        ("1e300 coordinate", b'{"features": [{"a": [1e300, 1], "b": [1, 1]}]}'),
        ("a top-level list", b"[1, 2, 3]"),
        ("version 3", b'{"version": 3}'),
        ("empty file", b""),
        ("truncated JSON", b'{"segments": [{"a": [[1, 2'),
        ("control characters in a name", b'{"segments": [{"name": "L\\u001b[2J\\nAD", '
         b'"a": [[1, 2]], "b": [[1, 2], [3, 4]]}]}'),
        ("one point in a", b'{"segments": [{"a": [[1, 2]], "b": [[1, 2], [3, 4]]}]}'),
    ]
    for label, data in seeds_docs:
        path = _write(folder / f"s{len(cases)}.json", data)
        recon_case("seeds", label, str(base_a()), seeds=str(path))
    recon_case("seeds", "/dev/zero as the seeds file", str(base_a()), seeds="/dev/zero")
    recon_case("seeds", "a folder as the seeds file", str(base_a()), seeds=str(folder))
    big = folder / "big.json"
    with big.open("wb") as fh:
        fh.write(b'{"features": [')
        fh.write(b'{"a": [1, 2], "b": [3, 4]}, ' * 450_000)
        fh.write(b'{"a": [1, 2], "b": [3, 4]}]}')
    recon_case("seeds", "a 12 MB seeds file", str(base_a()), seeds=str(big))
    # 5. command-line values
    for flag, bad in _BAD_FLAGS.items():
        for value in bad:
            recon_case("flags", f"{flag} {value}", str(base_a()), extra=(flag, value))
    for value in ("-50", "100", "nan", "inf", "abc", "1e400"):
        cases.append(FuzzCase("flags", f"phantom --stenosis {value}", (
            "phantom", "--out", str(folder / f"out-{next(counter)}"), "--stenosis", value)))
    for value in ("-1", "x", str(2**40)):
        cases.append(FuzzCase("flags", f"phantom --seed {value}", (
            "phantom", "--out", str(folder / f"out-{next(counter)}"), "--seed", value)))
    for name, value in (("calibration", "0"), ("matching", "-3"), ("centerline", "x"),
                        ("reconstruct", "-1")):
        cases.append(FuzzCase("flags", f"bench {name} --cases {value}",
                              ("bench", name, "--cases", value)))
    # 6. argparse usage errors
    for argv in (("reconstruct",), ("info",), ("nosuchcommand",), ("reconstruct", "--bogus"),
                 ("bench", "nosuchbench"), ("info", "--frame"), ("reconstruct", "--matcher",
                 "match9", "--demo", "--out", str(folder / "out-u")), ()):
        cases.append(FuzzCase("usage", " ".join(argv) or "(nothing)", argv))

    # 7. output folders that must be refused, and left as they were
    for k, builder in enumerate(_OUTPUT_TRAPS):
        label, argv_out, names, keep, extra_args = builder(folder / f"trap-{k}")
        cases.append(_output_case("outputs", label, argv_out, names, keep, extra_args))
    # 8. limits reached (the pipeline runs until it hits them)
    # (the memory limit as real processes only: at the limit OpenBLAS can loop in native code,
    # which only the real process's watchdog ends; tests/recon/io/test_limits.py)
    # In process, after the earlier cases, the demo's reconstruction takes 1.1-1.7 s of CPU
    # (its tables cached), so a 1 s limit was not always reached; 0.3 s always is.
    for flag, value, names in (("--max-cpu-s", "0.3", "--max-cpu-s"),):
        cases.append(FuzzCase("limits", f"{flag} {value}", (
            "reconstruct", "--demo", "--out", str(folder / f"out-{next(counter)}"), "--quiet",
            flag, value), names=names))

    # 9. random draws: byte flips, random out-of-range values, broken seeds, output traps
    for k in range(n_random):
        family = k % 5
        if family == 0:
            path = _flip_bytes(base, folder / f"flip{k}.dcm", rng, int(rng.integers(1, 6)))
            cases.append(FuzzCase("byte-flip", f"flips in {path.name}", ("info", str(path)),
                                  "no_traceback"))
        elif family == 1:
            keyword = list(_BAD_HEADER)[int(rng.integers(len(_BAD_HEADER)))]
            recon_case("header-random", keyword, dicom(keyword, {keyword: _random_bad(
                keyword, rng)}))
        elif family == 2:
            flag = ("--sid-mm", "--sod-mm", "--pixel-spacing-mm", "--alpha-deg",
                    "--beta-deg")[int(rng.integers(5))]
            recon_case("flags-random", flag, str(base_a()), extra=(flag, _random_bad(flag, rng)))
        elif family == 3:
            label, data = _random_seeds(rng)
            path = _write(folder / f"r{k}.json", data)
            recon_case("seeds-random", label, str(base_a()), seeds=str(path))
        else:
            builder = _OUTPUT_TRAPS[int(rng.integers(len(_OUTPUT_TRAPS)))]
            label, argv_out, names, keep, extra_args = builder(folder / f"rtrap-{k}", rng)
            cases.append(_output_case("outputs-random", label, argv_out, names, keep,
                                      extra_args))
    return cases


# ------------------------------------------------------------------ output traps
# Each builder makes a folder under ``root`` and returns (label, the --out value, what the
# error must name, the folder that must stay unchanged, extra argv (e.g. --seeds));
# the inputs are the bundled demo pair.
def _output_case(family: str, label: str, out: str, names: str, keep: str,
                 extra: tuple[str, ...]) -> FuzzCase:
    seeds = ("--seeds", str(DEMO / "seeds.json")) if "--seeds" not in extra else ()
    argv = ("reconstruct", str(DEMO / "a.dcm"), str(DEMO / "b.dcm"), *seeds, *extra,
            "--out", out, "--quiet")
    return FuzzCase(family, label, argv, "refused", names, keep)


def _name(rng: np.random.Generator | None, default: str) -> str:
    if rng is None:
        return default
    return str(rng.choice(["notes.txt", "a.dcm", ".DS_Store", "IM_0001", "result.csv",
                           "report.json.bak", "sub"]))


def _trap_empty(root: Path, rng=None) -> tuple:
    root.mkdir(parents=True)
    text = "" if rng is None else str(rng.choice(["", " ", "\t", "   "]))
    return f"--out {text!r}", text, "--out", str(root), ()


def _trap_file(root: Path, rng=None) -> tuple:
    root.mkdir(parents=True)
    path = root / _name(rng, "out.txt")
    path.write_text("a file")
    return "--out is a file", str(path), str(path), str(root), ()


def _trap_input(root: Path, rng=None) -> tuple:
    root.mkdir(parents=True)
    path = root / "a.dcm"
    path.write_bytes((DEMO / "a.dcm").read_bytes())
    return "--out is input A", str(path), str(path), str(root), ()


def _trap_foreign(root: Path, rng=None) -> tuple:
    root.mkdir(parents=True)
    name = _name(rng, "notes.txt")
    (root / name).write_text("the user's")
    return f"a folder holding {name}", str(root), "not a coronary3d output", str(root), ()


def _trap_seeds_at_report(root: Path, rng=None) -> tuple:
    root.mkdir(parents=True)
    name = "report.json" if rng is None else str(rng.choice(
        ["report.json", "centerline.csv", "mesh.stl", "outputs.json"]))
    seeds = root / name
    seeds.write_bytes((DEMO / "seeds.json").read_bytes())
    return f"the seeds file at OUT/{name}", str(root), str(seeds), str(root), (
        "--seeds", str(seeds))


def _trap_dir_at_output(root: Path, rng=None) -> tuple:
    name = "mesh.stl" if rng is None else str(rng.choice(
        ["mesh.stl", "report.json", "centerline.csv", "centerline.vtp", "outputs.json"]))
    (root / name).mkdir(parents=True)
    return f"a folder at OUT/{name}", str(root), f"{name}: is a folder", str(root), ()


def _trap_link_at_output(root: Path, rng=None) -> tuple:
    root.mkdir(parents=True)
    elsewhere = root.parent / f"{root.name}-target.json"
    elsewhere.write_text("someone else's")
    name = "report.json" if rng is None else str(rng.choice(["report.json", "mesh.stl"]))
    (root / name).symlink_to(elsewhere)
    return f"a link at OUT/{name}", str(root), f"{name}: is a link", str(root.parent), ()


def _trap_hardlink_input(root: Path, rng=None) -> tuple:
    root.mkdir(parents=True)
    seeds = root.parent / f"{root.name}-seeds.json"
    seeds.write_bytes((DEMO / "seeds.json").read_bytes())
    os.link(seeds, root / "centerline.csv")
    return "the seeds file hard-linked at OUT/centerline.csv", str(root), "seeds file", \
        str(root.parent), ("--seeds", str(seeds))


def _trap_not_a_folder_parent(root: Path, rng=None) -> tuple:
    root.mkdir(parents=True)
    (root / "file").write_text("x")
    return "--out below a file", str(root / "file" / "sub"), str(root / "file"), str(root), ()


def _trap_device(root: Path, rng=None) -> tuple:
    root.mkdir(parents=True)
    return "--out /dev/null", "/dev/null", "/dev/null", str(root), ()


_OUTPUT_TRAPS = (_trap_empty, _trap_file, _trap_input, _trap_foreign, _trap_seeds_at_report,
                 _trap_dir_at_output, _trap_link_at_output, _trap_hardlink_input,
                 _trap_not_a_folder_parent, _trap_device)


@dataclass(frozen=True)
class Outcome:
    """What one run of ``recon.cli.main`` did."""

    code: object  # the return value or SystemExit code
    stderr: str
    traceback: bool  # an exception other than SystemExit escaped main
    output_left: bool  # the case's --out folder was made by the run
    changed: bool = False  # the case's ``keep`` folder is not as it was


def output_folder(case: FuzzCase) -> Path | None:
    """The --out folder a case names, if any."""
    argv = list(case.argv)
    return Path(argv[argv.index("--out") + 1]) if "--out" in argv[:-1] else None


def run_in_process(case: FuzzCase) -> Outcome:
    """Run a case through ``recon.cli.main(argv)`` with stdout and stderr captured."""
    import contextlib
    import io
    import traceback

    from recon import cli

    err, out = io.StringIO(), io.StringIO()
    escaped = False
    folder = output_folder(case)
    existed = bool(folder and str(folder).strip() and os.path.lexists(folder))
    before = _snapshot(case.keep) if case.keep else None
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(out):
        try:
            code: object = cli.main(list(case.argv))
        except SystemExit as exc:
            code = exc.code
        except BaseException:  # noqa: BLE001 - a test of exactly this: nothing escapes
            escaped = True
            code = None
            err.write(traceback.format_exc())
    left = bool(folder and str(folder).strip() and not existed and os.path.lexists(folder))
    changed = before is not None and _snapshot(case.keep) != before
    return Outcome(code, err.getvalue(), escaped or "Traceback" in err.getvalue(), left, changed)


def _snapshot(folder: str) -> dict[str, object]:
    """Every entry under ``folder``: kind, and the bytes of regular files."""
    found: dict[str, object] = {}
    for dirpath, dirnames, filenames in os.walk(folder):
        for name in dirnames + filenames:
            path = Path(dirpath) / name
            if path.is_symlink():
                found[str(path)] = ("link", os.readlink(path))
            elif path.is_dir():
                found[str(path)] = "dir"
            else:
                found[str(path)] = path.read_bytes()
    return found


def failure(case: FuzzCase, outcome: Outcome) -> str | None:
    """Why an outcome breaks the case's expectation, or None when it holds."""
    if outcome.traceback:
        return "traceback"
    if case.expect == "no_traceback":
        return None if outcome.code in (0, 2) else f"exit {outcome.code}"
    lines = [line for line in outcome.stderr.splitlines() if line.strip()]
    if outcome.code != 2:
        return f"exit {outcome.code}"
    if len(lines) != 1 or not lines[0].startswith("coronary3d: error: "):
        return f"{len(lines)} stderr lines"
    if case.names and case.names not in lines[0]:
        return f"the error does not name {case.names!r}: {lines[0]}"
    if outcome.output_left:
        return "an output folder was written"
    if outcome.changed:
        return f"the folder {case.keep} was changed"
    return None


def base_a() -> Path:
    """View A of the bundled demo pair (a valid file)."""
    return DEMO / "a.dcm"


def _write(path: Path, data: bytes) -> Path:
    path.write_bytes(data)
    return path


# Accepted ranges, restated here so that a random draw lands outside them
_OUTSIDE = {
    "DistanceSourceToDetector": (700.0, 1300.0), "--sid-mm": (700.0, 1300.0),
    "DistanceSourceToPatient": (400.0, 1300.0), "--sod-mm": (400.0, 1300.0),
    "ImagerPixelSpacing": (0.05, 1.0), "--pixel-spacing-mm": (0.05, 1.0),
    "PositionerPrimaryAngle": (-180.0, 180.0), "--alpha-deg": (-180.0, 180.0),
    "PositionerSecondaryAngle": (-90.0, 90.0), "--beta-deg": (-90.0, 90.0),
}


def _random_bad(name: str, rng: np.random.Generator) -> str:
    """A value outside ``name``'s range: below, above, not finite, or not a number."""
    low, high = _OUTSIDE[name]
    kind = int(rng.integers(4))
    if kind == 0:
        value = low - abs(low) * float(rng.uniform(0.01, 3.0)) - 0.001
    elif kind == 1:
        value = high * 10 ** float(rng.uniform(0.01, 300))
    elif kind == 2:
        return str(rng.choice(["nan", "inf", "-inf", "NaN"]))
    else:
        return str(rng.choice(["abc", "1,5", "--", "0x10", "1e", "."]))
    text = f"{value:.6g}"
    if name.startswith("--") and text.startswith("-"):
        return f"{text}"  # argparse reads a leading '-' number as a value
    return text if math.isfinite(value) else "inf"


def _random_seeds(rng: np.random.Generator) -> tuple[str, bytes]:
    """A broken seeds document drawn at random."""
    kind = int(rng.integers(6))
    if kind == 0:
        depth = int(rng.integers(33, 3000))
        return f"{depth}-deep nesting", ('{"segments": ' + _nested(depth) + "}").encode()
    if kind == 1:
        digits = int(rng.integers(310, 6000))
        return f"{digits}-digit integer", (
            '{"features": [{"a": [' + "7" * digits + ', 1], "b": [1, 1]}]}').encode()
    if kind == 2:
        n = int(rng.integers(1001, 30000))
        return f"{n} waypoints", json.dumps({"segments": [
            {"a": [[1.0, 2.0]] * n, "b": [[1, 2], [3, 4]]}]}).encode()
    if kind == 3:
        value = rng.choice(["5", '"x"', "true", "null", "1.5", "{}"])
        key = rng.choice(["segments", "features"])
        doc = f'{{"{key}": {value}}}'
        if value in ("null", "{}") or (key == "features" and value == "{}"):
            doc = f'{{"{key}": [{value}]}}'
        return f"{key} = {value}", doc.encode()
    if kind == 4:
        data = bytearray(json.dumps({"segments": [], "note": "x" * 20}).encode())
        data[int(rng.integers(len(data)))] = int(rng.choice([0xFF, 0xC3, 0x80]))
        return "invalid UTF-8", bytes(data)
    bad = rng.choice(["NaN", "Infinity", "-Infinity", "1e400", '"7"', "[1]", "true"])
    return f"coordinate {bad}", f'{{"features": [{{"a": [{bad}, 1], "b": [1, 1]}}]}}'.encode()
