from dataclasses import dataclass
from typing import Literal

import pytest

from fourd.errors import InputError
from fourd.options import make_options, parse_assignments


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
