"""Faults of ``meshcurv batch`` (issue 11): a file that crashes its process fails alone, serial
and parallel, and a rerun retries only it; outputs are never inputs and never replace one;
workers die with a killed parent and Ctrl-C stops everything with one line; temporary files of
killed writes are removed by the next write, never those of a live process.

Crashes are produced by :func:`crashing_run_one`, put in place of ``cli.batch.run_one`` in a
batch run in a subprocess: the workers import it by name from this module, so it crashes inside the
worker exactly where a segmentation fault of the estimator would (no test hook in meshcurv)."""

import os
import re
import resource
import signal
import subprocess
import sys
import textwrap
import time

import pytest

from meshcurv import cli, io, surfaces
from meshcurv.cli import batch
from meshcurv.cli.batch import WorkerPool, crash_reason

TESTS = os.path.dirname(os.path.abspath(__file__))
_REAL_RUN_ONE = batch.run_one
COMPILING = "meshcurv: compiling the numba kernels"


def _crash(kind):
    """Kill this process the way ``kind`` says (no core file)."""
    resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
    if kind == "segv":
        os.kill(os.getpid(), signal.SIGSEGV)
    elif kind == "abort":
        os.abort()
    elif kind == "exit":
        os._exit(3)
    elif kind == "oom":  # what the kernel's out-of-memory killer does
        os.kill(os.getpid(), signal.SIGKILL)
    time.sleep(5)


def crashing_run_one(input_path, output_path, options):
    """``cli.batch.run_one``, except that an input named segv/abort/exit/oom.* kills the worker."""
    kind = os.path.splitext(os.path.basename(input_path))[0]
    if kind in ("segv", "abort", "exit", "oom"):
        _crash(kind)
    return _REAL_RUN_ONE(input_path, output_path, options)


def worker_task(x):
    """A pool task: (x, worker pid); a string x names a crash (see :func:`_crash`)."""
    if isinstance(x, str):
        _crash(x)
    if x < 0:
        raise ValueError(f"negative {x}\nsecond line")
    return x, os.getpid()


def run_cli(*argv, crash=False, **popen):
    """``meshcurv`` in a subprocess; with ``crash`` its workers run :func:`crashing_run_one`."""
    code = textwrap.dedent(f"""\
        import sys
        sys.path.insert(0, {TESTS!r})
        from meshcurv import cli
        if {crash!r}:
            import test_faults_batch
            cli.batch.run_one = test_faults_batch.crashing_run_one
        sys.exit(cli.main(sys.argv[1:]))
        """)
    popen = {"stdout": subprocess.PIPE, "stderr": subprocess.PIPE, **popen}
    return subprocess.Popen([sys.executable, "-c", code, *map(str, argv)], text=True, **popen)


def finish(proc, timeout=240):
    out, err = proc.communicate(timeout=timeout)
    lines = [line for line in err.splitlines() if not line.startswith(COMPILING)]
    return proc.returncode, out, lines


def _sphere(path, subdivisions=3):
    s = surfaces.sphere(radius=1.0, subdivisions=subdivisions)
    io.write_ply(str(path), s.vertices, s.faces)


@pytest.fixture
def crash_dir(tmp_path):
    """Three good meshes and two that crash their worker (a segmentation fault, and SIGKILL as
    from the out-of-memory killer); the crashing files are valid meshes as well."""
    d = tmp_path / "in"
    d.mkdir()
    for name in ("a", "b", "c", "segv", "oom"):
        _sphere(d / f"{name}.ply")
    return d


GOOD = ["a_curvature.ply", "b_curvature.ply", "c_curvature.ply"]
REASONS = {"segv": "crashed (signal 11, SIGSEGV)",
           "oom": "crashed (signal 9, SIGKILL; out of memory?)"}


# ------------------------------------------------------------------------------ crashes

@pytest.mark.parametrize("jobs", [1, 2])
def test_a_crashing_file_fails_alone_and_a_rerun_retries_only_it(tmp_path, crash_dir, jobs):
    out = tmp_path / "out"
    code, stdout, err = finish(run_cli("batch", crash_dir, "-O", out, "--jobs", jobs,
                                       crash=True))
    assert code == 1
    assert stdout == f"meshcurv batch: 3 annotated, 0 skipped (output exists), 2 failed, in {out}\n"
    # nothing but the failures: live, then listed at the end (no traceback, no warning)
    failures = [f"{crash_dir / name}.ply: {reason}" for name, reason in sorted(REASONS.items())]
    assert sorted(line for line in err if line.startswith("failed: ")) == \
        ["failed: " + f for f in failures]
    assert [line for line in err if not line.startswith("failed: ")] == \
        ["  FAILED " + f for f in failures]
    assert sorted(os.listdir(out)) == GOOD
    stamps = {f: os.stat(out / f).st_mtime_ns for f in GOOD}

    # a rerun (the cause fixed) skips the finished files and retries only the crashed ones
    code, stdout, err = finish(run_cli("batch", crash_dir, "-O", out, "--jobs", jobs))
    assert (code, err) == (0, [])
    assert "2 annotated, 3 skipped (output exists), 0 failed" in stdout
    assert {f: os.stat(out / f).st_mtime_ns for f in GOOD} == stamps
    assert sorted(os.listdir(out)) == sorted(GOOD + ["oom_curvature.ply", "segv_curvature.ply"])


def test_a_dead_worker_is_replaced_and_the_others_stay_warm():
    tasks = [1, 2, "abort", 3, -4, "exit", 5]
    with WorkerPool(1) as pool:
        done = {k: (value, error) for k, value, error in
                pool.run([(k, worker_task, (x,)) for k, x in enumerate(tasks)])}
    assert done[2] == (None, "crashed (signal 6, SIGABRT)")
    assert done[4] == (None, "ValueError: negative -4")  # an exception is no crash
    assert done[5] == (None, "crashed (the worker process exited with code 3)")
    assert [done[k][0][0] for k in (0, 1, 3, 6)] == [1, 2, 3, 5]
    # one process per stretch between crashes: reused, and only the dead one replaced
    pids = [done[k][0][1] for k in (0, 1, 3, 6)]
    assert pids[0] == pids[1] != pids[2] != pids[3] and pids[0] != pids[3]


def test_two_workers_share_the_tasks_and_a_crash_stops_neither(tmp_path):
    tasks = [1, "segv", 2, 3, "oom", 4, 5, 6]
    with WorkerPool(2) as pool:
        done = {k: (value, error) for k, value, error in
                pool.run([(k, worker_task, (x,)) for k, x in enumerate(tasks)])}
    assert sorted(done) == list(range(len(tasks)))
    assert done[1] == (None, "crashed (signal 11, SIGSEGV)")
    assert done[4] == (None, "crashed (signal 9, SIGKILL; out of memory?)")
    assert sorted(done[k][0][0] for k in (0, 2, 3, 5, 6, 7)) == [1, 2, 3, 4, 5, 6]


def test_crash_reasons_name_the_signal():
    assert crash_reason(-11) == "crashed (signal 11, SIGSEGV)"
    assert crash_reason(-9) == "crashed (signal 9, SIGKILL; out of memory?)"
    assert crash_reason(1) == "crashed (the worker process exited with code 1)"


# ------------------------------------------------------------------- outputs are not inputs

def test_a_batch_into_its_input_folder_never_annotates_its_outputs(tmp_path, capsys):
    d = tmp_path / "scans"
    d.mkdir()
    for name in ("a", "b"):
        _sphere(d / f"{name}.ply", subdivisions=2)
    assert cli.main(["batch", str(d), "-O", str(d)]) == 0
    assert "2 annotated, 0 skipped" in capsys.readouterr().out
    before = {f: (d / f).read_bytes() for f in os.listdir(d)}

    # a rerun: a_curvature.ply is the output of a.ply, not an input
    assert cli.main(["batch", str(d), "-O", str(d)]) == 0
    assert "0 annotated, 2 skipped" in capsys.readouterr().out
    # --overwrite recomputes the two outputs from the two inputs, nothing else
    assert cli.main(["batch", str(d), "-O", str(d), "--overwrite"]) == 0
    assert "2 annotated, 0 skipped" in capsys.readouterr().out
    assert {f: (d / f).read_bytes() for f in os.listdir(d)} == before

    # an output whose input is gone is still an output (the *_curvature.ply rule of OUT_DIR)
    os.remove(d / "a.ply")
    assert cli.main(["batch", str(d), "-O", str(d)]) == 0
    assert "0 annotated, 1 skipped" in capsys.readouterr().out
    assert sorted(os.listdir(d)) == ["a_curvature.ply", "b.ply", "b_curvature.ply"]


def _batch_of_one(tmp_path):
    """``in/a.ply`` annotated by a batch into ``out``; returns the two folders."""
    d = tmp_path / "in"
    d.mkdir()
    _sphere(d / "a.ply", subdivisions=2)
    out = tmp_path / "out"
    assert cli.main(["batch", str(d), "-O", str(out)]) == 0
    return d, out


def test_outputs_of_this_run_in_another_input_folder_are_skipped(tmp_path, capsys):
    d, out = _batch_of_one(tmp_path)
    capsys.readouterr()
    # the out folder given as an input too: its a_curvature.ply is a's output, so skipped
    assert cli.main(["batch", str(d), str(out), "-O", str(out), "--overwrite"]) == 0
    assert "1 annotated, 0 skipped" in capsys.readouterr().out
    assert sorted(os.listdir(out)) == ["a_curvature.ply"]


@pytest.mark.parametrize("how", ["named", "symlink", "hardlink"])
def test_a_run_that_would_overwrite_its_own_input_is_refused(tmp_path, capsys, how):
    d = tmp_path / "in"
    d.mkdir()
    _sphere(d / "a.ply", subdivisions=2)
    _sphere(d / "a_curvature.ply", subdivisions=1)  # an input that is also a's output name
    original = (d / "a_curvature.ply").read_bytes()
    other = d / "a_curvature.ply"
    if how != "named":
        other = tmp_path / "elsewhere.ply"
        (os.symlink if how == "symlink" else os.link)(d / "a_curvature.ply", other)
    code = cli.main(["batch", str(d / "a.ply"), str(other), "-O", str(d), "--overwrite"])
    err = capsys.readouterr().err
    assert code == 2
    assert err == (f"meshcurv: error: {other} is both an input and the output of {d / 'a.ply'}; "
                   "leave it out or choose another --out-dir\n")
    assert (d / "a_curvature.ply").read_bytes() == original
    assert sorted(os.listdir(d)) == ["a.ply", "a_curvature.ply"]


def test_batch_help_says_which_files_are_not_inputs(capsys):
    with pytest.raises(SystemExit):
        cli.main(["batch", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "Outputs are never inputs" in text
    assert "*_curvature.ply when the input folder is OUT_DIR itself" in text


# ------------------------------------------------------------- kill -9, Ctrl-C: no orphans

def _children():
    """{pid: parent pid} of every process, from /proc."""
    table = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if fields[0] != "Z":
                table[int(entry)] = int(fields[1])
    return table


def _descendants(pid):
    table = _children()
    found, frontier = set(), {pid}
    while frontier:
        frontier = {p for p, parent in table.items() if parent in frontier} - found
        found |= frontier
    return found


def _alive(pids):
    table = _children()
    return sorted(p for p in pids if p in table)


def _wait_for_workers(proc, n, timeout=60):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert proc.poll() is None, "the batch ended before its workers were seen"
        workers = _descendants(proc.pid)
        if len(workers) >= n:
            return workers
        time.sleep(0.1)
    raise AssertionError(f"no {n} workers after {timeout} s")


@pytest.fixture
def busy_dir(tmp_path):
    """Four meshes of 120k vertices: a few seconds of numba kernels each on one thread."""
    d = tmp_path / "big"
    d.mkdir()
    t = surfaces.torus(major=2.0, minor=0.5, n_major=600, n_minor=200)
    io.write_ply(str(d / "t0.ply"), t.vertices, t.faces)
    for k in (1, 2, 3):
        (d / f"t{k}.ply").write_bytes((d / "t0.ply").read_bytes())
    return d


def _kill_leftovers(pids):
    for p in _alive(pids):
        try:
            os.kill(p, signal.SIGKILL)
        except OSError:
            pass


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc")
def test_workers_die_with_a_killed_parallel_batch(tmp_path, busy_dir):
    # no pipes: orphans would hold them open
    proc = run_cli("batch", busy_dir, "-O", tmp_path / "out", "--jobs", 2,
                   start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    workers = set()
    try:
        workers = _wait_for_workers(proc, 2)
        time.sleep(2.0)  # the workers are computing now
        workers |= _descendants(proc.pid)
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        deadline = time.monotonic() + 5
        while _alive(workers) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _alive(workers) == []
    finally:
        _kill_leftovers(workers)


# a background job of a shell without job control starts with SIGINT ignored, and so does
# every program it runs: there a Ctrl-C reaches nobody, the CLI included
SIGINT_IGNORED = signal.getsignal(signal.SIGINT) is signal.SIG_IGN


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="needs /proc")
@pytest.mark.skipif(SIGINT_IGNORED, reason="SIGINT is ignored in this session")
@pytest.mark.parametrize("jobs", [1, 2])
def test_ctrl_c_stops_the_batch_with_one_line(tmp_path, busy_dir, jobs):
    out = tmp_path / "out"
    proc = run_cli("batch", busy_dir, "-O", out, "--jobs", jobs, start_new_session=True)
    workers = set()
    try:
        workers = _wait_for_workers(proc, jobs)
        time.sleep(2.0)
        workers |= _descendants(proc.pid)
        os.killpg(proc.pid, signal.SIGINT)  # a terminal's Ctrl-C: the whole process group
        code, stdout, err = finish(proc, timeout=60)
        assert code == 130
        assert stdout == ""
        assert len(err) == 1 and re.fullmatch(
            r"meshcurv: interrupted; [0-4] of 4 files done, rerun to resume", err[0]), err
        assert _alive(workers) == []
        assert not [f for f in os.listdir(out) if f.endswith(".part")] if out.exists() else True
    finally:
        _kill_leftovers(workers)


# --------------------------------------------------------------- temporary files of writes

def _dead_pid():
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_a_write_removes_the_temporary_files_of_killed_writers_only(tmp_path):
    target = tmp_path / "x.ply"
    host = io.atomic.host_tag()
    dead = tmp_path / f".x.ply.{host}.{_dead_pid()}.abcd1234.part"
    live = tmp_path / f".x.ply.{host}.{os.getppid()}.abcd1234.part"
    other_host = tmp_path / f".x.ply.{host}-other.{_dead_pid()}.abcd1234.part"
    other_target = tmp_path / f".y.ply.{host}.{_dead_pid()}.abcd1234.part"
    for f in (dead, live, other_host, other_target):
        f.write_bytes(b"partial")
    io.atomic_write(str(target), lambda tmp: open(tmp, "wb").write(b"done"))
    assert target.read_bytes() == b"done"
    assert sorted(os.listdir(tmp_path)) == sorted(
        f.name for f in (target, live, other_host, other_target))


def test_a_write_killed_by_sigkill_is_cleaned_by_the_next_write(tmp_path):
    target = tmp_path / "x.ply"
    writer = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""\
        import time
        from meshcurv import io
        def slow(tmp):
            open(tmp, "wb").write(b"half")
            print("writing", flush=True)
            time.sleep(60)
        io.atomic_write({str(target)!r}, slow)
        """)], stdout=subprocess.PIPE, text=True)
    try:
        assert writer.stdout.readline() == "writing\n"
        partial = [f for f in os.listdir(tmp_path) if f.endswith(".part")]
        assert len(partial) == 1 and f".{writer.pid}." in partial[0]
        # a concurrent write of the same target leaves the live writer's file alone
        io.atomic_write(str(target), lambda tmp: open(tmp, "wb").write(b"first"))
        assert sorted(os.listdir(tmp_path)) == sorted(["x.ply", *partial])
        writer.kill()
        writer.wait()
        io.atomic_write(str(target), lambda tmp: open(tmp, "wb").write(b"second"))
        assert os.listdir(tmp_path) == ["x.ply"] and target.read_bytes() == b"second"
    finally:
        writer.kill()
        writer.wait()


def test_a_batch_rerun_removes_stale_temporary_files_of_skipped_outputs(tmp_path, capsys):
    d, out = _batch_of_one(tmp_path)
    # an --overwrite run killed while rewriting a_curvature.ply left its temporary file
    stale = out / f".a_curvature.ply.{io.atomic.host_tag()}.{_dead_pid()}.k3j9x2q1.part"
    stale.write_bytes(b"partial")
    assert cli.main(["batch", str(d), "-O", str(out)]) == 0
    assert "0 annotated, 1 skipped" in capsys.readouterr().out
    assert os.listdir(out) == ["a_curvature.ply"]
