"""The ``fourd`` command. See DESIGN.md "Command line" (a contract scripts depend on)."""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import signal
import sys
import threading
import time
import tomllib
from pathlib import Path

from fourd.cache import counting_resumes
from fourd.compile_notice import listen_for_compiles, stop_listening
from fourd.errors import InputError
from fourd.jsonable import jsonable
from fourd.progress import progress_write

log = logging.getLogger("fourd.cli")

EXIT_BAD_INPUT = 2
#: A run that ran out of memory (a MemoryError; the kernel's OOM killer ends a process unseen).
EXIT_OUT_OF_MEMORY = 3
#: Exit status after Ctrl-C (SIGINT) and after SIGTERM: 128 + the signal's number.
EXIT_INTERRUPTED = 128 + signal.SIGINT
EXIT_TERMINATED = 128 + signal.SIGTERM


class Terminated(BaseException):
    """Raised in the main thread by SIGTERM (:func:`_terminate`), so that a run stops as it
    does on Ctrl-C: ``finally`` blocks run, a half-written output or cache entry is removed,
    and :func:`main` exits with :data:`EXIT_TERMINATED`. Not an ``Exception``: no
    ``except Exception`` swallows it."""


def _terminate(signum, frame):
    raise Terminated


def _frames_slice(text: str | None) -> slice:
    """Parse ``A:B:S`` (any part may be empty) into a slice."""
    if not text:
        return slice(None)
    parts = text.split(":")
    if len(parts) > 3:
        raise InputError(f"--frames expects A:B:S, got {text!r}")
    try:
        values = [int(p) if p.strip() else None for p in parts]
    except ValueError:
        raise InputError(f"--frames expects integers A:B:S, got {text!r}") from None
    values += [None] * (3 - len(values))
    if values[2] is not None and values[2] <= 0:
        raise InputError(f"--frames step must be positive, got {values[2]}")
    return slice(*values)


def _read_config(path: str | None) -> tuple[str | None, dict]:
    """Method name and options from a TOML file: ``method = "..."`` and an ``[options]`` table
    (or a table named after the method)."""
    if not path:
        return None, {}
    try:
        with open(path, "rb") as handle:
            config = tomllib.load(handle)
    except FileNotFoundError:
        raise InputError("config file does not exist", path) from None
    except (OSError, tomllib.TOMLDecodeError) as error:
        raise InputError(f"cannot read config ({error})", path) from None
    method = config.get("method")
    options = dict(config.get("options", {}))
    if method and isinstance(config.get(method), dict):
        options.update(config[method])
    return method, options


class _StderrHandler(logging.StreamHandler):
    """Writes to whatever ``sys.stderr`` is at the time of each message, on a line of its own
    when a progress bar is drawn there (the bar is cleared, then drawn again below)."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, value):
        pass

    def emit(self, record):
        try:
            progress_write(self.format(record), file=sys.stderr)
        except Exception:
            self.handleError(record)


def _configure_logging(quiet: bool, verbose: bool = False) -> None:
    level = logging.WARNING if quiet else (logging.DEBUG if verbose else logging.INFO)
    logger = logging.getLogger("fourd")
    logger.setLevel(level)
    if not any(isinstance(h, _StderrHandler) for h in logger.handlers):
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("%(message)s"))
        logger.addHandler(handler)
    logger.propagate = False




def _select_frames(seq, text: str | None, source):
    """``seq`` restricted to ``--frames A:B:S``; InputError naming ``--frames`` and the valid
    range when it selects no frame, a warning when it reaches past the input's frames."""
    chosen = _frames_slice(text)
    count = len(seq)
    indices = range(count)[chosen]
    valid = f"the input has {count} frame{'s' if count != 1 else ''} (0-{count - 1})"
    if len(indices) == 0:
        raise InputError(f"--frames {text} selects no frame: {valid}", source)
    beyond = [v for v in (chosen.start, chosen.stop) if v is not None and not -count <= v <= count]
    if beyond:
        log.warning("--frames %s reaches past the input's frames: %s; using %d of them (%d-%d)",
                    text, valid, len(indices), min(indices), max(indices))
    return seq[chosen]


def _positive(value: float | None, option: str) -> float | None:
    """``value`` when it is None or a positive finite number, else InputError naming ``option``."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise InputError(f"{option} must be a positive number, got {value:g}")
    return value


def _time_note(base, kind: str) -> str:
    """How the written file reads the times, for the log (empty for formats without a time
    base)."""
    if kind not in ("glb", "usd", "abc", "pc2"):
        return ""
    if base.unit == "frames":
        return f"; times are frame numbers at {base.fps:g} fps"
    return f"; times are seconds, {base.fps:.6g} fps"


def _want_uv(flag: bool | None) -> bool:
    """``--uv`` / ``--no-uv`` / neither (on when xatlas is installed); InputError for ``--uv``
    without xatlas, before any work."""
    from fourd.geometry.parameterization import uv_available

    if flag is False:
        return False
    if uv_available():
        return True
    if flag:
        raise InputError("--uv needs the xatlas package, which is not installed: "
                         "pip install 'fourd[uv]'")
    log.info("no UV atlas: the xatlas package is not installed (pip install 'fourd[uv]')")
    return False


def _with_uv_and_colors(result, seq, *, uv: bool, colors: bool):
    """``result`` with a UV atlas of its template (``rest``, else frame 0) and the input's
    colours carried to its vertices, as asked; a MeshSequence is returned as it is."""
    import dataclasses

    from fourd.animation import AnimatedMesh

    if not isinstance(result, AnimatedMesh) or len(result.faces) == 0:
        if uv or colors:
            log.info("the result has no single connectivity with faces: no UVs or vertex colours")
        return result
    changes = {}
    if uv:
        from fourd.geometry.parameterization import uv_atlas

        start = time.perf_counter()
        template = result.rest if result.rest is not None else result.vertices[0]
        changes["uv"] = uv_atlas(template, result.faces)
        log.info("UV atlas of %d vertices in %.1f s", result.vertex_count,
                 time.perf_counter() - start)
    if colors:
        from fourd.appearance import vertex_colors

        changes["colors"] = vertex_colors(result, seq)
    return dataclasses.replace(result, **changes) if changes else result


def cmd_reconstruct(args) -> int:
    from fourd.io.frames import load_sequence
    from fourd.io.results import save
    from fourd.io.timebase import time_base, time_unit_of
    from fourd.methods import (
        DEFAULT_METHOD,
        method_module,
        method_options,
        reconstruct,
        resolve_alias,
    )
    from fourd.options import parse_assignments
    from fourd.preflight import check_output

    output = Path(args.output)
    fps = _positive(args.fps, "--fps")
    scale = _positive(args.scale, "--scale")
    config_method, values = _read_config(args.config)
    values.update(parse_assignments(args.set or []))
    method = args.method or config_method or DEFAULT_METHOD
    method, values = resolve_alias(method, values)
    module = method_module(method)
    if args.stream:
        return _reconstruct_streamed(args, method, values)
    if args.times:
        import dataclasses

        if "times" not in {f.name for f in dataclasses.fields(module.Options)}:
            raise InputError(f"--times: method {method!r} writes one frame per input frame only")
        values["times"] = args.times
    if args.cache:
        import dataclasses

        if "cache_dir" not in {f.name for f in dataclasses.fields(module.Options)}:
            raise InputError(f"--cache: method {method!r} cannot resume from a cache yet")
        _check_cache(args.cache)
        values["cache_dir"] = args.cache
    if args.scheduler:
        import dataclasses

        if "scheduler" not in {f.name for f in dataclasses.fields(module.Options)}:
            raise InputError(f"--scheduler: method {method!r} runs its stages in this process only "
                             "(perframe, assembly and garment map their frames)")
        values["scheduler"] = args.scheduler
    options = method_options(method, values)
    # What can be told without the data is checked before it is loaded: the output can be
    # written (a missing folder can be made) and its format holds the method's result.
    kind = check_output(args.output, method, module, create_parents=True)
    uv = _want_uv(args.uv)
    seq = load_sequence(args.input)
    seq = _select_frames(seq, args.frames, args.input)
    coloured = any(frame.colors is not None for frame in seq)
    if args.colors and not coloured:
        raise InputError("--colors: the input's frames have no colours", args.input)
    # (a .pc2 holds positions only; its .obj gets the UVs)
    colors = coloured and args.colors is not False and kind != "pc2"
    # The input's times say what the result's count (also at --times between them): whole
    # numbers are frame numbers at --fps (default 30), anything else seconds.
    base = time_base(seq.times, fps=fps, unit=time_unit_of(seq.times))
    log.info("%s: %d frames, %d to %d points per frame", args.input, len(seq),
             min(len(f) for f in seq), max(len(f) for f in seq))
    start = time.perf_counter()
    # (fourd.preflight.check_input runs here first: frame sizes, --times, memory)
    with counting_resumes() as resumed:
        result = reconstruct(seq, method, options, check_memory=not args.force)
    elapsed = time.perf_counter() - start
    result = _with_uv_and_colors(result, seq, uv=uv, colors=colors)
    if not output.parent.exists():  # check_output made sure it can be created
        try:
            output.parent.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise InputError(f"cannot create the output folder ({error.strerror or error})",
                             args.output) from None
        log.info("created the folder %s", output.parent)
    save(result, args.output, fps=base.fps, time_unit=base.unit, up=args.up, scale=scale,
         glb_encoding=args.glb_encoding)
    log.info("wrote %s (%d frames, %.2f s, %.2f s/frame%s%s)", output, result.frame_count, elapsed,
             elapsed / max(len(seq), 1), _time_note(base, kind),
             "; resumed from the cache: the time counts only the work done now" if resumed else "")
    return 0


def _reconstruct_streamed(args, method: str, values: dict) -> int:
    """``reconstruct --stream``: auto, kinematic, flow, watertight, assembly or surfels over
    frames read a window at a time, the result written frame by frame
    (:mod:`fourd.methods.auto.stream`, :mod:`fourd.methods.kinematic.stream`,
    :mod:`fourd.methods.flow.windows`, :mod:`fourd.methods.watertight.stream`,
    :mod:`fourd.methods.assembly.stream`, :mod:`fourd.methods.surfels.stream`)."""
    from fourd.io.frames import open_sequence
    from fourd.io.npz import streamed_output
    from fourd.methods import (
        assembly,
        auto,
        flow,
        kinematic,
        method_options,
        surfels,
        watertight,
    )

    streamed = {
        "auto": auto.reconstruct_streamed,
        "kinematic": kinematic.reconstruct_streamed,
        "flow": flow.reconstruct_streamed,
        "watertight": watertight.reconstruct_streamed,
        "assembly": assembly.reconstruct_streamed,
        "surfels": surfels.reconstruct_streamed,
    }
    if method not in streamed:
        raise InputError(
            f"--stream: only auto, kinematic, flow, watertight, assembly and surfels run streamed (asked "
            f"for {method})"
        )
    for flag, given in (("--times", args.times), ("--uv", args.uv), ("--colors", args.colors),
                        ("--scheduler", args.scheduler)):
        if given:
            raise InputError(f"--stream: {flag} is not available on streamed runs")
    streamed_output(args.output)
    if args.scale != 1.0 or args.up != "y" or args.fps is not None:
        log.warning("--stream writes a .npz in the data's units and axes: --fps, --up and "
                    "--scale apply when it is converted")
    if args.cache:
        _check_cache(args.cache)
        values["cache_dir"] = args.cache
    options = method_options(method, values)
    source = _select_frames(open_sequence(args.input), args.frames, args.input)
    log.info("%s: %d frames, read a window at a time", args.input, len(source))
    summary = streamed[method](source, args.output, options)
    log.info("wrote %s (%d frames, %.2f s, %.2f s/frame, %d windows%s)", summary.output,
             summary.frames, summary.seconds, summary.seconds / summary.frames, summary.windows,
             f"; {summary.resumed} resumed from the cache: the time counts only the work done now"
             if summary.resumed else "")
    return 0


def _check_cache(folder: str) -> None:
    """``--cache DIR`` can be used: DIR is a folder (made if missing) that can be written."""
    path = Path(folder)
    if path.exists() and not path.is_dir():
        raise InputError("--cache: exists and is not a folder", folder)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        raise InputError(f"--cache: cannot create the folder ({error.strerror or error})",
                         folder) from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise InputError("--cache: the folder is not writable", folder)


def cmd_synth(args) -> int:
    from fourd import synth
    from fourd.synth.write import write_synth

    truth = synth.scene(args.scene, frames=args.frames, seed=args.seed)
    scans = synth.scan(truth, cameras=args.cameras, noise=args.noise, outliers=args.outliers,
                       resolution=args.resolution, seed=args.seed, appearance=args.appearance,
                       video=args.video, video_resolution=args.video_resolution,
                       lighting=args.lighting, mode="remeshed" if args.meshes else "depth")
    from fourd.synth.garments import GARMENT_SCENES, pattern_outline

    pattern = pattern_outline(args.scene, with_openings=True) if args.scene in GARMENT_SCENES else None
    write_synth(truth, scans, args.outdir, pattern=pattern)
    log.info("wrote %d scanned frames and the truth to %s", len(scans), args.outdir)
    return 0


def cmd_evaluate(args) -> int:
    from fourd.metrics import evaluate_files, format_report

    report = evaluate_files(args.result, args.truth, force=args.force, folds=args.folds)
    if args.json:
        print(json.dumps(jsonable(report), indent=2))
    else:
        print(format_report(report))
    return 0


def cmd_bench(args) -> int:
    from fourd.bench import default_output, merge_reports, run_bench

    # Without -o the report goes to the git-ignored benchmarks/out/, never over the tracked
    # benchmarks/BENCHMARKS.md (rewrite that one by naming it).
    output = args.output or default_output(args.quick and not args.merge)
    if args.merge:
        merge_reports(args.merge, output, notes=args.note or [])
        log.info("wrote %s", output)
        return 0
    run_bench(methods=args.methods, scenes=args.scenes, quick=args.quick, repeats=args.repeats,
              spread=args.spread, output=output, baselines=args.baselines, seed=args.seed, timeout=args.timeout,
              appearance=args.appearance, video=args.video)
    log.info("wrote %s", output)
    return 0


def cmd_demo(args) -> int:
    from fourd.demo import run_demo

    paths = run_demo(args.outdir, method=args.method)
    for label, path in paths.items():
        print(f"{label}: {path}")
    return 0


def cmd_view(args) -> int:
    from fourd.viz.viewer import EMBED_GLB_LIMIT, write_viewer

    outdir = Path(args.output) if args.output else Path(str(Path(args.result).with_suffix("")) + "-view")
    result, truth, metrics = args.result, args.truth, None
    if truth is not None:
        from fourd.io.results import load_result
        from fourd.metrics import check_truth, evaluate, load_truth

        result = load_result(args.result)
        truth = check_truth(result, load_truth(args.truth), args.result, args.truth,
                            force=args.force)
        # the page's metrics panel: what `fourd evaluate RESULT TRUTH` reports
        metrics = evaluate(result, truth)
    for flag, value in (("--carried-colors", args.carried_colors), ("--video", args.video)):
        if value and args.input is None:
            raise InputError(f"{flag} needs --input (the scans the result was made from)")
    page = write_viewer(result, outdir, truth=truth, scans=args.input, metrics=metrics,
                        material=args.material, carried_colors=args.carried_colors,
                        video=args.video, video_size=args.video_size)
    print(page)
    glb = page.parent / "result.glb"
    if glb.exists() and glb.stat().st_size > EMBED_GLB_LIMIT:
        log.info("the .glb is too big to inline: to play it, serve the folder "
                 "(python -m http.server -d %s) and open http://localhost:8000/", page.parent)
    if args.open:
        import webbrowser

        webbrowser.open(page.resolve().as_uri())
    return 0


def cmd_options(args) -> int:
    from fourd.methods import DEFAULT_METHOD, method_module
    from fourd.options import format_options

    name = args.method or DEFAULT_METHOD
    module = method_module(name)
    print(format_options(module.Options, getattr(module, "COMMON_OPTIONS", None),
                         everything=args.all, method=name))
    return 0


def cmd_learn_material(args) -> int:
    from fourd.deform import learn_material, save_material
    from fourd.deform.files import read_poses

    rest, poses, faces = read_poses(args.result)
    material = learn_material(rest, poses, faces)
    save_material(material, args.output)
    print(f"{args.output}: bending stiffness of {len(material.bending)} edges and shearing "
          f"stiffness of {len(material.shearing)} faces, learned from {len(poses)} poses")
    return 0


def cmd_deform(args) -> int:
    from fourd.deform import Deformer, load_material
    from fourd.deform.files import read_anchors, read_mesh, write_mesh

    vertices, faces = read_mesh(args.mesh)
    material = None
    if args.material:
        material = load_material(args.material)
        material.check(faces)
    spec = read_anchors(args.anchors, len(vertices), len(faces))
    deformer = Deformer(vertices, faces, material, anchors=spec.faces, fixed=spec.fixed,
                        handles=spec.handles, search=args.search)
    posed = deformer.pose(spec.transforms, spec.positions if len(spec.handles) else None,
                          axes=spec.axes)
    write_mesh(args.output, posed, faces)
    print(args.output)
    return 0


def cmd_info(args) -> int:
    from fourd.info import describe

    print(describe(args.path))
    return 0


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose ``epilog`` may be a function, called only when the help is shown
    (``fourd synth --help`` lists the scenes without every command importing them)."""

    def format_help(self) -> str:
        if callable(self.epilog):
            self.epilog = self.epilog()
        return super().format_help()


def _scenes_epilog() -> str:
    """The scenes of the synth registry (:data:`fourd.synth.scenes.SCENES`), one a line."""
    from fourd.synth.scenes import SCENES

    width = max(len(name) for name in SCENES)
    lines = [f"  {name:<{width}}  {text}" for name, text in SCENES.items()]
    return ("scenes:\n" + "\n".join(lines) + "\n\nThe shared-data scenes are read from "
            "../shared/data beside the project (or $FOURD_DATA); nothing is downloaded.")


def _method_help() -> str:
    from fourd.methods import DEFAULT_METHOD, METHODS

    return (f"reconstruction method: {', '.join(METHODS)} (default: {DEFAULT_METHOD}; "
            "fourd options METHOD lists its options)")


_VIEW_EPILOG = """\
The viewer is a folder (default RESULT-view/): open its index.html in a browser. The page
inlines three.js, the frames and the exported .glb, so it works from the file system and
loads nothing from the network. A .glb over 24 MB is not inlined, and browsers block a page
opened from file:// from loading it: to play it, serve the folder and open it over http://

  python -m http.server -d OUTDIR      # then open http://localhost:8000/

With --input scans that have colours or video (fourd synth --appearance cloth --video, or
cameras.json + video/<camera>/ beside the frames), the page also shows whether the texture
swims: the "carried colour" colouring (frame 0's colours kept on the vertices, beside the
input points in their own colours) and the input video beside the mesh with its outline:

  fourd view walk.npz --input filmed/ --video-size 320
"""

#: What a RESULT argument may be (every format ``fourd reconstruct -o`` writes).
_RESULT_HELP = ("a result: .npz, .glb, .usd/.usda/.usdc (needs usd-core), .abc (needs alembic3d), .pc2 (with its .obj "
                "beside it) or a folder of per-frame meshes")


def build_parser() -> argparse.ArgumentParser:
    from fourd.viz.video_panel import VIDEO_SIZE

    parser = _Parser(
        prog="fourd",
        description="Animated meshes from time-varying point clouds (4D scans).",
    )
    parser.add_argument("--version", action="version", version=f"fourd {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    def add(name, help_text, func, **kwargs):
        p = sub.add_parser(name, help=help_text, description=help_text, **kwargs)
        p.add_argument("--quiet", "-q", action="store_true", help="no progress bars or messages")
        p.add_argument("--verbose", "-v", action="store_true", help="debug messages")
        p.set_defaults(func=func)
        return p

    p = add("reconstruct", "reconstruct an animated mesh from a folder of scans", cmd_reconstruct)
    p.add_argument("input", help="folder of frame files (ply/obj/xyz/pts/npy/npz) or one .npz")
    p.add_argument("-o", "--output", required=True,
                   help="result: .npz, .glb, .usd/.usda/.usdc, .abc, .pc2 (+ .obj), or a folder")
    p.add_argument("--method", help=_method_help())
    p.add_argument("--config", help="TOML file with `method = ...` and an [options] table")
    p.add_argument("--set", action="append", metavar="KEY=VALUE", help="set a method option")
    p.add_argument("--frames", metavar="A:B:S", help="use input frames A:B:S (Python slice)")
    p.add_argument("--times", help="output times, comma separated (methods that support it)")
    p.add_argument("--cache", metavar="DIR",
                   help="keep finished stages in DIR; rerunning the same command resumes from them")
    p.add_argument("--scheduler", metavar="S",
                   help="where per-frame stages run: sync (here, the default), processes (local "
                        "processes side by side) or a dask.distributed scheduler's address "
                        "(tcp://HOST:PORT); the result is the same")
    p.add_argument("--stream", action="store_true",
                   help="whole captures: read the frames a window at a time (the option "
                        "window, default 20) and write the result (.npz) frame by frame, so "
                        "memory is bounded by the window, not the capture's length (auto, "
                        "kinematic, flow, watertight, assembly and surfels; --cache resumes it window by window)")
    p.add_argument("--force", action="store_true",
                   help="run even when the up-front estimate of the memory needed exceeds the "
                        "memory available")
    p.add_argument("--fps", type=float, metavar="F",
                   help="frames per second of the written animation (.glb, .usd, .abc, .pc2). "
                        "Input times that are whole numbers (no times.txt: 0, 1, 2, ...) are "
                        "frame numbers played at F (default 30); times with fractions "
                        "(a times.txt of time stamps) are seconds and F is the rate of the "
                        "frame-based timelines (USD time codes, .pc2 frames; default measured "
                        "from the times). --fps 1 reads whole-number times as seconds")
    p.add_argument("--up", choices=("y", "z"), default="y",
                   help="the data's up axis (default y). z: .glb and .abc (Y up by "
                        "specification/convention) are rotated (x, y, z) -> (x, z, -y), USD "
                        "gets upAxis Z; .npz, .pc2 and folders keep the data's axes")
    p.add_argument("--scale", type=float, default=1.0, metavar="S",
                   help="multiply every written position by S (all formats), e.g. 0.001 for "
                        "millimetre scans: glTF and fourd's USD (metersPerUnit 1) take "
                        "positions as metres")
    p.add_argument("--uv", action=argparse.BooleanOptionalAction, default=None,
                   help="a UV atlas of the animated mesh's template, shared by every frame "
                        "(.glb TEXCOORD_0, USD primvars:st, .abc uv, OBJ vt): texture it once. "
                        "Default: on when the xatlas package is installed (fourd[uv]); "
                        "--no-uv skips it (a few seconds per 10,000 vertices)")
    p.add_argument("--colors", action=argparse.BooleanOptionalAction, default=None,
                   help="vertex colours per frame from the nearest input point (.glb COLOR_0 "
                        "as the mean over observed frames, USD displayColor, .abc Cd, OBJ/PLY "
                        "per frame). Default: on when the input has colours")
    p.add_argument("--glb-encoding", choices=("quantized", "float"), default="quantized",
                   help=".glb morph targets: quantized (KHR_mesh_quantization, about half the "
                        "size; three.js, Babylon.js, Blender) or plain float32 (default "
                        "quantized)")

    p = add("synth", "synthesize a ground-truth scene and scan it with virtual depth cameras", cmd_synth,
            epilog=_scenes_epilog, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scene", help="one of the scenes below")
    p.add_argument("outdir", help="folder for the scans (frame_*.ply, times.txt, sensors.json) "
                                  "and the truth (truth.npz)")
    p.add_argument("--frames", type=int, default=None,
                   help="frames to make (default: 20, or what a shared scene has)")
    p.add_argument("--cameras", type=int, default=3)
    p.add_argument("--noise", type=float, default=0.002, help="fraction of the bounding-box diagonal")
    p.add_argument("--outliers", type=float, default=0.02, help="fraction of points")
    p.add_argument("--resolution", type=int, default=256, help="rays per camera side")
    p.add_argument("--appearance", choices=("skin", "cloth", "uniform"), default=None,
                   help="surface colour on the material (smooth low-contrast skin, a "
                        "high-contrast printed cloth or one uniform colour, chosen by --seed): "
                        "coloured scans")
    p.add_argument("--video", action="store_true",
                   help="also film every camera: cameras.json and video/<camera>/<frame>.png "
                        "(with --appearance cloth unless another is given)")
    p.add_argument("--video-resolution", type=int, default=None, metavar="N",
                   help="image side in pixels (default: --resolution, one pixel per depth ray)")
    p.add_argument("--lighting", choices=("lamps", "diffuse"), default="lamps",
                   help="the studio's light: three fixed lamps, or a uniform diffuse sky in which "
                        "a fold's valley is darker than its ridge (the garment studio of the "
                        "thesis; for --set wrinkles=true of the garment method)")
    p.add_argument("--meshes", action="store_true",
                   help="per-frame meshes with perfect geometry instead of scans: each frame's "
                        "true surface remeshed on its own (a different triangulation every "
                        "frame, vertices on the truth, at the rays' spacing; no noise or "
                        "outliers)")
    p.add_argument("--seed", type=int, default=0)

    p = add("evaluate", "metrics of a result against ground truth", cmd_evaluate)
    p.add_argument("result", help=_RESULT_HELP)
    p.add_argument("truth", help="the ground truth: a result in any of those formats, a "
                                 "points .npz [T, P, 3], or a folder from `fourd synth`")
    p.add_argument("--json", action="store_true", help="print all metrics as JSON")
    p.add_argument("--force", action="store_true",
                   help="score a truth whose frame count or bounding box differs from the "
                        "result's (frames matched by time)")
    p.add_argument("--folds", action="store_true",
                   help="also score the truth's folds: the share of those deeper than 0.5%% of "
                        "the diagonal that the result has within 1%% (garments; fourd.metrics.folds)")

    p = add("bench", "run methods x scenes and write a report (benchmarks/out/BENCHMARKS.md "
                     "unless -o names another)", cmd_bench)
    p.add_argument(
        "--methods",
        nargs="+",
        help="method names; NAME:key=value,... adds a row for a method with options as --set "
        "takes them (e.g. watertight, flow:missing_frames=1,2,resolution=64)",
    )
    p.add_argument("--scenes", nargs="+")
    p.add_argument("-o", "--output",
                   help="the Markdown report, with .json and plots beside it (default: "
                        "benchmarks/out/BENCHMARKS.md, with --quick benchmarks/out/"
                        "BENCHMARKS-quick.md, both git-ignored; -o benchmarks/BENCHMARKS.md "
                        "rewrites the tracked record)")
    p.add_argument("--quick", action="store_true", help="a tiny run that exercises the whole path")
    p.add_argument("--repeats", type=int, default=1, help="timing repeats (median reported)")
    p.add_argument("--spread", type=int, default=1, metavar="N",
                   help="N runs per row on the scans moved by seeded offsets of 1e-9 of their "
                        "diagonal (the first unmoved): each score their median, ranges in the "
                        ".json (how far rounding alone moves a method's scores)")
    p.add_argument("--baselines", action="store_true",
                   help="add the peers of BASELINES.md (needs the `baselines` extra: open3d)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--timeout", type=float, default=None, help="seconds one reconstruction may take")
    p.add_argument("--appearance", choices=("skin", "cloth", "uniform"), default=None,
                   help="scan every scene with this surface colour (coloured points)")
    p.add_argument("--video", action="store_true",
                   help="give the methods the rig's video too (--appearance cloth unless "
                        "another is given)")
    p.add_argument("--merge", nargs="+", metavar="JSON",
                   help="merge the .json reports of separate runs into OUTPUT instead of running")
    p.add_argument("--note", action="append", help="a line for the report's notes (with --merge)")

    p = add("demo", "synthesize, reconstruct, evaluate and render the embedded default scene", cmd_demo)
    p.add_argument("outdir", nargs="?", default="demo-out")
    p.add_argument("--method", help="method to use (default: the project's default)")

    p = add("view", "write a folder with a self-contained HTML viewer of a result "
                    "(index.html, result.glb, viewer.js, ...)", cmd_view,
            epilog=_VIEW_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("result", help=_RESULT_HELP)
    p.add_argument("--truth", help="ground truth (as for fourd evaluate): colours each vertex by "
                                   "its distance to it and fills the metrics panel")
    p.add_argument("--input", help="the scans (folder) to show as points; with colours or video "
                                   "it also gives the carried colour and the video panel")
    p.add_argument("-o", "--output", help="folder for the page (default: RESULT-view/)")
    p.add_argument("--open", action="store_true", help="open the page in a browser")
    p.add_argument("--force", action="store_true",
                   help="use a truth whose frame count or bounding box differs from the result's")
    p.add_argument("--material", help="a material from fourd learn-material: colours each vertex "
                                      "by how much the learned material lets it bend")
    p.add_argument("--carried-colors", "--carried-colours", dest="carried_colors",
                   action=argparse.BooleanOptionalAction, default=None,
                   help="a 'carried colour' colouring: frame 0's input colours kept on the vertices "
                        "of every frame, beside the input points in their own colours, so drift "
                        "shows as swimming colours (default: on when --input has colours and the "
                        "result is an animated mesh)")
    p.add_argument("--video", action=argparse.BooleanOptionalAction, default=None,
                   help="a panel with the input's video beside the mesh (the chosen camera's image "
                        "of the frame shown, the mesh's outline over it) (default: on when --input "
                        "has cameras.json and video/)")
    p.add_argument("--video-size", type=int, default=VIDEO_SIZE, metavar="PIXELS",
                   help=f"longest side of the video images inlined in the page; larger ones are "
                        f"downscaled (default {VIDEO_SIZE})")

    p = add("options", "a method's options to change first, with their defaults and what they do "
                       "(--all: the expert ones too)", cmd_options)
    p.add_argument("method", nargs="?", help="method name (default: the project's default)")
    p.add_argument("--all", "--long", dest="all", action="store_true",
                   help="describe the expert options too, not only the ones to change first "
                        "(--long is the old name)")

    p = add("info", "describe an input folder or a result: kind, frames, vertices, faces, "
                    "connectivity, closed and manifold or not (with the genus), time range", cmd_info)
    p.add_argument("path", help="a folder of scans, or " + _RESULT_HELP)
    p = add("learn-material", "learn bending and shearing stiffness from an animated mesh's "
            "frames (thesis 004, 2.7)", cmd_learn_material)
    p.add_argument("result", help="an animated mesh with one connectivity (.npz, a folder, ...)")
    p.add_argument("-o", "--output", required=True, help="the material (.npz)")

    p = add("deform", "pose a mesh with material-aware deformation from an anchors file "
            "(thesis 004, ch. 2; the file's format: fourd.deform.files)", cmd_deform)
    p.add_argument("mesh", help=".obj, .ply, or a result (its rest shape)")
    p.add_argument("--anchors", required=True, help="JSON: anchor triangles with rotations, "
                   "fixed vertices, dragged vertices")
    p.add_argument("--material", help="a material from learn-material (default uniform)")
    p.add_argument("--search", choices=("binary", "parabola"), default="binary",
                   help="the rotation search for dragged vertices")
    p.add_argument("-o", "--output", required=True, help="the posed mesh (.obj or .ply)")

    return parser


def _version() -> str:
    from fourd import __version__

    return __version__


def _interrupted(args, error: BaseException) -> int:
    """The one line and the exit status of a run stopped by Ctrl-C or SIGTERM."""
    terminated = isinstance(error, Terminated)
    line = "fourd: terminated" if terminated else "fourd: interrupted"
    cache = getattr(args, "cache", None)
    if cache:
        line += f"; the cache in {cache} keeps the finished stages (run the same command to resume)"
    print(line, file=sys.stderr)
    return EXIT_TERMINATED if terminated else EXIT_INTERRUPTED


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    _configure_logging(args.quiet, args.verbose)
    # SIGTERM stops the run as Ctrl-C does (handlers can only be set in the main thread)
    in_main_thread = threading.current_thread() is threading.main_thread()
    previous = signal.signal(signal.SIGTERM, _terminate) if in_main_thread else None
    compiles = listen_for_compiles(log)
    try:
        status = args.func(args)
        if summary := compiles.summary():
            log.info(summary)
        return status
    except (KeyboardInterrupt, Terminated) as error:
        return _interrupted(args, error)
    except InputError as error:
        print(f"fourd: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError) as error:
        name = error.filename or ""
        print(f"fourd: error: {name}: {error.strerror}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except MemoryError:
        hint = ""
        if getattr(args, "func", None) is cmd_reconstruct and not args.stream:
            hint = ("; for a long capture, --stream (auto, kinematic, flow, watertight, assembly, surfels) bounds "
                    "the memory by a window of frames, or --frames A:B reconstructs part of it")
        print(f"fourd: error: out of memory{hint}", file=sys.stderr)
        return EXIT_OUT_OF_MEMORY
    except BrokenPipeError:
        # The reader of our output went away (`fourd evaluate ... | head`): not an error.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
    finally:
        stop_listening(compiles)
        if in_main_thread:
            signal.signal(signal.SIGTERM, signal.SIG_DFL if previous is None else previous)


if __name__ == "__main__":
    sys.exit(main())
