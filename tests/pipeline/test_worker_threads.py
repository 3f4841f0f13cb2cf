"""Thread pools shared between worker processes and this one (fourd.pipeline.worker_threads):
work run here when it is alone gets a worker's BLAS pool, so that it computes what a worker
would have."""

import os

import numpy as np
from threadpoolctl import threadpool_info

from fourd.pipeline.worker_threads import blas_threads_as_workers, threads_per_worker


def _blas_threads() -> list[int]:
    np.dot(np.ones(2), np.ones(2))  # numpy's BLAS loaded
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def test_this_process_gets_a_workers_blas_threads_while_inside(monkeypatch):
    monkeypatch.delenv("OPENBLAS_NUM_THREADS", raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    before = _blas_threads()
    assert before
    with blas_threads_as_workers(8):
        assert set(_blas_threads()) == {1}
        with threads_per_worker(8):
            assert os.environ["OPENBLAS_NUM_THREADS"] == "1"  # what the workers start with
    assert _blas_threads() == before


def test_the_users_blas_threads_are_kept(monkeypatch):
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "3")
    with blas_threads_as_workers(64):
        assert set(_blas_threads()) == {3}
