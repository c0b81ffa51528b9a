"""The `coronary3d` command line: info, phantom, reconstruct, batch, view, bench.

Every user mistake (a bad file, a missing tag, a click off the vessel) ends
in one line on stderr naming the file or click and what is wrong, and exit
code 2. Set CORONARY3D_DEBUG=1 to see the traceback instead.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from recon.bench.command import add_bench_parser, bench_call
from recon.cli_inputs import add_ffr_options, ffr_words
from recon.cli_inputs import number_arg as _number
from recon.errors import CoronaryError
from recon.startup import cap_math_threads

EXIT_USER_ERROR = 2
_REAL_PROCESS = False  # main() runs as the process itself (not called in-process by a test)



class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose usage errors are one line ``coronary3d: error: ...``
    (exit 2) instead of the usage block; ``--help`` still prints the whole usage."""

    def error(self, message: str) -> None:  # type: ignore[override]
        text = " ".join(message.split())
        self.exit(EXIT_USER_ERROR, f"coronary3d: error: {text} (see {self.prog} --help)\n")


def _folder(text: str) -> str:
    """An argparse type for --out: a folder name (an empty one is refused)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("give a folder (an empty name would mean the current "
                                         "folder)")
    return text


_FINITE = _number(float)
_COUNT = _number(int, 1)
_INDEX = _number(int, 0)


def _add_geometry_options(p: argparse.ArgumentParser, per_file: bool = False) -> None:
    g = p.add_argument_group(
        "geometry overrides (for files that lack the tags; apply to every file given; a "
        "header value they replace is named in a warning)"
    )
    if per_file:
        for view in ("a", "b"):
            g.add_argument(
                f"--geometry-{view}", metavar="FILE",
                help=f"geometry JSON for file {view.upper()} only (any of alpha_deg, beta_deg, "
                "sid_mm, sod_mm, pixel_spacing_mm); wins over the flags for every file")
    g.add_argument("--alpha-deg", type=_FINITE, help="primary angle, degrees (LAO +, RAO -)")
    g.add_argument("--beta-deg", type=_FINITE, help="secondary angle, degrees (CRA +, CAU -)")
    g.add_argument("--sid-mm", type=_FINITE, help="source to detector distance, mm")
    g.add_argument("--sod-mm", type=_FINITE, help="source to isocenter distance, mm")
    g.add_argument(
        "--pixel-spacing-mm", type=_FINITE, help="detector pixel size, mm (square pixels)"
    )
    g.add_argument(
        "--geometry-json",
        metavar="FILE",
        help="JSON with any of alpha_deg, beta_deg, sid_mm, sod_mm, pixel_spacing_mm",
    )


def _overrides(args: argparse.Namespace):
    """GeometryOverrides from the command-line options (None when none given)."""
    from recon.io.overrides import GeometryOverrides

    json_path = getattr(args, "geometry_json", None)
    from_json = GeometryOverrides.from_json(json_path) if json_path else None
    spacing = getattr(args, "pixel_spacing_mm", None)
    values = {
        "alpha_deg": getattr(args, "alpha_deg", None),
        "beta_deg": getattr(args, "beta_deg", None),
        "sid_mm": getattr(args, "sid_mm", None),
        "sod_mm": getattr(args, "sod_mm", None),
        "pixel_spacing_mm": (spacing, spacing) if spacing is not None else None,
    }
    changes = {k: v for k, v in values.items() if v is not None}
    if not changes:
        return from_json
    from_cli = GeometryOverrides(**changes, source="command line")
    return from_cli.merged_over(from_json)


def _overrides_ab(args: argparse.Namespace):
    """(overrides of file A, of file B): each file's --geometry-a/-b JSON over the
    values given for every file."""
    from recon.io.overrides import per_file_overrides

    common = _overrides(args)
    return tuple(per_file_overrides(common, getattr(args, f"geometry_{v}", None))
                 for v in ("a", "b"))


def _warn_replaced(angio) -> None:
    """A warning on stderr for each header value a user's value replaced."""
    from recon.io.overrides import header_replacements

    for note in header_replacements(angio.geometry_notes):
        print(f"coronary3d: warning: {Path(angio.path).name}: {note}", file=sys.stderr)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="coronary3d",
        description=(
            "3D coronary artery reconstruction from two X-ray angiograms: C-arm geometry "
            "from the DICOM header, PALM calibration, CBOCD point matching, a watertight "
            "surface mesh and 3D stenosis measurements."
        ),
        epilog="Start with: coronary3d reconstruct --demo --out out/demo",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)

    p = sub.add_parser(
        "info",
        help="describe XA DICOM files: geometry tags, frames, chosen frame",
        description="Print, per file, the SOP class, size, frames, frame time, the C-arm "
        "geometry (angles, SID, SOD, pixel spacing, or 'missing') and the frame that "
        "reconstruction would use and why. No patient data unless --show-patient.",
    )
    p.add_argument("files", nargs="+", metavar="FILE")
    p.add_argument("--frame", type=_INDEX, help="frame index (0-based) to choose instead")
    p.add_argument("--show-patient", action="store_true", help="also print patient name and ID")
    p.add_argument("--json", action="store_true", help="print JSON instead of text")
    _add_geometry_options(p)

    p = sub.add_parser(
        "phantom",
        help="make a synthetic angiogram pair with known ground truth",
        description="Render two XA DICOM files of a synthetic coronary tree with a stenosis, "
        "with the nominal geometry in the headers and a known header error on view B, "
        "plus seeds.json (clicks) and truth.json (ground truth).",
    )
    p.add_argument("--out", required=True, type=_folder, metavar="DIR", help="output folder")
    p.add_argument(
        "--preset",
        default="static",
        help="geometry preset: data1, data2, data3 (the paper's Table 1) or static "
        "(like the real phantom pair); default static",
    )
    p.add_argument("--seed", type=_number(int, 0, 2**32 - 1), default=0,
                   help="random seed, 0 to 2^32-1 (same seed, same files)")
    p.add_argument("--stenosis", type=_number(float, 0.0, 100.0, below_high=True), default=50.0,
                   help="%% diameter stenosis, 0 to below 100")
    p.add_argument("--frames", type=_number(int, 1, 200), default=1,
                   help="number of cine frames (1 to 200)")

    p = sub.add_parser(
        "reconstruct",
        help="run the whole pipeline headless and write centerline, mesh and report",
        description="Load two angiograms, trace every segment clicked in seeds.json (the "
        "vessel tree: branches join their parent at the bifurcation) in each "
        "view, calibrate view B (PALM) on the whole tree, match points (CBOCD + dynamic "
        "programming), triangulate, build the surface and measure the narrowing and the "
        "bifurcations. Writes "
        "DIR/centerline.csv, DIR/centerline.vtp, DIR/mesh.stl (or --format) and "
        "DIR/report.json; with --sr also DIR/measurements-sr.dcm.",
    )
    p.add_argument("file_a", nargs="?", metavar="A", help="reference view (DICOM or PNG/TIFF)")
    p.add_argument("file_b", nargs="?", metavar="B", help="second view")
    p.add_argument("--seeds", metavar="FILE", help="clicks file (seeds.json)")
    p.add_argument("--out", required=True, type=_folder, metavar="DIR", help="output folder")
    p.add_argument("--demo", action="store_true", help="use the bundled demo case")
    p.add_argument("--matcher", default="match3", choices=["match1", "match2", "match3", "match4"])
    p.add_argument("--optimizer", default="palm", choices=["palm", "lm", "anneal"])
    p.add_argument("--format", default="stl", help="mesh formats, comma separated: stl,obj,ply,glb")
    p.add_argument("--frame-a", type=_INDEX, help="frame of view A (0-based) for a cine")
    p.add_argument("--frame-b", type=_INDEX, help="frame of view B (0-based) for a cine")
    p.add_argument("--segment", default=None, metavar="NAME|INDEX",
                   help="reconstruct only this segment of seeds.json (its name, or its "
                   "0-based index); default: every segment, as one tree")
    p.add_argument(
        "--self-calibration",
        action="store_true",
        help="after matching, recalibrate with the deviation pairs (the paper's sec. 3.4.2) "
        "and refine over the matched points (off by default: it did not improve the pose "
        "on the phantom benchmark)",
    )
    for view in ("a", "b"):
        p.add_argument(
            f"--intensity-{view}",
            choices=("auto", "lin", "log"),
            default="auto",
            help=f"how file {view.upper()}'s stored values relate to attenuation: lin (linear in "
            "X-ray intensity), log (linear in attenuation) or auto (its "
            "PixelIntensityRelationship tag when LIN/LOG, else estimated); default auto",
        )
    p.add_argument(
        "--calibration",
        choices=("full", "supported", "header", "curves"),
        default="full",
        help="how far view B moves from its header: full (all six rig parameters; default), "
        "supported (only as far as the clicks support: header, rig translation or full), "
        "header (no correction) or curves (full, from the clicks and the traced curves)",
    )
    p.add_argument(
        "--tracer", choices=("2d", "3d"), default="2d",
        help="2d: trace each view on its own (default); 3d: calibrate on the clicks first, "
        "then trace a 3D path both views vote on (experimental)")
    p.add_argument(
        "--allow-close-views",
        action="store_true",
        help="go on, with a warning, when the two views are less than 25 deg apart "
        "(refused otherwise: depth is not fixed)",
    )
    p.add_argument(
        "--sr",
        action="store_true",
        help="also write measurements-sr.dcm, a DICOM Structured Report (TID 1500) of the "
        "measurements in the inputs' patient and study (DICOM inputs only)",
    )
    p.add_argument("--report", action="store_true",
                   help="also write report.pdf, the report of every segment beside "
                   "report.json (no "
                   "patient name, ID or date unless --identify)")
    p.add_argument("--allow-different-patients", action="store_true",
                   help="go on, with a warning, when files A and B name different patients "
                   "(their PatientID differs; refused otherwise)")
    p.add_argument("--identify", action="store_true",
                   help="put the patient name, ID and study date from the DICOM headers in "
                   "report.pdf")
    add_ffr_options(p)
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    _add_limit_options(p, "the job")
    _add_geometry_options(p, per_file=True)

    p = sub.add_parser(
        "batch",
        help="reconstruct every case of a manifest CSV on Dask (local or a cluster)",
        description="Reconstruct one case per manifest row (header id,a,b,seeds, optional "
        "columns geometry_a, geometry_b, frame_a, frame_b, segment, matcher, optimizer, "
        "intensity_a, intensity_b, self_calibration; paths relative to the manifest) into "
        "DIR/<id>/, on a local Dask cluster or an existing one (--scheduler). A failed case "
        "is recorded with its error and the others go on; a rerun skips the recorded cases. "
        "DIR/results.csv (and results.parquet with the [batch] extra) has one row per case.",
    )
    p.add_argument("manifest", metavar="MANIFEST.csv")
    p.add_argument("--out", required=True, type=_folder, metavar="DIR", help="output folder")
    p.add_argument("--workers", type=_COUNT, default=1, metavar="N",
                   help="local worker processes (default 1; ignored with --scheduler)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="an existing Dask scheduler, e.g. tcp://10.0.0.5:8786")
    p.add_argument("--retry-failed", action="store_true", help="run the failed cases again")
    p.add_argument("--format", default="stl", help="mesh formats, comma separated: stl,obj,ply,glb")
    p.add_argument("--sr", action="store_true",
                   help="also write measurements-sr.dcm per case (DICOM inputs only)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    _add_limit_options(p, "each case")

    p = sub.add_parser(
        "view",
        help="open the browser viewer",
        description="Start the viewer and print its URL. With no files it opens the bundled "
        "demo case. Binds 127.0.0.1 unless --host says otherwise (angiograms are patient data).",
    )
    p.add_argument("file_a", nargs="?", metavar="A")
    p.add_argument("file_b", nargs="?", metavar="B")
    p.add_argument("--seeds", metavar="FILE")
    p.add_argument("--host", default="127.0.0.1")
    p.add_argument("--out", type=_folder, metavar="DIR",
                   help="the folder 'Save seeds to path' writes into (default: the current one)")
    p.add_argument("--port", type=_number(int, 0, 65535), default=8080,
                   help="port to serve on (0: any free port)")
    _add_geometry_options(p, per_file=True)

    add_bench_parser(sub)
    return parser


# ----------------------------------------------------------------- commands
def cmd_info(args: argparse.Namespace) -> int:
    from recon.errors import LoadError
    from recon.io.describe import describe_file, format_description

    overrides = _overrides(args)
    failed = False
    results = []
    for path in args.files:
        try:
            desc = describe_file(
                path, show_patient=args.show_patient, frame=args.frame, overrides=overrides
            )
        except LoadError as exc:
            print(f"coronary3d: error: {_one_line(exc)}", file=sys.stderr)
            failed = True
            continue
        if args.json:
            results.append(desc)
        else:
            print(format_description(desc))
            print()
    if args.json:
        print(json.dumps(results, indent=2, default=str))
    return EXIT_USER_ERROR if failed else 0


def cmd_phantom(args: argparse.Namespace) -> int:
    from recon.io.phantom_case import write_phantom_case
    from recon.synth import PRESETS, make_phantom

    if args.preset not in PRESETS:
        print(
            f"coronary3d: error: unknown preset {args.preset!r} "
            f"(choose from {', '.join(sorted(PRESETS))})",
            file=sys.stderr,
        )
        return EXIT_USER_ERROR
    case = make_phantom(
        args.preset, args.seed, stenosis_pct=args.stenosis, n_frames=max(1, args.frames)
    )
    paths = write_phantom_case(case, Path(args.out))
    for name, path in paths.items():
        print(f"{name}: {path}")
    return 0


def cmd_reconstruct(args: argparse.Namespace) -> int:
    from recon.cli_inputs import file_bytes, input_files, segment_choice
    from recon.io.angiogram import load_angiogram
    from recon.io.demo import demo_paths
    from recon.io.limits import job_limits, limits_for
    from recon.io.outputs import check_output_dir, write_outputs
    from recon.io.seeds_file import load_seeds
    from recon.pipeline import ReconstructionOptions, reconstruct_pair
    from recon.tree import reconstruct_tree

    if args.demo:
        demo = demo_paths()
        file_a = args.file_a or str(demo["a"])
        file_b = args.file_b or str(demo["b"])
        seeds_path = args.seeds or str(demo["seeds"])
    else:
        file_a, file_b, seeds_path = args.file_a, args.file_b, args.seeds
        if not (file_a and file_b and seeds_path):
            print(
                "coronary3d: error: reconstruct needs two files A B and --seeds FILE "
                "(or --demo)",
                file=sys.stderr,
            )
            return EXIT_USER_ERROR
    formats = _mesh_formats(args.format)
    if formats is None:
        return EXIT_USER_ERROR
    from recon.io.patients import check_same_patient

    patients = check_same_patient(file_a, file_b, allow_different=args.allow_different_patients,
                                  hint="give --allow-different-patients to go on anyway")
    if patients.same_patient is False:  # allowed: said, never the identifiers
        print(f"coronary3d: warning: {patients.message()}; going on as asked",
              file=sys.stderr)

    def progress(stage: str, fraction: float) -> None:
        if not args.quiet:
            print(f"[{fraction * 100:5.1f}%] {stage}", file=sys.stderr, flush=True)

    inputs = input_files(file_a, file_b, seeds_path, getattr(args, "geometry_json", None),
                          getattr(args, "geometry_a", None), getattr(args, "geometry_b", None))
    check_output_dir(Path(args.out), formats, args.sr, inputs, report=args.report)
    overrides_a, overrides_b = _overrides_ab(args)
    t0 = time.perf_counter()
    # uncompressed 16-bit pixel data: about one pixel per two bytes of file
    file_px = max(file_bytes(file_a), file_bytes(file_b)) // 2
    hard = _REAL_PROCESS  # a stuck native call ends the process (no output is written yet)
    with job_limits(limits_for(file_px, args.max_memory_gb, args.max_cpu_s), "loading", hard):
        angio_a = load_angiogram(file_a, frame=args.frame_a, overrides=overrides_a)
        angio_b = load_angiogram(file_b, frame=args.frame_b, overrides=overrides_b)
    for angio in (angio_a, angio_b):
        _warn_replaced(angio)
    sr_sources = None
    if args.sr:  # refused before the reconstruction when the inputs cannot carry an SR
        from recon.io.sr import read_sr_sources

        frames = (angio_a.frame_index + 1, angio_b.frame_index + 1)
        sr_sources = read_sr_sources(file_a, file_b, frames)
    seeds = load_seeds(seeds_path)
    try:
        segment = segment_choice(args.segment, seeds, seeds_path)
    except ValueError as err:
        print(f"coronary3d: error: {err}", file=sys.stderr)
        return EXIT_USER_ERROR
    options = ReconstructionOptions(
        matcher=args.matcher,
        optimizer=args.optimizer,
        segment=segment or 0,
        self_calibration=args.self_calibration,
        intensity_a=args.intensity_a,
        intensity_b=args.intensity_b,
        allow_close_views=args.allow_close_views,
        calibration=args.calibration,
        tracer=args.tracer,
        aortic_pressure_mmhg=args.aortic_pressure,
        ffr_velocity_m_s=args.ffr_velocity,
        ffr_split_exponent=args.ffr_split_exponent,
    )
    pixels = max(angio_a.image.size, angio_b.image.size)
    with job_limits(limits_for(pixels, args.max_memory_gb, args.max_cpu_s), hard_exit=hard):
        if segment is None:
            rec = reconstruct_tree(angio_a, angio_b, seeds, options, progress=progress)
            parts = [(seeds.segments[b.options.segment].name, b) for b in rec.branches]
        else:
            rec = reconstruct_pair(angio_a, angio_b, seeds, options, progress=progress)
            parts = [(seeds.segments[segment].name, rec)]
        extra = {}
        if args.report:
            from recon.io.report_pdf import report_pdf_bytes

            # the whole reconstruction: an overview, then a page per segment
            extra["report.pdf"] = report_pdf_bytes(rec, angio_a.image, angio_b.image,
                                                   identify=args.identify)
    written = write_outputs(rec, Path(args.out), formats=formats, sr_sources=sr_sources,
                            inputs=inputs, extra=extra)
    for line in rec.warnings:  # shown even with --quiet: they qualify the numbers
        print(f"coronary3d: warning: {line}", file=sys.stderr)
    if not args.quiet:
        print(f"done in {(time.perf_counter() - t0):.2f} s", file=sys.stderr)
        for name, part in parts:
            m = part.measurements
            print(
                f"{name}: length {m.segment_length_mm:.1f} mm, MLD {m.mld_mm:.2f} mm, "
                f"diameter stenosis {m.diameter_stenosis_pct:.0f} %, "
                f"lesion {m.lesion_length_mm:.1f} mm{ffr_words(part)}",
                file=sys.stderr,
            )
        for bif in getattr(rec, "bifurcations", ()):
            print(f"{bif.name}: bifurcation angle {bif.bifurcation_angle_deg:.0f} deg, "
                  f"proximal angle {bif.proximal_angle_deg:.0f} deg, Medina {bif.medina}",
                  file=sys.stderr)
    for path in written:
        print(path)
    return 0


def _add_limit_options(p: argparse.ArgumentParser, who: str) -> None:
    for flag, what, default in (("--max-memory-gb", "memory", "1.5 GB"),
                                ("--max-cpu-s", "CPU time", "60 s")):
        p.add_argument(flag, type=_number(float, 0.0), metavar=flag.rsplit("-", 1)[1].upper(),
                       help=f"{what} {who} may use (default {default} for 512 x 512 views, "
                       "in proportion for larger ones; 0: no limit)")


def _mesh_formats(text: str) -> tuple[str, ...] | None:
    """The --format list, or None (after one error line) when it names an unknown format."""
    from recon.io.outputs import MESH_FORMATS

    formats = tuple(f.strip().lower() for f in text.split(",") if f.strip())
    if not formats or any(f not in MESH_FORMATS for f in formats):
        print(f"coronary3d: error: --format {text!r}: choose from {', '.join(MESH_FORMATS)}",
              file=sys.stderr)
        return None
    return formats


def cmd_batch(args: argparse.Namespace) -> int:
    from recon.io.engine import run_batch
    from recon.io.manifest import read_manifest

    formats = _mesh_formats(args.format)
    if formats is None:
        return EXIT_USER_ERROR
    cases = read_manifest(args.manifest)
    tty = sys.stderr.isatty()

    def on_start(summary, n_to_run: int) -> None:
        if args.quiet:
            return
        where = args.scheduler or f"a local cluster of {args.workers} worker(s)"
        swept = f"; {len(summary.swept)} left by a killed run removed" if summary.swept else ""
        print(f"{len(cases)} case(s): {summary.skipped} already recorded, {n_to_run} to run "
              f"on {where}{swept}", file=sys.stderr)
        if n_to_run:
            dashboard = summary.dashboard or "not available (install coronary3d[batch])"
            print(f"Dask dashboard: {dashboard}", file=sys.stderr)

    def on_case(record: dict, completed: int, total: int) -> None:
        if args.quiet:
            return
        width = 30
        filled = round(width * completed / total)
        bar = f"[{'#' * filled}{'.' * (width - filled)}] {completed}/{total}"
        if tty:
            end = "\n" if completed == total else ""
            print(f"\r{bar} {record['id']}: {record['status']}\033[K", end=end, file=sys.stderr,
                  flush=True)
        else:
            print(f"{bar} {record['id']}: {record['status']}", file=sys.stderr, flush=True)

    summary = run_batch(
        cases,
        Path(args.out),
        formats=formats,
        sr=args.sr,
        workers=args.workers,
        scheduler=args.scheduler,
        retry_failed=args.retry_failed,
        on_start=on_start,
        on_case=on_case,
        limits=(args.max_memory_gb, args.max_cpu_s),
    )
    if not args.quiet:
        for record in summary.records:
            if record["status"] == "failed":
                print(f"coronary3d: failed: {record['id']}: {record['error']}", file=sys.stderr)
        print(f"{summary.done} done, {summary.failed} failed ({summary.run} run now, "
              f"{summary.skipped} skipped)", file=sys.stderr)
    for path in summary.tables:
        print(path)
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    from recon.io.demo import demo_paths
    from viewer_app import run_viewer

    if bool(args.file_a) != bool(args.file_b):
        print("coronary3d: error: view needs two files A B, or none for the demo", file=sys.stderr)
        return EXIT_USER_ERROR
    demo = demo_paths() if not args.file_a else None
    file_a = args.file_a or str(demo["a"])
    file_b = args.file_b or str(demo["b"])
    seeds = args.seeds or (str(demo["seeds"]) if demo else None)
    if args.host not in ("127.0.0.1", "localhost", "::1"):
        print(f"coronary3d: warning: --host {args.host}: the viewer (and both angiograms) can be "
              "reached from other machines by anyone given its address", file=sys.stderr)
    overrides_a, overrides_b = _overrides_ab(args)
    run_viewer(
        file_a,
        file_b,
        seeds,
        host=args.host,
        port=args.port,
        on_ready=lambda url: print(f"coronary3d viewer: {url}", flush=True),
        overrides_a=overrides_a,
        overrides_b=overrides_b,
        out_dir=args.out,
    )
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    try:
        run, fmt, kwargs = bench_call(args)
    except ValueError as err:
        print(f"coronary3d: error: {err}", file=sys.stderr)
        return EXIT_USER_ERROR
    result = run(**kwargs)
    print(fmt(result))
    if args.json:
        from recon.io.files import atomic_write_bytes

        atomic_write_bytes(
            Path(args.json), (json.dumps(result, indent=2, default=float) + "\n").encode()
        )
        print(f"wrote {args.json}")
    return 0


COMMANDS = {
    "info": cmd_info,
    "phantom": cmd_phantom,
    "reconstruct": cmd_reconstruct,
    "batch": cmd_batch,
    "view": cmd_view,
    "bench": cmd_bench,
}


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; returns the exit code (argparse's own errors exit 2 through SystemExit).

    A SIGTERM or SIGINT is exit 128 + its number, whenever it comes: also in the instant
    before the command starts or while the signal handlers are put back after it."""
    try:
        return _main(argv)
    except KeyboardInterrupt as exc:  # recon.io.output_set.Terminated included
        return 128 + int(getattr(exc, "signum", 2))  # 2: SIGINT


def _main(argv: Sequence[str] | None) -> int:
    import signal

    from recon.io.output_set import Terminated, raise_on_termination

    global _REAL_PROCESS
    _REAL_PROCESS = argv is None  # the console script and `python -m recon.cli`
    if _REAL_PROCESS:
        cap_math_threads()  # before numpy loads (recon.startup)

    args = build_parser().parse_args(argv)
    handlers = {sig: signal.getsignal(sig) for sig in (signal.SIGTERM, signal.SIGINT)}
    if _REAL_PROCESS:  # a signal after the command ends the process (no Python handler)
        handlers = dict.fromkeys(handlers, signal.SIG_DFL)
    raise_on_termination()  # SIGTERM / SIGINT clean up temporary files on their way out
    try:
        return COMMANDS[args.command](args)
    except Terminated as exc:
        return 128 + exc.signum
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # stdout closed early (`coronary3d info --json | head`)
        _silence_stdout()
        return 0
    except CoronaryError as exc:
        if os.environ.get("CORONARY3D_DEBUG"):
            raise
        print(f"coronary3d: error: {_one_line(exc)}", file=sys.stderr)
        return EXIT_USER_ERROR
    finally:
        for sig, handler in handlers.items():
            with contextlib.suppress(ValueError, TypeError):  # not the main thread
                signal.signal(sig, handler)


def _one_line(exc: BaseException) -> str:
    """An error's message as one printable line (a path may hold a newline or a control byte)."""
    return "".join(ch if ch.isprintable() else "?" for ch in str(exc).strip())


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush is quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    sys.exit(main())
