"""Per-frame stages mapped by a scheduler (fourd.pipeline): in this process, in local
processes, and on a local two-worker dask.distributed cluster on loopback, with the same
result."""

import numpy as np
import pytest

from fourd.errors import InputError
from fourd.pipeline import check_scheduler, map_frames


def _square(x):
    return x * x


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as local:
        yield local.scheduler_address


@pytest.fixture(scope="module")
def scans():
    from fourd import synth

    return synth.scan(synth.scene("squash-ball", frames=4), resolution=64)


def test_every_scheduler_maps_in_order(cluster):
    items = list(range(7))
    expected = [x * x for x in items]
    assert map_frames(_square, items) == expected
    assert map_frames(_square, items, scheduler="processes", workers=2) == expected
    assert map_frames(_square, items, scheduler=cluster) == expected
    assert map_frames(_square, [], scheduler=cluster) == []


def test_the_three_schedulers_mesh_the_same_frames(cluster, scans):
    from fourd.methods import reconstruct

    results = [reconstruct(scans, "perframe", scheduler=s) for s in ("sync", "processes", cluster)]
    for other in results[1:]:
        for (v0, f0), (v1, f1) in zip(results[0].meshes, other.meshes, strict=True):
            assert np.array_equal(f0, f1)
            assert np.allclose(v0, v1, atol=1e-12)
    assert all(len(f) > 100 for _, f in results[0].meshes)


def test_a_bad_scheduler_is_an_input_error_naming_what_is_accepted():
    with pytest.raises(InputError, match="sync, processes"):
        check_scheduler("threads please")
    with pytest.raises(InputError, match="cannot connect"):
        map_frames(_square, [1], scheduler="tcp://127.0.0.1:9")  # nothing listens on port 9
