"""Dask for tiled runs: connecting to a scheduler or starting a quiet LocalCluster, and running
a stage's tasks with one-line failures."""

import contextlib
import logging
import os
import time

from tqdm.auto import tqdm

from ..io import las
from ..io import first_line
from ..threads import process_environment, threads_per_process
from .tasks import TileError

__all__ = ["connect", "dask_client", "run_jobs"]


@contextlib.contextmanager
def connect(scheduler, timeout="20s"):
    """A ``distributed.Client`` for ``scheduler``: an address (connected here, waiting at most
    ``timeout``, and closed on exit) or an existing Client (used as is).

    Raises OSError "cannot connect to the Dask scheduler <address>: <reason>" (one line).
    """
    if not isinstance(scheduler, str):
        yield scheduler
        return
    from distributed import Client

    try:
        client = Client(scheduler, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as exc:
        raise OSError(f"cannot connect to the Dask scheduler {scheduler}: "
                      f"{first_line(exc)}") from None
    try:
        yield client
    finally:
        client.close()


@contextlib.contextmanager
def dask_client(scheduler, n_workers, threads_per_task=None):
    """(client, numba threads per task): the given Client, one connected to an address, or a
    LocalCluster of ``n_workers`` one-thread processes, closed on exit.

    Threads per task: ``threads_per_task`` if given; for the LocalCluster the cores shared out
    among its workers (:func:`meshcurv.threads.threads_per_process`, which keeps a user's
    ``NUMBA_NUM_THREADS``), also the size of each worker's numba thread pool; else None
    (numba's default, all cores of the worker's machine).
    """
    from distributed import Client

    if threads_per_task is not None and int(threads_per_task) < 1:
        raise ValueError(f"threads_per_task must be at least 1, got {threads_per_task}")
    if scheduler is not None:
        try:
            with _drop_interrupted_sync_error(), connect(scheduler) as client:
                yield client, threads_per_task
        finally:
            _set_distributed_log_level(None)
        return
    n_workers = int(n_workers or min(os.cpu_count() or 1, 8))
    threads = int(threads_per_task or threads_per_process(n_workers))
    # the workers' thread pools sized to their share (the nanny sets it before numba loads)
    env = {k: v for k, v in process_environment(threads).items() if k == "NUMBA_NUM_THREADS"}
    with _drop_interrupted_sync_error():
        with _local_cluster(n_workers, env) as cluster, Client(cluster) as client:
            client.register_plugin(_quiet_worker_plugin())
            yield client, threads


@contextlib.contextmanager
def _local_cluster(n_workers, env):
    """A LocalCluster of ``n_workers`` one-thread worker processes that ignore Ctrl-C, closed on
    exit; if the run inside fails or is interrupted, closed without distributed's warnings."""
    from distributed import LocalCluster

    cluster = None
    try:
        with _workers_ignore_sigint():
            # the scheduler's HTTP server on a free port: with None it still takes 8787 and
            # warns ("Port 8787 is already in use") when another cluster holds it
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                   dashboard_address=":0", env=env)
        yield cluster
    except BaseException:
        # interrupted or failed: the caller reports it in one line; the scheduler and nannies
        # in this process would add warnings about the workers they stop
        _set_distributed_log_level(logging.CRITICAL)
        raise
    finally:
        if cluster is not None:
            try:
                cluster.close()
            finally:
                _set_distributed_log_level(None)


@contextlib.contextmanager
def _workers_ignore_sigint():
    """Ignore SIGINT in this process while a LocalCluster starts its worker processes.

    The workers inherit the ignored signal, so a Ctrl-C in the terminal (sent to the whole
    process group) reaches only the driver, which closes the cluster and reports one line,
    instead of every worker printing a KeyboardInterrupt traceback. A Ctrl-C during these
    seconds of start-up is lost; workers the nanny restarts later (after a crash) ignore it
    through :func:`_quiet_worker_plugin`.
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


class _InterruptedSyncError(logging.Filter):
    """Drops the traceback distributed's event loop logs (through tornado) when a Ctrl-C reaches
    ``distributed.utils.sync`` before its task started: its ``cancel`` callback then reads an
    unassigned variable (NameError). The interrupt itself is reported by the caller in one line."""

    def filter(self, record):
        exc = record.exc_info[1] if record.exc_info else None
        return not (isinstance(exc, NameError) and "sync.<locals>.cancel" in record.getMessage())


@contextlib.contextmanager
def _drop_interrupted_sync_error():
    """Install :class:`_InterruptedSyncError` on tornado's callback logger while a client runs."""
    logger, dropper = logging.getLogger("tornado.application"), _InterruptedSyncError()
    logger.addFilter(dropper)
    try:
        yield
    finally:
        logger.removeFilter(dropper)


def _quiet_worker_plugin():
    """A ``distributed`` WorkerPlugin that runs :func:`_quiet_worker` in every worker process
    of our LocalCluster, those the nanny starts again after a crash included."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class QuietWorker(WorkerPlugin):
        name = "meshcurv-quiet-worker"

        def setup(self, worker):
            _quiet_worker()

    return QuietWorker()


def _quiet_worker():
    """Run in each worker process of our LocalCluster: the driver reports a failed task in one
    line (tile and reason), so the worker's own log of it (a multi-line "Compute Failed" block)
    and its warnings while the cluster shuts down are not printed. A Ctrl-C is for the driver.

    The progress bars' lock is a thread lock: tqdm's default also takes a multiprocessing
    semaphore, which a worker stopped mid-task (Ctrl-C, failed run) leaves registered, and
    Python's resource tracker then warns about it ("leaked semaphore objects") after the
    driver's one-line report.
    """
    import signal
    import threading

    from tqdm import tqdm as tqdm_std

    for name in ("distributed", "distributed.worker"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    tqdm_std.set_lock(threading.RLock())
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


_SAVED_LOG_LEVELS = {}


def _set_distributed_log_level(level):
    """Set the level of distributed's loggers in this process; None restores them."""
    names = ("distributed", "distributed.scheduler", "distributed.nanny", "distributed.worker",
             "distributed.core", "distributed.client", "distributed.deploy.spec")
    for name in names:
        logger = logging.getLogger(name)
        if level is None:
            if name in _SAVED_LOG_LEVELS:
                logger.setLevel(_SAVED_LOG_LEVELS.pop(name))
        else:
            _SAVED_LOG_LEVELS.setdefault(name, logger.level)
            logger.setLevel(level)


def run_jobs(client, jobs, desc, unit, in_path, progress):
    """Submit ``jobs`` ({name: (func, args, kwargs)}) and wait for all.

    The first failure cancels the rest and is raised naming its tile or chunk and the file.
    Returns {name: task result}.
    """
    from distributed import as_completed

    token = f"{os.getpid()}-{time.time_ns()}"
    futures = {client.submit(func, *args, key=f"meshcurv-{desc}-{name}-{token}", pure=False,
                             **kwargs): name
               for name, (func, args, kwargs) in jobs.items()}
    results = {}
    bar = tqdm(total=len(futures), desc=desc, unit=unit, disable=not progress)
    try:
        for fut in as_completed(futures):
            name = futures[fut]
            try:
                results[name] = fut.result()
            except (TileError, las.LasReadError):
                raise
            except Exception as e:  # KilledWorker, CommClosedError, ...: the worker is gone
                raise TileError(f"{unit} {name} of {in_path}: {desc} task failed "
                                f"({type(e).__name__}: {e})") from e
            bar.update(1)
    except BaseException:
        # the caller reports this in one line; the scheduler (in this process for a
        # LocalCluster) logs the keys it can no longer gather once they are cancelled, from
        # its own thread: quiet before cancelling, not after (dask_client restores the level)
        _set_distributed_log_level(logging.CRITICAL)
        client.cancel(list(futures))
        raise
    finally:
        bar.close()
    return results

