"""The README's table of measured figures is the benchmark's: every cell equals the row of
``benchmarks/BENCHMARKS.json`` it names, so the two cannot drift apart."""

import importlib.util
import json
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _readme_table():
    spec = importlib.util.spec_from_file_location("readme_table", ROOT / "benchmarks" / "readme_table.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_readme_table_is_the_benchmarks():
    readme_table = _readme_table()
    readme = (ROOT / "README.md").read_text()
    report = json.loads((ROOT / "benchmarks" / "BENCHMARKS.json").read_text())
    rows = [line for line in readme.splitlines() if readme_table.ROW.match(line)]
    assert len(rows) >= 20
    assert readme_table.rewrite(readme, report) == readme, (
        "README.md's table differs from benchmarks/BENCHMARKS.json: python benchmarks/readme_table.py")


def test_a_changed_figure_is_caught():
    readme_table = _readme_table()
    readme = (ROOT / "README.md").read_text()
    report = json.loads((ROOT / "benchmarks" / "BENCHMARKS.json").read_text())
    report["scenes"]["crane"]["rows"]["kinematic"]["metrics"]["correspondence_mean"] += 0.001
    assert readme_table.rewrite(readme, report) != readme


def test_the_readme_lists_the_scenes_of_the_synth_registry():
    from fourd.synth.scenes import SCENES

    readme = (ROOT / "README.md").read_text()
    rows = [line for line in readme.splitlines() if line.startswith("| `") and line.count("|") == 3]
    listed = {line.split("`")[1]: line.split("|")[2].strip() for line in rows if line.split("`")[1] in SCENES}
    expected = [f"| `{name}` | {text} |" for name, text in SCENES.items()]
    start = readme.index(expected[0])
    assert readme[start:].startswith("\n".join(expected) + "\n"), (
        "README.md's scene table differs from fourd.synth.scenes.SCENES")
    assert listed == SCENES


def test_the_readme_says_how_long_the_main_commands_take_and_what_they_need():
    readme = " ".join((ROOT / "README.md").read_text().split())
    assert "measured on the 2-core development machine: `make demo` about 1-2 minutes" in readme
    assert "`make test` about 18 minutes (the full CI run, installs included; the slow tests run too)" in readme
    assert "needs the package index" in readme
    browser_tests = "tests/viz/test_viewer_browser.py"
    assert f"Without Chromium, `make test` skips the viewer's browser tests (`{browser_tests}`" in readme
    assert (ROOT / browser_tests).is_file() and "npm ci" in (ROOT / browser_tests).read_text()
