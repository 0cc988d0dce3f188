"""Processes that share the cores: ``meshcurv batch --jobs N`` gives each worker its share of
numba threads (a user's NUMBA_NUM_THREADS is left as it is)."""

import os

import pytest

from meshcurv import threads
from meshcurv.cli import batch
from meshcurv.cli.batch import WorkerPool


@pytest.fixture
def no_user_threads(monkeypatch):
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)


@pytest.mark.parametrize("cores, jobs, expected", [(2, 1, 2), (2, 2, 1), (2, 4, 1), (8, 3, 2),
                                                   (16, 4, 4)])
def test_threads_per_process_shares_the_cores(monkeypatch, no_user_threads, cores, jobs,
                                              expected):
    monkeypatch.setattr(threads, "available_cores", lambda: cores)
    assert threads.threads_per_process(jobs) == expected


def test_users_numba_num_threads_is_respected(monkeypatch):
    monkeypatch.setattr(threads, "available_cores", lambda: 8)
    assert threads.threads_per_process(4, {"NUMBA_NUM_THREADS": "3"}) == 3
    assert threads.process_environment(2, {"NUMBA_NUM_THREADS": "3"})["NUMBA_NUM_THREADS"] == "3"
    assert threads.process_environment(2, {})["NUMBA_NUM_THREADS"] == "2"
    # unset or empty: the share of the cores
    assert threads.threads_per_process(4, {"NUMBA_NUM_THREADS": ""}) == 2


def _worker_counts(pool, n_tasks):
    """numba's (pool size, threads used) seen by the workers of ``pool``, one per task."""
    return [value for _, value, error in pool.run(
        (k, threads.numba_thread_counts, ()) for k in range(n_tasks)) if error is None]


def test_each_batch_worker_runs_its_share_of_the_threads(no_user_threads):
    n_jobs = 2
    share = max(1, threads.available_cores() // n_jobs)
    with WorkerPool(n_jobs, threads.threads_per_process(n_jobs)) as pool:
        counts = _worker_counts(pool, 2 * n_jobs)
    # the pool itself has only the worker's threads (no idle ones), and kernels use all of them
    assert counts == [(share, share)] * (2 * n_jobs)


def test_batch_worker_keeps_the_users_numba_num_threads(monkeypatch):
    monkeypatch.setenv("NUMBA_NUM_THREADS", "3")
    with WorkerPool(2, threads.threads_per_process(2)) as pool:
        assert _worker_counts(pool, 2) == [(3, 3)] * 2


def test_run_batch_gives_each_job_its_share(monkeypatch, no_user_threads, tmp_path):
    """run_batch sizes its pool from the jobs (not from all cores)."""
    made = []

    class RecordingPool:
        def __init__(self, n_workers, threads=1):
            made.append((n_workers, threads))

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            return False

        def run(self, tasks):
            for key, _, (inp, out, _) in tasks:
                yield key, {"input": inp, "output": out, "status": "ok"}, None

    monkeypatch.setattr(threads, "available_cores", lambda: 4)
    monkeypatch.setattr(batch, "WorkerPool", RecordingPool)
    inputs = []
    for name in ("a.off", "b.off", "c.off"):
        path = tmp_path / name
        path.write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
        inputs.append(str(path))
    results = batch.run_batch(inputs, str(tmp_path / "out"), jobs=2, progress=False)
    assert [r["status"] for r in results] == ["ok"] * 3
    assert made == [(2, 2)]
    assert not os.path.exists(tmp_path / "out" / "a_curvature.ply")  # nothing really ran


# ------------------------------------------------------------------------------ LAS/LAZ writes

def _point_record(point_format, n, seed=0):
    """A laspy record of ``n`` points of ``point_format`` with random raw bytes in every dim."""
    import laspy
    import numpy as np

    header = laspy.LasHeader(point_format=point_format, version="1.4")
    rec = laspy.ScaleAwarePointRecord.zeros(n, header=header)
    raw = np.random.default_rng(seed).integers(0, 256, rec.array.nbytes, dtype=np.uint8)
    rec.array.view(np.uint8)[:] = raw
    return rec, header


@pytest.mark.parametrize("point_format", [0, 1, 3, 6, 8])
def test_block_copy_of_the_input_dims_equals_the_field_by_field_copy(point_format):
    import copy

    import laspy
    import numpy as np

    from meshcurv.io import las

    rec, header = _point_record(point_format, 1000)
    out_header = copy.deepcopy(header)
    out_header.add_extra_dims([laspy.ExtraBytesParams(name="k1", type=np.float64),
                               laspy.ExtraBytesParams(name="valid", type=np.uint8)])
    fast = laspy.ScaleAwarePointRecord.zeros(len(rec), header=out_header)
    slow = laspy.ScaleAwarePointRecord.zeros(len(rec), header=out_header)
    las._copy_input_dims(rec.array, fast.array)
    for name in rec.array.dtype.names:
        slow.array[name] = rec.array[name]
    assert fast.array.tobytes() == slow.array.tobytes()
    # the new dims are left as they were (zero) for the caller to fill
    assert not fast.array["k1"].any() and not fast.array["valid"].any()


def test_block_copy_falls_back_when_the_layouts_differ():
    import numpy as np

    from meshcurv.io import las

    source = np.zeros(3, dtype=[("X", "<i4"), ("Y", "<i4")])
    source["X"], source["Y"] = [1, 2, 3], [4, 5, 6]
    target = np.zeros(3, dtype=[("Y", "<i4"), ("X", "<i4"), ("k1", "<f8")])
    las._copy_input_dims(source, target)
    assert target["X"].tolist() == [1, 2, 3] and target["Y"].tolist() == [4, 5, 6]


# ------------------------------------------------------------------------------ tiled runs

def test_tiled_local_cluster_workers_run_their_share_of_the_threads(no_user_threads):
    from meshcurv.tiled.cluster import dask_client

    share = max(1, threads.available_cores() // 2)
    with dask_client(None, 2) as (client, per_task):
        seen = client.run(threads.numba_thread_counts)
    assert per_task == share
    assert sorted(seen.values()) == [(share, share)] * 2
