"""The machine a bench run was made on."""

from __future__ import annotations

from fourd.bench.machine import machine_info


def test_machine_info_names_the_machine():
    info = machine_info()
    assert info["cores"] >= 1 and info["cpu"] and info["date"].endswith("UTC")
