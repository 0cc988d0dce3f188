"""Numba threads of the processes of a parallel run: how many each one gets.

Several processes on one machine (``meshcurv batch --jobs N``, the workers of a tiled run's
LocalCluster) share its cores: each gets ``max(1, cores // N)`` numba threads, set through
``NUMBA_NUM_THREADS`` in its environment so that its thread pool has no idle threads beyond
them. A user's own ``NUMBA_NUM_THREADS`` is numba's per-process thread count and is left as it
is.

This module imports nothing heavy: the command line uses it before numba is loaded.
"""

import os

__all__ = ["available_cores", "threads_per_process", "process_environment",
           "numba_thread_counts"]


def available_cores():
    """Cores this process may run on (its CPU affinity where the system reports one), >= 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):
        return max(1, os.cpu_count() or 1)


def threads_per_process(n_processes, environ=None):
    """Numba threads of each of ``n_processes`` processes sharing this machine (int >= 1).

    The user's ``NUMBA_NUM_THREADS`` (in ``environ``, default ``os.environ``) when it is set to
    a positive integer, else the cores shared out: ``max(1, cores // n_processes)``.

    >>> threads_per_process(2, {"NUMBA_NUM_THREADS": "3"})
    3
    """
    environ = os.environ if environ is None else environ
    own = _user_threads(environ)
    if own is not None:
        return own
    return max(1, available_cores() // max(1, int(n_processes)))


def process_environment(threads, environ=None):
    """The environment of a child process that is to run ``threads`` numba threads: a copy of
    ``environ`` (default ``os.environ``) with ``NUMBA_NUM_THREADS=threads``, unless the user
    set ``NUMBA_NUM_THREADS`` there (then it is passed on unchanged, even a value numba
    refuses: numba's own message is the clearer one).

    >>> process_environment(1, {})["NUMBA_NUM_THREADS"]
    '1'
    """
    env = dict(os.environ if environ is None else environ)
    if not env.get("NUMBA_NUM_THREADS", "").strip():
        env["NUMBA_NUM_THREADS"] = str(max(1, int(threads)))
    return env


def numba_thread_counts():
    """``(pool, used)`` of this process: numba's thread-pool size (``NUMBA_NUM_THREADS``) and
    the threads its parallel kernels use now (``numba.get_num_threads()``)."""
    import numba

    return int(numba.config.NUMBA_NUM_THREADS), int(numba.get_num_threads())


def _user_threads(environ):
    """The positive int of ``NUMBA_NUM_THREADS`` in ``environ``, or None (unset or invalid:
    numba itself refuses an invalid value with its own message)."""
    value = environ.get("NUMBA_NUM_THREADS", "").strip()
    try:
        number = int(value)
    except ValueError:
        return None
    return number if number >= 1 else None
