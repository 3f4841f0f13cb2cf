"""A closed object reconstructed by the default method in memory, shared by the tests of the
rule (``test_auto.py``) and of the streamed run (``test_auto_stream.py``): one run, not two."""

import pytest

from fourd import synth
from fourd.methods.auto import Options, reconstruct_with_diagnostics
from fourd.metrics import evaluate

#: The options of that run (the fit to the frames has a test of its own).
SQUASH_OPTIONS = Options(resolution=20, fit_frames=False)


@pytest.fixture(scope="session")
def closed_squash():
    """(truth, scans, Reconstruction, its metrics, the options) of squash-ball, four frames."""
    truth = synth.scene("squash-ball", frames=4)
    scans = synth.scan(truth, resolution=96, seed=0)
    memory = reconstruct_with_diagnostics(scans, options=SQUASH_OPTIONS)
    return truth, scans, memory, evaluate(memory.result, truth, samples=10000), SQUASH_OPTIONS
