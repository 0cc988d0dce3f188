"""``meshcurv batch``: many files annotated in crash-isolated worker processes, or on Dask.

:func:`run_batch` plans the run (outputs are never inputs, see :func:`_batch_plan`), skips the
files whose output exists and runs the others through :class:`WorkerPool` or a Dask cluster.

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
import contextlib
import functools
import os
import pickle
import signal
import subprocess
import sys
import threading
import time
from multiprocessing.connection import Connection, wait

from .. import io
from ..threads import process_environment, threads_per_process
from .annotate import AnnotateOptions, CommandError, annotate_file

__all__ = ["WorkerPool", "WorkerStartError", "crash_reason", "BatchInterrupted", "run_batch",
           "run_one", "output_path_for", "dask_client", "failure_text"]

# the worker's own code, run with ``python -c``: the parent's sys.path, so that the worker
# imports the same meshcurv (and any module a task function lives in) as the parent
_BOOTSTRAP = ("import sys; sys.path[:] = {path!r}; "
              "from meshcurv.cli.batch import _worker_main; _worker_main()")

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
        # the thread pool itself sized to the worker's share of the cores (numba starts
        # NUMBA_NUM_THREADS threads whatever set_num_threads later asks for)
        env = dict(process_environment(threads), MESHCURV_WORKER_THREADS=str(threads))
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
    oversubscribing them: :func:`meshcurv.threads.threads_per_process`); it is the size of
    the worker's numba thread pool unless the user set ``NUMBA_NUM_THREADS``. Leaving the ``with`` block stops every worker, also on an exception
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
    """``"TypeName: first line of the message"`` (the type name alone when there is none)."""
    text = io.first_line(exc)
    return text if text == type(exc).__name__ else f"{type(exc).__name__}: {text}"


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
        # the parent reports the stop in one line: nothing this worker prints while it unwinds
        # reaches the terminal (a signal landing in a C callback, e.g. while numba compiles,
        # is printed by Python as "Exception ignored ..." and the worker continues until the
        # parent kills it after the grace period)
        quiet = os.open(os.devnull, os.O_WRONLY)
        os.dup2(quiet, 1)
        os.dup2(quiet, 2)
        os.close(quiet)
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


# ------------------------------------------------------------------------------------ batch

def run_one(input_path, output_path, options):
    """Annotate one file; never raises. Returns a dict with ``status`` "ok" or "failed".

    The task both the process pool and Dask workers run: arguments are plain paths and a
    frozen dataclass, so nothing heavy crosses process boundaries.
    """
    try:
        summary = annotate_file(input_path, output_path, options)
        summary["status"] = "ok"
        return summary
    except (ValueError, OSError) as exc:       # io.MeshFileError is a ValueError
        message = io.first_line(exc)
    except Exception as exc:  # a bug, but one bad file must not stop a batch
        message = _one_line(exc)
    return {"input": input_path, "output": output_path, "status": "failed", "error": message}


def _expand_inputs(inputs, out_dir=None):
    """Input paths, each as ``(path, from_folder)``; a directory contributes its readable files
    (not recursive), sorted. In a directory that is ``out_dir`` itself, files named like batch
    outputs (``*_curvature.ply``) are left out: they are outputs of an earlier run."""
    out = []
    for p in inputs:
        if os.path.isdir(p):
            is_out_dir = out_dir is not None and os.path.isdir(out_dir) \
                and os.path.samefile(p, out_dir)
            out.extend((os.path.join(p, f), True) for f in sorted(os.listdir(p))
                       if io.file_extension(f) in io.READERS
                       and os.path.isfile(os.path.join(p, f))
                       and not (is_out_dir and f.lower().endswith(_OUTPUT_SUFFIX + ".ply")))
        else:
            out.append((p, False))
    return out


def _file_id(path):
    """``(device, inode)`` of an existing file (hard links and symlinks share it), else None."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _batch_plan(inputs, out_dir):
    """``(inputs, outputs)`` of a batch, absolute paths, in order.

    Outputs are never inputs: a file found in an input folder that is the output of another
    input of this run (same path after resolving symlinks, or the same file) is left out, and a
    run in which an output would be one of its inputs (named on the command line, or reached
    through a link) is refused with CommandError (exit 2) before anything is written.
    """
    listed = [(os.path.abspath(p), from_folder)
              for p, from_folder in _expand_inputs(inputs, out_dir)]
    targets = [output_path_for(p, out_dir) for p, _ in listed]
    target_names = {os.path.realpath(o) for o in targets}
    target_ids = {i for i in map(_file_id, targets) if i is not None}

    def is_output(path):
        return os.path.realpath(path) in target_names or _file_id(path) in target_ids

    kept = [p for p, from_folder in listed if not (from_folder and is_output(p))]
    if not kept:
        raise CommandError(f"no input files in {' '.join(map(str, inputs))} (readable: "
                           f"{', '.join(sorted(io.READERS))}; outputs of this run are not "
                           "inputs)", 2)
    outputs = [output_path_for(p, out_dir) for p in kept]
    seen = {}
    for i, o in zip(kept, outputs):
        if o in seen:
            raise CommandError(f"{i} and {seen[o]} would both write {o}; rename one", 2)
        seen[o] = i
    input_names = {os.path.realpath(p): p for p in kept}
    input_ids = {_file_id(p): p for p in kept}
    input_ids.pop(None, None)
    for i, o in zip(kept, outputs):
        other = input_names.get(os.path.realpath(o)) or input_ids.get(_file_id(o))
        if other is not None:
            raise CommandError(f"{other} is both an input and the output of {i}; leave it "
                               "out or choose another --out-dir", 2)
    return kept, outputs


_OUTPUT_SUFFIX = "_curvature"


def output_path_for(input_path, out_dir, suffix=_OUTPUT_SUFFIX, extension=".ply"):
    """``out_dir/<stem><suffix>.ply`` for an input file."""
    stem = os.path.splitext(os.path.basename(input_path))[0]
    return os.path.join(out_dir, stem + suffix + extension)


@contextlib.contextmanager
def dask_client(scheduler):
    """:func:`meshcurv.tiled.connect`, with a one-line error when dask.distributed is missing
    (an unreachable scheduler raises its one-line OSError)."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise CommandError("--dask-scheduler needs dask.distributed "
                           "(pip install 'meshcurv[dask]')", 2) from None
    from ..tiled import connect

    with connect(scheduler) as client:
        yield client


class BatchInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a batch: ``done`` of ``total`` files have their output (workers stopped)."""

    def __init__(self, done, total):
        super().__init__(f"{done} of {total} files done")
        self.done, self.total = done, total


def run_batch(inputs, out_dir, options=AnnotateOptions(), jobs=1, overwrite=False,
              scheduler=None, progress=None):
    """Annotate many files; returns a list of per-file result dicts, in input order.

    Each dict has ``input, output, status`` ("ok", "skipped" or "failed") and, for failures,
    ``error``. Outputs that exist are skipped unless ``overwrite`` (writes are atomic, so an
    existing output is complete). Every file runs in a worker process (``jobs`` of them, reused
    from file to file, ``max(1, cores // jobs)`` numba threads each unless the user set
    ``NUMBA_NUM_THREADS``): a file that crashes its process (segmentation fault, out of memory) is
    that file's failure, ``error`` "crashed (signal 11, SIGSEGV)", and the others complete.
    ``scheduler`` (a Dask scheduler address or a ``distributed.Client``) runs the files on a
    Dask cluster whose workers see the same paths: only paths and options travel, never mesh
    data. Outputs are never taken as inputs and never overwrite one (see :func:`_batch_plan`).
    Ctrl-C raises :class:`BatchInterrupted` once the workers are stopped.
    """
    out_dir = os.path.abspath(out_dir)
    inputs, outputs = _batch_plan(inputs, out_dir)
    results = [None] * len(inputs)
    todo = []
    for k, (i, o) in enumerate(zip(inputs, outputs)):
        if os.path.exists(o) and not overwrite:
            results[k] = {"input": i, "output": o, "status": "skipped"}
        else:
            todo.append(k)
    # temporary files of writes killed in an earlier run (outputs that exist are not rewritten)
    io.remove_stale_partials(out_dir, [os.path.basename(o) for o in outputs])
    try:
        if scheduler is not None and todo:
            with dask_client(scheduler) as client:  # connect before creating anything
                _batch_loop(todo, results, out_dir, progress, functools.partial(
                    _batch_dask, client, inputs, outputs, options, todo))
        elif todo:
            _batch_loop(todo, results, out_dir, progress, functools.partial(
                _batch_pool, inputs, outputs, options, todo, jobs=jobs))
    except KeyboardInterrupt:
        done = sum(r is not None and r["status"] in ("ok", "skipped") for r in results)
        raise BatchInterrupted(done, len(inputs)) from None
    return results


def _batch_loop(todo, results, out_dir, progress, run):
    """Create ``out_dir`` and call ``run(record)`` under a progress bar; ``record(k, result)``
    stores file k's result dict in ``results``."""
    from tqdm.auto import tqdm

    os.makedirs(out_dir, exist_ok=True)
    bar = tqdm(total=len(todo), desc="meshcurv batch", unit="file", file=sys.stderr,
               disable=progress is False or (progress is None and not sys.stderr.isatty()))

    def record(k, res):
        results[k] = res
        bar.update(1)
        if res["status"] == "failed":
            bar.write(f"failed: {failure_text(res)}", file=sys.stderr)

    try:
        run(record)
    finally:
        bar.close()


def failure_text(res):
    """``<input>: <reason>`` of a failed file (most reasons already start with the file)."""
    error = res["error"]
    return error if error.startswith(res["input"]) else f"{res['input']}: {error}"


def _worker_failure(k, inputs, outputs, exc):
    return {"input": inputs[k], "output": outputs[k], "status": "failed",
            "error": f"worker failed: {_one_line(exc)}"}


def _batch_pool(inputs, outputs, options, todo, record, jobs=1):
    """The pending files on ``jobs`` crash-isolated worker processes (one for a serial run),
    sharing the cores (``max(1, cores // workers)`` numba threads each, or the user's
    ``NUMBA_NUM_THREADS``); a file whose worker dies is reported failed with the reason."""
    if os.name != "posix":  # the worker pipes are POSIX file descriptors: no isolation here
        for k in todo:
            record(k, run_one(inputs[k], outputs[k], options))
        return
    n_workers = max(1, min(jobs, len(todo)))
    threads = threads_per_process(n_workers)
    task = run_one  # looked up now: the worker imports it by name
    with WorkerPool(n_workers, threads) as pool:
        for k, res, error in pool.run((k, task, (inputs[k], outputs[k], options))
                                      for k in todo):
            if error is not None:
                res = {"input": inputs[k], "output": outputs[k], "status": "failed",
                       "error": error}
            record(k, res)


def _batch_dask(client, inputs, outputs, options, todo, record):
    """The pending files as Dask tasks: file paths travel, data stays on the workers."""
    from distributed import as_completed

    token = time.time_ns()
    futures = {client.submit(run_one, inputs[k], outputs[k], options, pure=False,
                             key=f"meshcurv-{k}-{os.path.basename(inputs[k])}-{token}"): k
               for k in todo}
    try:
        for fut in as_completed(futures):
            k = futures[fut]
            try:
                res = fut.result()
            except Exception as exc:  # KilledWorker, lost connection, ...
                res = _worker_failure(k, inputs, outputs, exc)
            record(k, res)
    except BaseException:
        client.cancel(list(futures))
        raise

