from dataclasses import dataclass
from typing import Literal

import pytest

from fourd.errors import InputError
from fourd.methods import METHODS, method_module
from fourd.options import make_options, option_docs, parse_assignments


@dataclass(frozen=True)
class Example:
    iterations: int = 5
    radius: float | None = None
    mode: Literal["fast", "exact"] = "fast"
    coherent: bool = False
    times: tuple[float, ...] = ()


def test_strings_are_converted_by_field_type():
    options = make_options(
        Example,
        {"iterations": "7", "radius": "0.5", "mode": "exact", "coherent": "true", "times": "0,0.5,1"},
    )
    assert options == Example(7, 0.5, "exact", True, (0.0, 0.5, 1.0))
    assert make_options(Example, {"radius": "none"}).radius is None


def test_unknown_key_lists_valid_keys():
    with pytest.raises(InputError, match="valid keys: coherent, iterations, mode, radius, times"):
        make_options(Example, {"iteration": "3"}, method="demo")


@pytest.mark.parametrize("values", [{"iterations": "x"}, {"mode": "slow"}, {"coherent": "maybe"}])
def test_bad_values(values):
    with pytest.raises(InputError):
        make_options(Example, values)


def test_parse_assignments():
    assert parse_assignments(["a=1", " b = two "]) == {"a": "1", "b": "two"}
    with pytest.raises(InputError, match="key=value"):
        parse_assignments(["novalue"])


@dataclass(frozen=True)
class Documented:
    """Options of a test.

    Attributes
    ----------
    radius : float
        Search radius (``e.g.`` 2 spacings). A second sentence.
    lo, hi : float, int
        Bounds (``lo`` the lower; one entry for two fields).
    window : int
        Frames per fit (0: all; windows of this many frames are fitted one by one, each with
        its own tree, which keeps the memory linear in the frame count and the time too).

    Notes
    -----
    radius : not an option
    """

    radius: float = 1.0
    lo: float = 0.0
    hi: int = 4
    window: int = 0
    hidden: bool = False


def test_option_docs_read_the_attributes_section():
    docs = {d.name: d for d in option_docs(Documented)}
    assert list(docs) == ["radius", "lo", "hi", "window", "hidden"]
    assert (docs["lo"].type, docs["hi"].type, docs["hi"].default) == ("float", "int", 4)
    assert docs["lo"].description == docs["hi"].description
    assert docs["radius"].summary == "Search radius (e.g. 2 spacings)."
    assert docs["radius"].description.endswith("A second sentence.")  # not the Notes section
    assert docs["window"].summary == "Frames per fit (0: ...)."
    assert docs["hidden"].description == ""


@pytest.mark.parametrize("method", list(METHODS))
def test_every_option_of_every_method_is_documented(method):
    missing = [d.name for d in option_docs(method_module(method).Options) if not d.description]
    assert not missing, f"{method}.Options does not describe {missing} in its Attributes section"


def test_a_renamed_option_is_still_accepted_under_its_old_name(caplog):
    from fourd.methods import method_options

    with caplog.at_level("WARNING", logger="fourd.options"):
        options = method_options("perframe", {"normal_k": "8"})
    assert options.normals_k == 8
    assert "normals_k" in caplog.text
    assert method_options("kinematic", {"normal_k": 12}).normals_k == 12
    with pytest.raises(InputError, match="only normals_k"):
        method_options("perframe", {"normal_k": "8", "normals_k": "9"})


def test_methods_agree_on_the_name_of_the_normals_neighbourhood():
    for method in ("perframe", "kinematic"):
        names = {f for f in method_module(method).Options.__dataclass_fields__}
        assert "normals_k" in names and "normal_k" not in names


def test_format_options_shows_an_entry_of_several_fields_once():
    from fourd.options import format_options

    short = format_options(Documented, ("radius", "hi"), method="m")
    assert "  radius = 1.0  (float)\n      Search radius (e.g. 2 spacings). A second sentence." in short
    assert "  lo = 0.0  (float), hi = 4  (int)\n      Bounds" in short  # hi brings its partner
    assert short.count("Bounds") == 1 and "Frames per fit" not in short
    assert short.endswith("2 expert options (fourd options m --all describes them):\n  window, hidden")
    full = format_options(Documented, ("radius",), everything=True, method="m")
    assert full.count("Bounds") == 1 and "expert options:" in full
    assert "each with its own tree, which keeps the memory linear" in " ".join(full.split())
    assert "(undocumented)" in full
    with pytest.raises(ValueError, match="nope"):
        format_options(Documented, ("nope",))
