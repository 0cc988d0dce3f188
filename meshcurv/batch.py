"""Crash-isolated worker processes for ``meshcurv batch``.

Each file of a batch runs in a worker process, so a file that kills its process (a segmentation
fault, an abort, the out-of-memory killer, ``os._exit``) is that file's failure only: the pool
reports it by name and replaces the dead worker, and the other workers keep their warm state
(imported modules, loaded numba kernels) from file to file.

Workers are plain ``python`` subprocesses talking to the parent over two pipes (no
``multiprocessing`` pool, queue or semaphore, hence no resource-tracker process and no "leaked
semaphore" warnings). They ignore SIGINT (the parent handles Ctrl-C and stops them) and exit when
the parent dies: on Linux through ``prctl(PR_SET_PDEATHSIG, SIGKILL)``, elsewhere (and as a second
line) through end-of-file on their task pipe when idle and a watchdog thread that polls the
parent's pid while they compute.
"""

import collections
import os
import pickle
import signal
import subprocess
import sys
import threading
import time
from multiprocessing.connection import Connection, wait

__all__ = ["WorkerPool", "WorkerStartError", "crash_reason"]

# the worker's own code, run with ``python -c``: the parent's sys.path, so that the worker
# imports the same meshcurv (and any module a task function lives in) as the parent
_BOOTSTRAP = "import sys; sys.path[:] = {path!r}; from meshcurv.batch import _worker_main; " \
             "_worker_main()"

_STOP_SECONDS = 2.0  # grace period for a worker to exit before it is killed


class WorkerStartError(OSError):
    """A worker process died before it was ready (it could not import meshcurv)."""


def crash_reason(returncode):
    """One line for a worker that ended with ``returncode`` (negative: killed by a signal).

    >>> crash_reason(-11)
    'crashed (signal 11, SIGSEGV)'
    >>> crash_reason(3)
    'crashed (the worker process exited with code 3)'
    """
    if returncode is not None and returncode < 0:
        number = -returncode
        try:
            name = signal.Signals(number).name
        except ValueError:
            name = "unknown signal"
        hint = "; out of memory?" if number == getattr(signal, "SIGKILL", None) else ""
        return f"crashed (signal {number}, {name}{hint})"
    return f"crashed (the worker process exited with code {returncode})"


class _Worker:
    """One worker process and its two pipe ends."""

    def __init__(self, threads):
        task_read, task_write = os.pipe()
        result_read, result_write = os.pipe()
        env = dict(os.environ, MESHCURV_WORKER_THREADS=str(threads))
        # SIGINT stays blocked in the child until it has chosen to ignore it: a Ctrl-C during
        # its start-up then can neither kill it with a traceback nor be lost for the parent
        masked = hasattr(signal, "pthread_sigmask")
        if masked:
            old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            self.process = subprocess.Popen(
                [sys.executable, *subprocess._args_from_interpreter_flags(), "-c",
                 _BOOTSTRAP.format(path=list(sys.path)), str(os.getpid())],
                stdin=task_read, stdout=result_write, env=env, close_fds=True)
        except BaseException:
            os.close(task_write)
            os.close(result_read)
            raise
        finally:
            if masked:
                signal.pthread_sigmask(signal.SIG_SETMASK, old)
            os.close(task_read)
            os.close(result_write)
        self.tasks = Connection(task_write, readable=False)
        self.results = Connection(result_read, writable=False)
        self.ready = False     # it has started and imported what it needs
        self.broken = False    # its task pipe is closed: it died while idle
        self.key = None        # the key of the task it is running

    def request_stop(self):
        """End of tasks; a busy worker also gets SIGTERM (it unwinds, removing partial files)."""
        try:
            self.tasks.send(None)
        except OSError:
            pass
        if self.key is not None and self.process.poll() is None:
            self.process.terminate()

    def finish(self, timeout):
        """Wait ``timeout`` seconds for the worker to exit, then kill it; close the pipes."""
        try:
            self.process.wait(max(timeout, 0.0))
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        for conn in (self.tasks, self.results):
            try:
                conn.close()
            except OSError:
                pass


class WorkerPool:
    """``n_workers`` crash-isolated worker processes; use as a context manager.

    ``threads`` is the numba thread count of each worker (share the cores instead of
    oversubscribing them). Leaving the ``with`` block stops every worker, also on an exception
    or KeyboardInterrupt. Workers are started when :meth:`run` needs them and reused from task
    to task; one that dies is replaced.
    """

    def __init__(self, n_workers, threads=1):
        if n_workers < 1:
            raise ValueError(f"n_workers must be at least 1, got {n_workers}")
        self.n_workers = int(n_workers)
        self.threads = max(1, int(threads))
        self._workers = []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        """Stop every worker: all are asked at once, each is killed after a grace period."""
        workers, self._workers = self._workers, []
        for w in workers:
            w.request_stop()
        deadline = time.monotonic() + _STOP_SECONDS
        for w in workers:
            w.finish(deadline - time.monotonic())

    def run(self, tasks):
        """Run ``tasks``, an iterable of ``(key, func, args)``; yield ``(key, value, error)``
        as tasks finish: ``value = func(*args)`` and ``error`` None, or ``value`` None and
        ``error`` a one-line reason (the worker crashed, or ``func`` raised).

        ``func`` must be importable by name in a fresh interpreter (a module-level function;
        it is pickled by reference) and its arguments and result picklable.
        Raises :class:`WorkerStartError` if a worker dies before it is ready.
        """
        pending = collections.deque(tasks)
        while len(self._workers) < min(self.n_workers, len(pending)):
            self._workers.append(_Worker(self.threads))
        while True:
            for w in self._workers:
                while w.key is None and not w.broken and pending:
                    key, func, args = pending.popleft()
                    try:
                        w.tasks.send((key, func, args))
                        w.key = key
                    except OSError:       # it died while idle: not this task's fault
                        pending.appendleft((key, func, args))
                        w.broken = True
                    except Exception as exc:  # the task cannot be pickled
                        yield key, None, f"cannot send the task to a worker: {_one_line(exc)}"
            if not pending and all(w.key is None for w in self._workers):
                return
            for conn in wait([w.results for w in self._workers]):
                w = next(w for w in self._workers if w.results is conn)
                try:
                    message = w.results.recv()
                except (EOFError, OSError, pickle.UnpicklingError):
                    yield from self._replace(w, pending)
                    continue
                if message[0] == "ready":
                    w.ready = True
                    continue
                key, w.key = w.key, None
                yield key, message[1], message[2]

    def _replace(self, w, pending):
        """The worker ``w`` died: report its task, start another if work is left."""
        returncode = w.process.wait()
        w.finish(0)
        self._workers.remove(w)
        if not w.ready:
            raise WorkerStartError(f"a batch worker process could not start ({sys.executable} "
                                   f"{crash_reason(returncode)}; see the messages above)")
        if pending and len(self._workers) < self.n_workers:
            self._workers.append(_Worker(self.threads))
        if w.key is not None:
            yield w.key, None, crash_reason(returncode)


def _one_line(exc):
    text = str(exc).strip()
    return f"{type(exc).__name__}: {text.splitlines()[0]}" if text else type(exc).__name__


# ------------------------------------------------------------------------------ worker side

def _die_with_parent(parent):
    """Exit when the parent process ``parent`` dies (Linux: PR_SET_PDEATHSIG; also a watchdog
    thread for systems without it and for the instant before prctl took effect)."""
    if sys.platform.startswith("linux"):
        try:
            import ctypes

            libc = ctypes.CDLL(None, use_errno=True)
            PR_SET_PDEATHSIG = 1
            libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except Exception:
            pass
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(1)

    def watch():
        while os.getppid() == parent:
            time.sleep(1.0)
        os._exit(1)

    threading.Thread(target=watch, name="meshcurv-parent-watchdog", daemon=True).start()


def _worker_main():
    """Run tasks from the parent until it sends None or closes the pipe."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    _die_with_parent(int(sys.argv[1]))

    def stop(signum, frame):  # SIGTERM: unwind, so atomic writes remove their temporary file
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, stop)
    tasks = Connection(os.dup(0), writable=False)
    results = Connection(os.dup(1), readable=False)
    # stray prints of any library go to stderr, never into the result pipe
    devnull = os.open(os.devnull, os.O_RDONLY)
    os.dup2(devnull, 0)
    os.close(devnull)
    os.dup2(2, 1)
    threads = int(os.environ.get("MESHCURV_WORKER_THREADS", "1"))
    try:
        import numba

        numba.set_num_threads(max(1, min(threads, numba.config.NUMBA_NUM_THREADS)))
    except Exception:
        pass
    results.send(("ready",))
    while True:
        try:
            message = tasks.recv()
        except (EOFError, OSError):  # the parent is gone
            break
        if message is None:
            break
        key, func, args = message
        try:
            value, error = func(*args), None
        except Exception as exc:
            value, error = None, _one_line(exc)
        try:
            results.send(("done", value, error))
        except (TypeError, AttributeError, pickle.PicklingError) as exc:  # unpicklable value
            results.send(("done", None, f"cannot return the result: {_one_line(exc)}"))
