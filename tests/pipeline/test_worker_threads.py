"""Thread pools shared between worker processes and this one (fourd.pipeline.worker_threads):
work that must come out the same in any process runs with one BLAS thread."""

import numpy as np
from threadpoolctl import threadpool_info

from fourd.pipeline.worker_threads import one_blas_thread


def _blas_threads() -> list[int]:
    np.dot(np.ones(2), np.ones(2))  # numpy's BLAS loaded
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def test_one_blas_thread_while_inside_and_in_what_it_decorates():
    before = _blas_threads()
    assert before
    with one_blas_thread():
        assert set(_blas_threads()) == {1}
    assert _blas_threads() == before

    @one_blas_thread()
    def inside():
        return _blas_threads()

    assert set(inside()) == {1}
    assert set(inside()) == {1}  # each call enters anew
    assert _blas_threads() == before
