"""Spawned worker pools split the cores' OpenMP threads among their workers."""

from __future__ import annotations

import os
from concurrent.futures import wait

import pytest

from odometry.config import variant
from odometry.pipeline import (
    PREFETCH_ENV,
    PREFETCH_SCANS,
    PREFETCH_SCANS_WITHOUT_NORMALS,
    OdometryError,
    default_prefetch,
)
from tools.worker_pool import openmp_threads_per_worker, spawned_pool


def test_threads_per_worker_share_the_cores():
    assert openmp_threads_per_worker(2, cores=2) == 1
    assert openmp_threads_per_worker(1, cores=2) == 2
    assert openmp_threads_per_worker(3, cores=8) == 2
    assert openmp_threads_per_worker(4, cores=2) == 1  # never fewer than one


def test_workers_inherit_their_share_and_the_driver_keeps_its_environment(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    with spawned_pool(2) as pool:
        seen = pool.submit(os.getenv, "OMP_NUM_THREADS").result()
    assert seen == str(openmp_threads_per_worker(2))
    assert "OMP_NUM_THREADS" not in os.environ


def test_workers_with_a_core_each_prepare_no_scans_ahead(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.delenv(PREFETCH_ENV, raising=False)
    for workers in (1, 2):
        with spawned_pool(workers) as pool:
            seen = pool.submit(default_prefetch).result()
        assert seen == (0 if openmp_threads_per_worker(workers) < 2 else PREFETCH_SCANS), workers
        assert PREFETCH_ENV not in os.environ
    monkeypatch.setenv(PREFETCH_ENV, "3")  # the user's choice is kept
    with spawned_pool(2) as pool:
        assert pool.submit(default_prefetch).result() == 3


def test_scans_prepared_ahead_follow_what_a_preparation_holds(monkeypatch):
    """Two ahead where a scan's preparation has its normals and NCF (scan to scan), one where it is a
    voxel grid and poles (the map variants); the environment variable overrides both."""
    monkeypatch.delenv(PREFETCH_ENV, raising=False)
    assert default_prefetch(variant("salo")) == PREFETCH_SCANS == 2
    assert default_prefetch(variant("salo-map")) == PREFETCH_SCANS_WITHOUT_NORMALS == 1
    monkeypatch.setenv(PREFETCH_ENV, "0")
    assert default_prefetch(variant("salo")) == default_prefetch(variant("salo-map")) == 0
    monkeypatch.setenv(PREFETCH_ENV, "1")
    assert default_prefetch(variant("salo")) == default_prefetch(variant("salo-map")) == 1


def test_a_bad_prefetch_setting_names_the_variable(monkeypatch):
    monkeypatch.setenv(PREFETCH_ENV, "two")
    with pytest.raises(OdometryError, match="SALO_PREFETCH_SCANS='two'"):
        default_prefetch()
    monkeypatch.setenv(PREFETCH_ENV, "-1")
    with pytest.raises(OdometryError, match="whole number"):
        default_prefetch()


def test_a_users_thread_count_is_kept(monkeypatch):
    monkeypatch.setenv("OMP_NUM_THREADS", "3")
    with spawned_pool(2) as pool:
        assert pool.submit(os.getenv, "OMP_NUM_THREADS").result() == "3"
    assert os.environ["OMP_NUM_THREADS"] == "3"


def test_an_error_in_the_driver_cancels_the_pending_tasks(monkeypatch):
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    with pytest.raises(KeyboardInterrupt):
        with spawned_pool(1) as pool:
            futures = [pool.submit(os.getenv, "HOME") for _ in range(50)]
            raise KeyboardInterrupt
    wait(futures, timeout=60)  # (the pool's manager thread cancels them after the driver has left)
    assert any(f.cancelled() for f in futures)
    assert "OMP_NUM_THREADS" not in os.environ
