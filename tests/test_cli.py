"""The command line: exit status 2 and one line naming the file for every kind of bad input."""

import dataclasses
import json
import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

import fourd
from fourd.cli import main
from fourd.methods import METHODS, method_module


def _ply(path: Path, points: np.ndarray) -> Path:
    header = f"ply\nformat ascii 1.0\nelement vertex {len(points)}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
    path.write_text(header + "\n".join(" ".join(f"{v:.6f}" for v in p) for p in points) + "\n")
    return path


def _sphere_points(count=400, seed=0, shift=0.0):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(count, 3))
    return p / np.linalg.norm(p, axis=1, keepdims=True) + shift


def _folder(tmp_path: Path, frames=2) -> Path:
    folder = tmp_path / "scans"
    folder.mkdir()
    for i in range(frames):
        _ply(folder / f"frame_{i}.ply", _sphere_points(seed=i, shift=0.05 * i))
    return folder


def _run_bad(capsys, argv, *needles):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    errors = [line for line in err.splitlines() if line.startswith("fourd: error:")]
    assert len(errors) == 1 and err.splitlines()[-1] == errors[0], err
    for needle in needles:
        assert needle in errors[0], (needle, errors[0])
    assert "Traceback" not in err


def _sequence_method():
    for name in METHODS:
        try:
            module = method_module(name)
        except Exception:
            continue
        if getattr(module, "MIN_FRAMES", 1) >= 2:
            return name
    pytest.skip("no sequence method (MIN_FRAMES >= 2) is registered yet")


def test_missing_folder(tmp_path, capsys):
    _run_bad(capsys, ["reconstruct", str(tmp_path / "nope"), "-o", str(tmp_path / "o.npz")], "nope")


def test_empty_folder(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    _run_bad(capsys, ["reconstruct", str(tmp_path / "empty"), "-o", str(tmp_path / "o.npz")], "empty")


def test_frame_with_zero_points(tmp_path, capsys):
    folder = _folder(tmp_path)
    _ply(folder / "frame_2.ply", np.zeros((0, 3)))
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz")], "frame_2.ply")


def test_nan_coordinates(tmp_path, capsys):
    folder = _folder(tmp_path)
    points = _sphere_points(seed=5)
    points[7, 1] = np.nan
    np.save(folder / "frame_2.npy", points)
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz")], "frame_2.npy", "NaN")


def test_truncated_ply(tmp_path, capsys):
    folder = _folder(tmp_path)
    text = (folder / "frame_1.ply").read_text().splitlines()
    (folder / "frame_1.ply").write_text("\n".join(text[: len(text) // 2]))
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz")], "frame_1.ply")


def test_malformed_ply_header(tmp_path, capsys):
    folder = _folder(tmp_path)
    (folder / "frame_1.ply").write_text("ply\nformat banana 1.0\nend_header\n")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz")], "frame_1.ply")


def test_unknown_extension(tmp_path, capsys):
    folder = _folder(tmp_path)
    (folder / "frame_2.stl").write_text("solid x\nendsolid x\n")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz")], "frame_2.stl")


def test_mixed_point_dimensions(tmp_path, capsys):
    folder = tmp_path / "mixed"
    folder.mkdir()
    np.save(folder / "a_0.npy", _sphere_points())
    np.save(folder / "a_1.npy", np.c_[_sphere_points(), np.zeros(400)])
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz")], "a_1.npy")


def test_too_few_frames_for_a_sequence_method(tmp_path, capsys):
    method = _sequence_method()
    folder = _folder(tmp_path, frames=1)
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz"), "--method", method],
             "at least 2 frames")


def test_unwritable_output(tmp_path, capsys):
    folder = _folder(tmp_path)
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(folder / "frame_0.ply" / "o.npz")],
             "frame_0.ply is a file, not a folder")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(folder / "frame_0.ply" / "deeper" / "o.npz")],
             "frame_0.ply is a file, not a folder")
    if Path("/proc").is_dir():  # writable bits for root, but no file can be made there
        _run_bad(capsys, ["reconstruct", str(folder), "-o", "/proc/o.npz"], "/proc", "cannot write")
    if os.geteuid() != 0:
        locked = tmp_path / "locked"
        locked.mkdir()
        locked.chmod(0o500)
        _run_bad(capsys, ["reconstruct", str(folder), "-o", str(locked / "o.npz")], "not writable")


@pytest.fixture
def no_method_runs(monkeypatch):
    """Every registered method's reconstruct fails the test when it is called."""

    def fail(*args, **kwargs):
        raise AssertionError("the method ran before the checks refused")

    for name in METHODS:
        module = method_module(name)
        monkeypatch.setattr(module, "reconstruct", fail)


@pytest.mark.usefixtures("no_method_runs")
def test_a_grid_too_large_for_the_memory_is_refused_before_the_work(tmp_path, capsys):
    folder = _folder(tmp_path, frames=3)
    method_module("flow"), method_module("auto")  # imported: time the check, not the imports
    for method in ("flow", "watertight", "auto"):
        start = time.perf_counter()
        _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "x.npz"), "--method", method,
                          "--set", "resolution=100000"],
                 f"method '{method}' would need about", "resolution=100000", "lower resolution")
        assert time.perf_counter() - start < 1.0
    # --force skips the estimate (here: straight into the method, which fails the test)
    with pytest.raises(AssertionError, match="the method ran"):
        main(["reconstruct", str(folder), "-o", str(tmp_path / "x.npz"), "--method", "flow",
              "--set", "resolution=100000", "--force"])


@pytest.mark.usefixtures("no_method_runs")
def test_per_frame_meshes_to_a_point_cache_are_refused_before_loading(tmp_path, capsys):
    for method in ("perframe", "flow"):
        _run_bad(capsys, ["reconstruct", str(tmp_path / "not-loaded"), "-o", str(tmp_path / "x.pc2"),
                          "--method", method],
                 "x.pc2", f"method '{method}' gives a mesh per frame",
                 "use --method auto, kinematic, ", " or write .npz, .glb, .usd, .abc or a folder")


def test_frames_out_of_range_name_the_option_and_the_range(tmp_path, capsys):
    folder = _folder(tmp_path, frames=3)
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz"), "--method", "perframe",
                      "--frames", "50:60"],
             "--frames 50:60 selects no frame: the input has 3 frames (0-2)")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz"), "--method", "perframe",
                      "--frames", "2:1"], "--frames 2:1 selects no frame")


def test_frames_too_small_are_named_and_a_missing_output_folder_is_made(tmp_path, capsys):
    folder = _folder(tmp_path, frames=3)
    _ply(folder / "frame_1.ply", _sphere_points(count=6, seed=1))
    out = tmp_path / "new" / "deeper" / "o.npz"
    assert main(["reconstruct", str(folder), "-o", str(out), "--method", "perframe", "--frames", "1:9"]) == 0
    err = capsys.readouterr().err
    assert "--frames 1:9 reaches past the input's frames: the input has 3 frames (0-2); using 2 of them (1-2)" in err
    assert "frame 0 (frame_1.ply, time 1) has 6 points, fewer than the 20 a surface needs: its mesh will be empty" in err
    assert out.exists()
    tiny = tmp_path / "tiny"
    tiny.mkdir()
    for i in range(2):
        _ply(tiny / f"frame_{i}.ply", _sphere_points(count=10, seed=i))
    _run_bad(capsys, ["reconstruct", str(tiny), "-o", str(tmp_path / "t.npz"), "--method", "perframe"],
             "every frame has fewer than 20 points")


def _truth_files(tmp_path):
    rng = np.random.default_rng(0)
    sphere = _sphere_points(count=300)
    vertices = np.stack([sphere + [0.1 * t, 0, 0] for t in range(3)])
    faces = np.zeros((0, 3), int)
    paths = {}
    for name, v in {"truth": vertices, "noisy": vertices + rng.normal(scale=0.01, size=vertices.shape),
                    "millimetres": 1000 * vertices, "elsewhere": vertices + 5.0, "short": vertices[:2]}.items():
        paths[name] = tmp_path / f"{name}.npz"
        np.savez(paths[name], vertices=v, faces=faces)
    return paths


def test_evaluate_refuses_a_truth_that_does_not_match(tmp_path, capsys):
    files = _truth_files(tmp_path)
    truth = str(files["truth"])
    for name, needle in [("millimetres", "bounding box"), ("elsewhere", "bounding box"),
                         ("short", "the result has 2 frames but the truth has 3")]:
        _run_bad(capsys, ["evaluate", str(files[name]), truth, "--json"],
                 f"{truth} does not look like the truth of {files[name]}: ", needle, "--force")
    capsys.readouterr()
    assert main(["evaluate", str(files["short"]), truth, "--json", "--force"]) == 0
    assert '"frames": 2' in capsys.readouterr().out


def test_evaluate_scores_a_garments_folds_when_asked(tmp_path, capsys):
    from fourd.synth.garments import tshirt

    garment = tshirt(6, 0)
    folded, plain = tmp_path / "folded.npz", tmp_path / "plain.npz"
    np.savez(folded, vertices=garment.vertices, faces=garment.faces)
    np.savez(plain, vertices=tshirt(6, 0, fold_depth=0.0).vertices, faces=garment.faces)
    assert main(["evaluate", str(folded), str(folded), "--json", "--folds"]) == 0
    assert json.loads(capsys.readouterr().out)["fold_recall"] == 1.0
    assert main(["evaluate", str(plain), str(folded), "--folds"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "truth folds found" in x)
    assert float(line.split()[-2]) < 0.4  # (the last column is the floor: not scored for folds)
    assert main(["evaluate", str(plain), str(folded), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["fold_recall"] is None  # only when asked


def test_view_refuses_a_truth_that_does_not_match(tmp_path, capsys):
    files = _truth_files(tmp_path)
    _run_bad(capsys, ["view", str(files["millimetres"]), "--truth", str(files["truth"]), "-o", str(tmp_path / "v")],
             "does not look like the truth of", "millimetres.npz", "truth.npz")
    assert not (tmp_path / "v").exists()
    assert main(["view", str(files["millimetres"]), "--truth", str(files["truth"]), "-o", str(tmp_path / "v"),
                 "--force", "--quiet"]) == 0
    assert (tmp_path / "v" / "index.html").exists()


def test_unknown_output_extension(tmp_path, capsys):
    folder = _folder(tmp_path)
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.xyz3"), "--method", "perframe"], "o.xyz3")


def test_unknown_method_and_option(tmp_path, capsys):
    folder = _folder(tmp_path)
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz"), "--method", "magic"], "magic", "perframe")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz"), "--method", "perframe",
                      "--set", "no_such_option=1"], "no_such_option", "valid keys")


def test_bad_frames_and_config(tmp_path, capsys):
    folder = _folder(tmp_path)
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz"), "--frames", "a:b"], "--frames")
    config = tmp_path / "bad.toml"
    config.write_text("method = [")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz"), "--config", str(config)], "bad.toml")


def test_reconstruct_perframe_to_npz_and_folder(tmp_path, capsys):
    folder = _folder(tmp_path, frames=2)
    config = tmp_path / "c.toml"
    config.write_text('method = "perframe"\n[options]\n')
    out = tmp_path / "o.npz"
    assert main(["reconstruct", str(folder), "-o", str(out), "--config", str(config), "--quiet"]) == 0
    with np.load(out) as data:
        assert data["times"].tolist() == [0.0, 1.0]
    outdir = tmp_path / "meshes"
    assert main(["reconstruct", str(folder), "-o", str(outdir), "--method", "perframe", "--quiet", "--frames", "1:"]) == 0
    meshes = sorted(p.name for p in outdir.iterdir() if p.suffix in (".obj", ".ply"))
    assert len(meshes) == 1
    assert main(["info", str(folder)]) == 0
    assert "2 frames" in capsys.readouterr().out


def test_every_subcommand_has_help(capsys):
    for command in ["reconstruct", "synth", "evaluate", "bench", "demo", "view", "info"]:
        with pytest.raises(SystemExit) as exit_info:
            main([command, "--help"])
        assert exit_info.value.code == 0
        assert "usage: fourd " + command in capsys.readouterr().out


def test_an_interrupted_run_resumes_from_its_cache(tmp_path, monkeypatch, capsys):
    from fourd.geometry import frame_surface

    folder = _folder(tmp_path, frames=3)
    cache = tmp_path / "cache"
    calls = []
    original = frame_surface._surface_of  # one frame's mesh, as perframe makes it

    def fail_on_third(settings, frame):
        calls.append(frame.time)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return original(settings, frame)

    monkeypatch.setattr(frame_surface, "_surface_of", fail_on_third)
    out = tmp_path / "o.npz"
    argv = ["reconstruct", str(folder), "-o", str(out), "--method", "perframe", "--cache", str(cache), "--quiet"]
    assert main(argv) == 130
    assert not out.exists() and len(list(cache.glob("perframe-*.npz"))) == 2
    calls.clear()
    monkeypatch.setattr(frame_surface, "_surface_of",
                        lambda settings, frame: (calls.append(frame.time), original(settings, frame))[1])
    assert main(argv) == 0
    assert calls == [2.0] and out.exists()
    assert main(argv[:-1]) == 0  # not quiet: the resumed frames are named
    assert "resumed: 3 of 3 frames' meshes from the cache" in capsys.readouterr().err


def test_every_method_takes_a_cache_folder(tmp_path, capsys):
    for name in METHODS:
        fields = {f.name: f.default for f in dataclasses.fields(method_module(name).Options)}
        assert fields.get("cache_dir", "missing") is None, name
    assert main(["options", "kinematic", "--all"]) == 0
    assert "\n  cache_dir = None  (str or None)" in capsys.readouterr().out
    # a file where the cache folder should be is named before the work
    blocked = tmp_path / "blocked"
    blocked.write_text("")
    folder = _folder(tmp_path, frames=2)
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.npz"), "--method",
                      "kinematic", "--cache", str(blocked)], "--cache", "blocked")


def test_per_frame_stages_run_where_scheduler_says_and_other_methods_refuse_it(tmp_path, capsys):
    folder = _folder(tmp_path, frames=2)
    out = tmp_path / "meshes.npz"
    assert main(["reconstruct", str(folder), "-o", str(out), "--method", "perframe", "--scheduler", "processes"]) == 0
    assert out.exists()
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "k.npz"), "--method", "kinematic",
                      "--scheduler", "processes"], "--scheduler", "in this process only")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "p.npz"), "--method", "perframe",
                      "--scheduler", "threads"], "scheduler", "sync, processes")


class _SlideSteps:
    """Counts the kinematic sliding's steps; with ``signum`` set, the second one sends that
    signal to this process (as a user or a scheduler would) and goes on."""

    def __init__(self, monkeypatch, signum=None):
        from fourd.methods.kinematic import sliding

        self.calls, self.signum, original = 0, signum, sliding.slide_step

        def step(*args, **kwargs):
            self.calls += 1
            if self.calls == 2 and self.signum is not None:
                os.kill(os.getpid(), self.signum)
            return original(*args, **kwargs)

        monkeypatch.setattr(sliding, "slide_step", step)


@pytest.mark.parametrize("signum, status, word", [(signal.SIGTERM, 143, "terminated"),
                                                   (signal.SIGINT, 130, "interrupted")])
def test_a_signal_stops_the_run_with_one_line_and_the_next_run_resumes(
    tmp_path, monkeypatch, capsys, signum, status, word
):
    folder = _folder(tmp_path, frames=4)
    out, cache = tmp_path / "o.npz", tmp_path / "cache"
    argv = ["reconstruct", str(folder), "-o", str(out), "--method", "kinematic", "--cache",
            str(cache), "--set", "template_vertices=400"]
    before = signal.getsignal(signal.SIGTERM)
    interrupt = signal.signal(signal.SIGINT, signal.default_int_handler)
    steps = _SlideSteps(monkeypatch, signum)
    try:
        assert main(argv) == status
    finally:
        signal.signal(signal.SIGINT, interrupt)
    assert signal.getsignal(signal.SIGTERM) == before  # main puts the handler back
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.splitlines()[-1].split("\r")[-1] == (
        f"fourd: {word}; the cache in {cache} keeps the finished stages (run the same command "
        "to resume)"
    )
    assert not out.exists() and not list(tmp_path.glob(".o*"))
    assert len(list(cache.glob("kinematic-prepare-*.npz"))) == 4
    assert len(list(cache.glob("kinematic-slide-*.npz"))) == 1

    steps.calls, steps.signum = 0, None
    assert main(argv) == 0 and out.exists()
    err = capsys.readouterr().err
    assert "resumed: 4 of 4 frames' preparation from the cache" in err
    assert "resumed: 1 of 3 slid frames from the cache" in err
    assert "resumed from the cache: the time counts only the work done now" in err
    assert steps.calls == 2


def _launch(argv):
    """``fourd`` in a child process with Ctrl-C's default handling (a child of a shell
    without job control starts with SIGINT ignored)."""
    import subprocess
    import sys

    import fourd

    src = str(Path(fourd.__file__).resolve().parents[1])
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([src, os.environ.get("PYTHONPATH", "")]))
    code = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
            "from fourd.cli import main; sys.exit(main(sys.argv[1:]))")
    return subprocess.Popen([sys.executable, "-c", code, *argv], stderr=subprocess.PIPE,
                            stdout=subprocess.DEVNULL, text=True, env=env)


def _wait_for(process, needle, seconds):
    """The child's stderr lines up to the first holding ``needle`` (read on a thread, so a
    silent child fails the test after ``seconds`` instead of hanging it)."""
    import queue
    import threading

    lines = queue.Queue()
    threading.Thread(target=lambda: [lines.put(line) for line in process.stderr] + [lines.put(None)],
                     daemon=True).start()
    seen = []
    deadline = time.monotonic() + seconds
    while True:
        line = lines.get(timeout=max(deadline - time.monotonic(), 0.01))
        if line is None:
            raise AssertionError(f"the run ended before {needle!r}: {''.join(seen)}")
        seen.append(line)
        if needle in line:
            return lines, seen


@pytest.mark.slow
@pytest.mark.parametrize("signum, status", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_a_killed_process_exits_with_the_signal_status_and_keeps_its_cache(tmp_path, signum, status):
    folder = _folder(tmp_path, frames=3)
    out, cache = tmp_path / "o.npz", tmp_path / "cache"
    process = _launch(["reconstruct", str(folder), "-o", str(out), "--method", "flow", "--cache",
                       str(cache), "--set", "resolution=12"])
    try:
        # the labels are kept before the solve starts; stop it in its second iteration
        lines, seen = _wait_for(process, "flow iteration 0", 240)
        process.send_signal(signum)
        assert process.wait(timeout=120) == status
    finally:
        process.kill()
    while (line := lines.get(timeout=10)) is not None:
        seen.append(line)
    err = "".join(seen)
    assert "Traceback" not in err
    last = err.splitlines()[-1].split("\r")[-1]
    assert last.startswith("fourd: ") and f"the cache in {cache} keeps the finished stages" in last
    assert not out.exists() and not list(tmp_path.glob(".o*")) and not list(cache.glob(".*"))
    assert len(list(cache.glob("flow-labels-*.npz"))) == 1


def _described(out: str) -> tuple[list[str], list[str]]:
    """The option names with a ``name = default`` header in ``fourd options`` output, and the
    description paragraphs (one per header line)."""
    import re

    names, texts = [], []
    for block in out.split("\n\n"):
        lines = block.splitlines()
        if lines and re.match(r"^  \w+ = ", lines[0]):
            names += re.findall(r"(?:^  |, )(\w+) = ", lines[0])
            texts.append(" ".join(line.strip() for line in lines[1:]))
    return names, texts


@pytest.mark.parametrize("method", list(METHODS))
def test_options_shows_the_common_ones_and_the_rest_under_all(capsys, method):
    module = method_module(method)
    fields = [f.name for f in dataclasses.fields(module.Options)]
    common = module.COMMON_OPTIONS
    assert 0 < len(common) <= 8 and len(common) < len(fields)
    assert main(["options", method]) == 0
    out = capsys.readouterr().out
    names, _ = _described(out)
    assert set(common) <= set(names) and len(names) <= len(common) + 2  # an entry's partner
    expert = out.split("expert options", 1)[1]
    assert f"fourd options {method} --all" in out
    assert all(name in expert for name in fields if name not in names)
    assert main(["options", method, "--all"]) == 0
    everything = capsys.readouterr().out
    names, texts = _described(everything)
    assert sorted(names) == sorted(fields)  # every option described, each once
    assert len(set(texts)) == len(texts) and all(texts), "a description shown twice or empty"
    assert "..." not in everything  # nothing cut short
    assert main(["options", method, "--long"]) == 0  # the old name still works
    assert capsys.readouterr().out == everything


def test_options_of_an_unknown_method(capsys):
    assert main(["options", "flow"]) == 0
    assert "resolution = 32  (int)" in capsys.readouterr().out
    assert main(["options", "nosuch"]) == 2
    assert "unknown method 'nosuch'" in capsys.readouterr().err


# ------------------------------------------------- time base, up axis, scale, Alembic


def _fake_reconstruct(monkeypatch, calls=None):
    """Replace the reconstruction by a known result (a sphere moving along x, one frame per
    input frame at the input's times): the output options are what is tested."""
    import trimesh

    import fourd.methods
    from fourd.animation import AnimatedMesh

    sphere = trimesh.creation.icosphere(subdivisions=1)

    def fake(seq, method, options, **kwargs):
        if calls is not None:
            calls.append(method)
        vertices = np.stack([sphere.vertices + [0.1 * k, 0, 0] for k in range(len(seq))])
        return AnimatedMesh(sphere.faces, vertices, times=seq.times)

    monkeypatch.setattr(fourd.methods, "reconstruct", fake)
    return fake


def _glb_keys(path, vertex_count=42):
    """Key times and frame 0's positions (the base, float32, through the node's quantization
    transform; the first ``vertex_count`` vertices, the copies on UV seams left out)."""
    import pygltflib

    gltf = pygltflib.GLTF2.load(path)
    blob = gltf.binary_blob()

    def values(index, width):
        accessor = gltf.accessors[index]
        view = gltf.bufferViews[accessor.bufferView]
        assert accessor.componentType == 5126
        start = (view.byteOffset or 0) + (accessor.byteOffset or 0)
        return np.frombuffer(blob, np.float32, accessor.count * width, start).reshape(accessor.count, width)

    times = values(gltf.animations[0].samplers[0].input, 1)[:, 0]
    node = gltf.nodes[0]
    base = values(gltf.meshes[0].primitives[0].attributes.POSITION, 3)[:vertex_count]
    return times, base * (node.scale or 1.0) + (node.translation or 0.0)


def test_fps_up_and_scale_reach_the_written_files(tmp_path, monkeypatch):
    from fourd.io.axes import z_up_to_y_up
    from fourd.io.pc2 import read_pc2

    fake = _fake_reconstruct(monkeypatch)
    folder = _folder(tmp_path, frames=3)  # no times.txt: frame numbers 0, 1, 2
    truth = fake(__import__("fourd").load_sequence(folder), "auto", None)
    options = ["--fps", "24", "--up", "z", "--scale", "2", "--quiet"]
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "o.glb"), *options]) == 0
    times, base = _glb_keys(tmp_path / "o.glb")
    assert np.allclose(times, [0, 1 / 24, 2 / 24])
    assert np.abs(base - z_up_to_y_up(2 * truth.vertices[0])).max() <= 1e-5
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "o.pc2"), *options]) == 0
    cache = read_pc2(tmp_path / "o.pc2")
    assert (cache.start, cache.rate) == (0.0, 1.0)
    assert np.abs(cache.vertices - 2 * truth.vertices).max() <= 1e-5  # no up axis in .pc2
    if _importable("pxr"):
        from pxr import Usd, UsdGeom

        assert main(["reconstruct", str(folder), "-o", str(tmp_path / "o.usda"), *options]) == 0
        stage = Usd.Stage.Open(str(tmp_path / "o.usda"))
        assert stage.GetTimeCodesPerSecond() == 24 and UsdGeom.GetStageUpAxis(stage) == "Z"
        points = UsdGeom.Mesh(stage.GetPrimAtPath("/Root/Mesh")).GetPointsAttr()
        assert points.GetTimeSamples() == [0.0, 1.0, 2.0]
        assert np.abs(np.array(points.Get(2)) - 2 * truth.vertices[2]).max() <= 1e-5
    if _importable("alembic3d"):
        from fourd.io.abc import read_abc

        assert main(["reconstruct", str(folder), "-o", str(tmp_path / "o.abc"), *options]) == 0
        back = read_abc(tmp_path / "o.abc")
        assert back.times.tolist() == [0.0, 1.0, 2.0]
        assert np.abs(back.vertices - z_up_to_y_up(2 * truth.vertices)).max() <= 1e-5


def test_times_txt_of_seconds_keep_their_seconds(tmp_path, monkeypatch, capsys):
    from fourd.io.pc2 import read_pc2

    _fake_reconstruct(monkeypatch)
    folder = _folder(tmp_path, frames=3)
    (folder / "times.txt").write_text("0.50\n0.54\n0.58\n")  # time stamps of a 25 fps capture
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "o.glb")]) == 0
    assert "times are seconds, 25 fps" in capsys.readouterr().err
    assert np.allclose(_glb_keys(tmp_path / "o.glb")[0], [0.5, 0.54, 0.58])
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "o.pc2"), "--quiet"]) == 0
    cache = read_pc2(tmp_path / "o.pc2")
    assert (cache.start, cache.rate) == (12.5, pytest.approx(1.0))
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "o.pc2"), "--fps", "100", "-q"]) == 0
    assert read_pc2(tmp_path / "o.pc2").start == 50.0  # another timeline rate, same seconds


def test_bad_output_options_stop_before_the_work(tmp_path, monkeypatch, capsys):
    calls = []
    _fake_reconstruct(monkeypatch, calls)
    folder = _folder(tmp_path, frames=2)
    out = str(tmp_path / "o.glb")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", out, "--fps", "0"], "--fps must be a positive number")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", out, "--scale", "-2"], "--scale must be a positive number")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", out, "--scale", "nan"], "--scale")
    for argv in (["--up", "x"], ["--fps", "fast"]):
        with pytest.raises(SystemExit) as info:
            main(["reconstruct", str(folder), "-o", out, *argv])
        assert info.value.code == 2
    assert calls == [] and not (tmp_path / "o.glb").exists()


def test_abc_without_alembic3d_is_one_line_before_the_work(tmp_path, monkeypatch, capsys):
    import builtins

    calls = []
    _fake_reconstruct(monkeypatch, calls)
    real_import = builtins.__import__

    def no_alembic(name, *args, **kwargs):
        if name in ("alembic3d", "imath") or name.startswith("alembic3d."):
            raise ImportError(f"No module named {name!r}")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_alembic)
    folder = _folder(tmp_path, frames=2)
    _run_bad(capsys, ["reconstruct", str(folder), "-o", str(tmp_path / "o.abc")],
             "o.abc: writing .abc needs the alembic3d package: pip install 'fourd[abc]'")
    assert calls == []


def test_info_and_evaluate_read_an_abc_result(tmp_path, monkeypatch, capsys):
    pytest.importorskip("alembic3d", reason="alembic3d (the fourd[abc] extra) is not installed")
    import fourd

    fake = _fake_reconstruct(monkeypatch)
    folder = _folder(tmp_path, frames=2)
    fourd.save(fake(fourd.load_sequence(folder), "auto", None), tmp_path / "truth.npz")
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "o.abc"), "-q"]) == 0
    assert main(["info", str(tmp_path / "o.abc")]) == 0
    out = capsys.readouterr().out
    assert "kind: animated mesh" in out and "frames: 2, times 0 .. 1" in out
    assert "vertices: 42" in out and "faces: 80" in out
    assert main(["evaluate", str(tmp_path / "o.abc"), str(tmp_path / "truth.npz"), "--json"]) == 0
    report = __import__("json").loads(capsys.readouterr().out)
    assert report["correspondence_mean"] < 1e-6  # the same mesh, vertex for vertex


def _importable(name: str) -> bool:
    import importlib.util

    return importlib.util.find_spec(name) is not None


@pytest.mark.parametrize("suffix", [".glb", ".pc2", ".usda", "/"])
def test_evaluate_and_view_read_every_result_format(tmp_path, capsys, suffix):
    if suffix == ".usda":
        pytest.importorskip("pxr", reason="usd-core (the fourd[usd] extra) is not installed")
    import trimesh

    from fourd.animation import AnimatedMesh
    from fourd.io.results import save

    sphere = trimesh.creation.icosphere(subdivisions=1)
    vertices = np.stack([sphere.vertices + [0.1 * t, 0, 0] for t in range(3)])
    truth = AnimatedMesh(sphere.faces, vertices)
    save(truth, tmp_path / "truth.npz")
    result = str(tmp_path / "result") + suffix
    save(AnimatedMesh(sphere.faces, vertices * 1.01), result)
    assert main(["evaluate", result, str(tmp_path / "truth.npz"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["frames"] == 3 and 0 < report["chamfer"] < 0.01
    assert main(["view", result, "--truth", str(tmp_path / "truth.npz"), "-o", str(tmp_path / "v"),
                 "--quiet"]) == 0
    from fourd.viz.viewer import read_viewer_data

    data = read_viewer_data(tmp_path / "v" / "index.html")
    assert data["hasErrors"] and data["metrics"]["chamfer"] == pytest.approx(report["chamfer"])


def test_view_shows_carried_colours_and_video_of_a_filmed_input(tmp_path, capsys):
    """On by default when the input has them; asked for without them: exit 2 naming the file."""
    import trimesh

    import fourd
    from fourd.animation import AnimatedMesh, MeshSequence
    from fourd.io.frames import write_frames
    from fourd.io.results import save
    from fourd.sequence import PointCloudSequence
    from fourd.viz.viewer import read_viewer_data

    sphere = trimesh.creation.icosphere(subdivisions=2)
    anim = AnimatedMesh(sphere.faces, np.stack([sphere.vertices + [0.1 * t, 0, 0] for t in range(2)]))
    save(anim, tmp_path / "result.npz")
    scans = fourd.synth.scan(anim, resolution=24, cameras=1, appearance="cloth", video=True,
                             video_resolution=40, outliers=0.0)
    write_frames(scans, tmp_path / "filmed")
    write_frames(PointCloudSequence.from_arrays(list(anim.vertices)), tmp_path / "plain")
    result, view = str(tmp_path / "result.npz"), str(tmp_path / "v")
    assert main(["view", result, "--input", str(tmp_path / "filmed"), "-o", view, "--quiet",
                 "--video-size", "32"]) == 0
    data = read_viewer_data(tmp_path / "v" / "index.html")
    assert "carriedColors" in data and data["video"]["cameras"][0]["shownWidth"] == 32
    assert main(["view", result, "--input", str(tmp_path / "filmed"), "-o", view, "--quiet",
                 "--no-video", "--no-carried-colors"]) == 0
    data = read_viewer_data(tmp_path / "v" / "index.html")
    assert "carriedColors" not in data and "video" not in data
    assert main(["view", result, "--input", str(tmp_path / "plain"), "-o", view, "--quiet"]) == 0
    _run_bad(capsys, ["view", result, "--input", str(tmp_path / "plain"), "-o", view, "--carried-colours"],
             str(tmp_path / "plain"), "no colours")
    _run_bad(capsys, ["view", result, "--input", str(tmp_path / "plain"), "-o", view, "--video"],
             str(tmp_path / "plain"), "no video")
    _run_bad(capsys, ["view", result, "-o", view, "--video"], "--video needs --input")
    _run_bad(capsys, ["view", result, "--input", str(tmp_path / "filmed"), "-o", view,
                      "--video-size", "2"], "video size")
    meshes = MeshSequence((anim.frame(0), (anim.vertices[1], anim.faces[1:])))
    save(meshes, tmp_path / "meshes")
    _run_bad(capsys, ["view", str(tmp_path / "meshes"), "--input", str(tmp_path / "filmed"), "-o", view,
                      "--carried-colors"], str(tmp_path / "meshes"), "animated mesh")


def test_view_help_says_it_writes_a_folder_and_how_to_serve_it(capsys):
    from fourd.viz.viewer import EMBED_GLB_LIMIT

    with pytest.raises(SystemExit):
        main(["view", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert "write a folder" in out and "index.html" in out
    assert "python -m http.server -d OUTDIR" in out and "file://" in out
    assert f"A .glb over {EMBED_GLB_LIMIT // 1_000_000} MB is not inlined" in out


def test_bench_never_writes_the_tracked_record_unless_told(tmp_path, monkeypatch):
    """Without -o the report goes to the git-ignored benchmarks/out/ (the quick run to its own
    file there); only -o benchmarks/BENCHMARKS.md rewrites the record."""
    import fourd.bench

    calls = []
    monkeypatch.setattr(fourd.bench, "run_bench", lambda **kw: calls.append(("run", kw)))
    monkeypatch.setattr(fourd.bench, "merge_reports", lambda parts, out, notes: calls.append(("merge", out)))
    assert main(["bench", "--quiet"]) == 0
    assert main(["bench", "--quick", "--quiet"]) == 0
    assert main(["bench", "--merge", "a.json", "--quiet"]) == 0
    assert main(["bench", "--quiet", "-o", "benchmarks/BENCHMARKS.md"]) == 0
    outputs = [Path(kw["output"]) if kind == "run" else Path(kw) for kind, kw in calls]
    assert outputs == [Path("benchmarks/out/BENCHMARKS.md"), Path("benchmarks/out/BENCHMARKS-quick.md"),
                       Path("benchmarks/out/BENCHMARKS.md"), Path("benchmarks/BENCHMARKS.md")]
    assert calls[1][1]["quick"] is True
    ignored = (Path(__file__).resolve().parents[1] / ".gitignore").read_text().split()
    assert "benchmarks/out/" in ignored


def test_help_lists_the_scenes_and_the_methods(capsys):
    from fourd.methods import DEFAULT_METHOD
    from fourd.synth.scenes import SCENES

    with pytest.raises(SystemExit):
        main(["synth", "--help"])
    out = capsys.readouterr().out
    assert all(f"  {name} " in out and text in out for name, text in SCENES.items())
    with pytest.raises(SystemExit):
        main(["reconstruct", "--help"])
    out = " ".join(capsys.readouterr().out.split())
    assert f"(default: {DEFAULT_METHOD};" in out
    assert all(name in out.split("--method METHOD", 2)[2] for name in METHODS)


# ------------------------------------------------------ UVs, vertex colours, .glb size


def _coloured_folder(tmp_path: Path, frames=2) -> Path:
    """Scans whose points are red on the +x side and blue elsewhere."""
    from fourd.io.ply import write_ply

    folder = tmp_path / "coloured"
    folder.mkdir()
    for i in range(frames):
        points = _sphere_points(seed=i) + [0.1 * i, 0, 0]  # follows the fake result's sphere
        colors = np.where(points[:, :1] - 0.1 * i > 0, [1.0, 0, 0], [0, 0, 1.0])
        write_ply(folder / f"frame_{i}.ply", points, colors=colors)
    return folder


def test_reconstruct_carries_colours_and_uvs_into_the_result(tmp_path, monkeypatch):
    import fourd
    from fourd.geometry.parameterization import uv_available

    _fake_reconstruct(monkeypatch)
    folder = _coloured_folder(tmp_path)
    uv = uv_available()
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "o.npz"), "-q"]) == 0
    result = fourd.io.results.load_result(tmp_path / "o.npz")
    assert result.colors is not None and (result.uv is not None) == uv
    x = result.vertices[:, :, 0] - 0.1 * np.arange(2)[:, None]  # across the moving sphere
    assert (result.colors[x > 0.2] == [1.0, 0, 0]).all()
    assert (result.colors[x < -0.2] == [0, 0, 1.0]).all()
    if uv:
        assert result.uv.shape == (len(result.faces), 3, 2)
        assert 0 <= result.uv.min() and result.uv.max() <= 1
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "plain.npz"), "-q",
                 "--no-uv", "--no-colors"]) == 0
    plain = fourd.io.results.load_result(tmp_path / "plain.npz")
    assert plain.uv is None and plain.colors is None


def test_glb_is_quantized_unless_asked_for_float(tmp_path, monkeypatch):
    import pygltflib

    _fake_reconstruct(monkeypatch)
    folder = _folder(tmp_path, frames=3)
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "q.glb"), "-q"]) == 0
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "f.glb"), "-q",
                 "--glb-encoding", "float"]) == 0
    quantized, plain = (pygltflib.GLTF2.load(tmp_path / name) for name in ("q.glb", "f.glb"))
    assert quantized.extensionsRequired == ["KHR_mesh_quantization"]
    assert not plain.extensionsRequired
    assert (tmp_path / "q.glb").stat().st_size < (tmp_path / "f.glb").stat().st_size
    assert np.allclose(_glb_keys(tmp_path / "q.glb")[1], _glb_keys(tmp_path / "f.glb")[1], atol=1e-5)


def test_uv_and_colors_flags_that_cannot_be_met_stop_before_the_work(tmp_path, monkeypatch, capsys):
    import sys

    calls = []
    _fake_reconstruct(monkeypatch, calls)
    folder = _folder(tmp_path, frames=2)  # no colours
    out = str(tmp_path / "o.glb")
    _run_bad(capsys, ["reconstruct", str(folder), "-o", out, "--colors"], "--colors", "no colours")
    monkeypatch.setitem(sys.modules, "xatlas", None)  # not installed
    _run_bad(capsys, ["reconstruct", str(folder), "-o", out, "--uv"], "xatlas", "fourd[uv]")
    assert calls == [] and not (tmp_path / "o.glb").exists()
    assert main(["reconstruct", str(folder), "-o", out]) == 0  # the default does without
    assert "no UV atlas: the xatlas package is not installed" in capsys.readouterr().err


# ----------------------------------------------------------------------- appearance and video


def test_synth_appearance_and_video_write_what_they_say(tmp_path):
    import fourd
    from fourd.io.ply import read_ply

    out = tmp_path / "filmed"
    argv = ["synth", "squash-ball", str(out), "--frames", "2", "--resolution", "32", "--quiet"]
    assert main([*argv, "--appearance", "cloth", "--video", "--video-resolution", "40"]) == 0
    assert (out / "cameras.json").is_file()
    for k in range(3):
        assert sorted(p.name for p in (out / "video" / f"cam_{k}").iterdir()) == [
            "frame_0000.png",
            "frame_0001.png",
        ]
    assert read_ply(out / "frame_0000.ply").colors is not None
    seq = fourd.load_sequence(out)
    assert seq.video.names == ("cam_0", "cam_1", "cam_2")
    assert seq.video.image("cam_1", 1).shape == (40, 40, 3)
    assert json.loads((out / "cameras.json").read_text())["cameras"][0]["width"] == 40

    plain = tmp_path / "skin"
    assert main(["synth", "squash-ball", str(plain), "--frames", "2", "--resolution", "32",
                 "--appearance", "skin", "--quiet"]) == 0
    assert not (plain / "cameras.json").exists() and not (plain / "video").exists()
    colours = fourd.load_sequence(plain)[0].colors
    assert colours is not None and colours.std() < 0.15  # skin: low contrast

    bare = tmp_path / "bare"
    assert main(["synth", "squash-ball", str(bare), "--frames", "2", "--resolution", "32", "--quiet"]) == 0
    assert read_ply(bare / "frame_0000.ply").colors is None


@pytest.fixture
def filmed(tmp_path):
    out = tmp_path / "filmed"
    assert main(["synth", "squash-ball", str(out), "--frames", "2", "--resolution", "24",
                 "--video", "--quiet"]) == 0
    return out


def test_bad_cameras_json_is_exit_2_naming_it(filmed, capsys):
    data = json.loads((filmed / "cameras.json").read_text())
    data["cameras"][1]["t"] = [0, 1]
    (filmed / "cameras.json").write_text(json.dumps(data))
    _run_bad(capsys, ["info", str(filmed)], str(filmed / "cameras.json"), "t must have shape")


def test_missing_or_wrong_image_is_exit_2_naming_it(filmed, capsys):
    missing = filmed / "video" / "cam_2" / "frame_0001.png"
    missing.unlink()
    _run_bad(capsys, ["info", str(filmed)], str(filmed / "video" / "cam_2"), "1 images", "2 frames")
    from PIL import Image

    Image.fromarray(np.zeros((24, 25, 3), np.uint8)).save(missing)
    _run_bad(capsys, ["reconstruct", str(filmed), "-o", str(filmed.parent / "o.npz")], str(missing), "25x24")


@pytest.mark.parametrize(("method", "settings"), [("kinematic", ["template_vertices=400"]),
                                                 ("watertight", ["window_overlap=1", "resolution=12"]),
                                                 ("assembly", ["relax_sweeps=1"]),
                                                 ("surfels", ["window=3", "sampling=2", "iterations=2",
                                                              "final_iterations=1",
                                                              "align_iterations=4"])])
def test_stream_writes_a_npz_read_a_window_at_a_time(tmp_path, capsys, method, settings):
    folder = _folder(tmp_path, frames=5)
    out = tmp_path / "out.npz"
    argv = ["reconstruct", str(folder), "-o", str(out), "--stream", "-q", "--method", method,
            "--set", "window=2", *(x for setting in settings for x in ("--set", setting))]
    assert main(argv) == 0
    from fourd.io.results import load_result

    result = load_result(out)
    assert result.frame_count == 5 and result.rest is not None
    # every frame's vertices on that frame's unit sphere (shifted 0.05 per frame)
    for t in range(5):
        radius = np.linalg.norm(result.vertices[t] - [0.05 * t] * 3, axis=1)
        assert np.abs(np.median(radius) - 1.0) < 0.05, t
    _run_bad(capsys, argv[:3] + [str(tmp_path / "out.glb"), "--stream"], "out.glb", ".npz")
    _run_bad(capsys, argv[:6] + ["--method", "perframe"], "--stream", "auto, kinematic, flow, watertight, assembly and surfels")
    _run_bad(capsys, argv + ["--times", "0.5"], "--stream", "--times")
    if method == "assembly":
        _run_bad(capsys, argv + ["--set", "paste=true"], "paste", "without --stream")


def test_stream_runs_the_default_method_with_its_options(tmp_path, monkeypatch):
    """``--stream`` without ``--method`` streams ``auto``, with the options set and the
    cache folder given."""
    from fourd.methods import auto

    seen = {}

    def streamed(source, output, options):
        seen.update(frames=len(source), output=output, options=options)
        return auto.StreamSummary(Path(output), len(source), 3, 2, 0, None, 1.0)

    monkeypatch.setattr(auto, "reconstruct_streamed", streamed)
    folder = _folder(tmp_path, frames=3)
    out = tmp_path / "out.npz"
    argv = ["reconstruct", str(folder), "-o", str(out), "--stream", "-q",
            "--set", "window=2", "--set", "resolution=24", "--cache", str(tmp_path / "cache")]
    assert main(argv) == 0
    assert seen["frames"] == 3 and Path(seen["output"]) == out
    assert (seen["options"].window, seen["options"].resolution) == (2, 24)
    assert seen["options"].cache_dir == str(tmp_path / "cache")


@pytest.mark.slow
def test_stream_runs_flow_in_windows(tmp_path):
    folder = _folder(tmp_path, frames=5)
    out = tmp_path / "out.npz"
    argv = ["reconstruct", str(folder), "-o", str(out), "--stream", "-q", "--method", "flow",
            "--set", "window=3", "--set", "window_overlap=1", "--set", "resolution=12"]
    assert main(argv) == 0
    from fourd.io.results import load_result

    result = load_result(out)
    assert isinstance(result, fourd.MeshSequence) and result.frame_count == 5
    for t, (vertices, faces) in enumerate(result.meshes):
        mesh = trimesh.Trimesh(vertices, faces)
        assert mesh.is_watertight, t
        radius = np.linalg.norm(vertices - [0.05 * t] * 3, axis=1)
        assert np.abs(np.median(radius) - 1.0) < 0.05, t


def test_running_out_of_memory_is_one_line_that_names_stream(tmp_path, capsys, monkeypatch):
    def exhausted(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr("fourd.methods.reconstruct", exhausted)
    folder = _folder(tmp_path, frames=3)
    assert main(["reconstruct", str(folder), "-o", str(tmp_path / "o.npz"), "-q"]) == 3
    err = capsys.readouterr().err.strip()
    assert err.splitlines() == [err] and "out of memory" in err and "--stream" in err
    assert not (tmp_path / "o.npz").exists()
