import json
from dataclasses import dataclass

import numpy as np

from fourd.jsonable import jsonable


@dataclass(frozen=True)
class Settings:
    radius: float = 0.5
    times: tuple = (0, 1)


def test_numpy_dataclasses_and_non_finite_values_become_plain_json():
    value = {"a": np.arange(3), "b": np.float32(0.25), "c": (np.int64(2), float("nan")), 4: Settings(),
             "d": np.bool_(True), "e": None, "f": object}
    plain = jsonable(value)
    assert json.loads(json.dumps(plain, allow_nan=False)) == {
        "a": [0, 1, 2], "b": 0.25, "c": [2, None], "4": {"radius": 0.5, "times": [0, 1]},
        "d": True, "e": None, "f": "<class 'object'>"}
