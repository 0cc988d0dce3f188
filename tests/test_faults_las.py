"""LAS/LAZ and tiled runs under faults: LAS 1.0 inputs, annotated inputs refused before any work,
``info`` of annotated LAS/LAZ, Ctrl-C and failing tiles in one line."""

import glob
import os
import shutil
import signal

import laspy
import numpy as np
import pytest

import meshcurv
from meshcurv import cli
from meshcurv.io import las

VIEWPOINT = (20.0, 20.0, 500.0)


def _cloud(n, seed=0):
    """(n, 3) points of a wavy height field over a 40 x 40 square, random order."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, 40.0, (n, 2))
    return np.column_stack([xy, 2.0 * np.sin(xy[:, 0] / 6.0) * np.cos(xy[:, 1] / 7.0)])


def write_las10(path, xyz, point_format=1, as_10=True):
    """A LAS 1.0 file: laspy writes 1.1 and later only, so write 1.2 and set the version's
    minor byte (offset 25 of the header; formats 0 and 1 and the header layout are those of
    1.0). ``as_10=False`` leaves it 1.2. Returns the stored (n, 3) coordinates."""
    rng = np.random.default_rng(1)
    header = laspy.LasHeader(point_format=point_format, version="1.2")
    header.scales, header.offsets = [1e-4] * 3, [500.0, 800.0, 0.0]
    data = laspy.LasData(header)
    data.x, data.y, data.z = xyz[:, 0] + 500.0, xyz[:, 1] + 800.0, xyz[:, 2]
    data.intensity = rng.integers(0, 65535, len(xyz)).astype(np.uint16)
    data.classification = rng.integers(0, 20, len(xyz)).astype(np.uint8)
    if point_format == 1:
        data.gps_time = rng.uniform(0.0, 1e5, len(xyz))
    data.write(path)
    if as_10:
        with open(path, "r+b") as fh:
            fh.seek(24)
            assert fh.read(2) == b"\x01\x02"
            fh.seek(25)
            fh.write(b"\x00")
    src = laspy.read(path)
    assert str(src.header.version) == ("1.0" if as_10 else "1.2")
    return np.asarray(src.xyz, dtype=np.float64)


@pytest.fixture(scope="module")
def las10(tmp_path_factory):
    path = str(tmp_path_factory.mktemp("las10") / "old.las")
    return path, write_las10(path, _cloud(3000))


def _assert_copy_of(src_path, out_path, version="1.2"):
    src, got = laspy.read(src_path), laspy.read(out_path)
    assert str(got.header.version) == version
    assert got.header.point_format.id == src.header.point_format.id
    for name in src.point_format.dimension_names:  # every input dimension, bit for bit
        np.testing.assert_array_equal(np.asarray(src[name]), np.asarray(got[name]), err_msg=name)
    np.testing.assert_array_equal(src.header.scales, got.header.scales)
    np.testing.assert_array_equal(src.header.offsets, got.header.offsets)
    return got


# ----------------------------------------------------------------------------- LAS 1.0 input

@pytest.mark.parametrize("point_format", [0, 1])
def test_las10_input_is_written_as_las12_with_every_dimension(tmp_path, point_format):
    path = str(tmp_path / "old.las")
    xyz = write_las10(path, _cloud(2000), point_format)
    assert las.output_version(path) == ("1.0", "1.2")
    res = meshcurv.principal_curvatures(xyz, radius=2.0, orientation=VIEWPOINT)
    for suffix in (".las", ".laz"):
        out = str(tmp_path / f"annotated{suffix}")
        las.write_las_curvature(path, out, res)
        got = _assert_copy_of(path, out)
        np.testing.assert_array_equal(np.asarray(got["k1"]), res.k1)
        np.testing.assert_array_equal(np.asarray(got["NormalZ"]), res.normals[:, 2])
    assert sorted(os.listdir(tmp_path)) == ["annotated.las", "annotated.laz", "old.las"]


def test_las10_input_through_the_cli_says_so_in_one_line_and_succeeds(las10, tmp_path, capsys):
    path, xyz = las10
    out = str(tmp_path / "out.laz")
    assert cli.main(["annotate", path, "-o", out, "--radius", "2",
                     "--viewpoint", *map(str, VIEWPOINT)]) == 0
    err = [ln for ln in capsys.readouterr().err.splitlines() if "compiling" not in ln]
    assert err == [f"meshcurv: note: {path} is LAS 1.0, which laspy cannot write; {out} will "
                   "be LAS 1.2 with the same point format and dimensions"]
    got = _assert_copy_of(path, out)
    res = meshcurv.principal_curvatures(xyz, radius=2.0, orientation=VIEWPOINT)
    np.testing.assert_array_equal(np.asarray(got["k2"]), res.k2)


def test_las10_input_of_a_tiled_run_is_written_as_las12(las10, tmp_path, capsys):
    path, xyz = las10
    out = str(tmp_path / "out.las")
    assert cli.main(["annotate", path, "-o", out, "--radius", "2", "--tile-size", "20",
                     "--viewpoint", *map(str, VIEWPOINT)]) == 0
    assert "will be LAS 1.2" in capsys.readouterr().err
    got = _assert_copy_of(path, out)
    # tiles estimate at the one radius their halo covers (no sparse retries, no MLS blend)
    res = meshcurv.principal_curvatures(xyz, radius=2.0, orientation=VIEWPOINT,
                                        sparse_retry=False, coarse_fit="circles")
    np.testing.assert_array_equal(np.asarray(got["k1"]), res.k1)
    assert sorted(os.listdir(tmp_path)) == ["out.las"]  # no work folder left


# ----------------------------------------------------------------------------- annotated input

@pytest.fixture(scope="module")
def annotated(tmp_path_factory):
    """An annotated LAZ (k1 .. d2z and NormalX.. as extra bytes) and its curvature result."""
    folder = tmp_path_factory.mktemp("annotated")
    path, out = str(folder / "scan.las"), str(folder / "scan_curv.laz")
    xyz = write_las10(path, _cloud(3000, seed=3), as_10=False)
    res = meshcurv.principal_curvatures(xyz, radius=2.0, orientation=VIEWPOINT)
    las.write_las_curvature(path, out, res)
    return out, res


def _no_computation(*args, **kwargs):
    raise AssertionError("the curvature was computed before the input was refused")


def test_annotated_laz_is_refused_before_computing(annotated, tmp_path, capsys, monkeypatch):
    path, _ = annotated
    out = str(tmp_path / "twice.laz")
    monkeypatch.setattr(meshcurv.api, "principal_curvatures", _no_computation)
    assert cli.main(["annotate", path, "-o", out, "--radius", "2"]) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if "compiling" not in ln]
    more = len(meshcurv.result.CURVATURE_FIELDS) - 3
    assert err == [f"meshcurv: error: {path} already has dimension(s) k1, k2, mean and {more} more "
                   "(an annotated file?); annotate the original file"]
    assert os.listdir(tmp_path) == []
    # to PLY the annotated LAZ is an ordinary input
    monkeypatch.undo()
    assert cli.main(["annotate", path, "-o", str(tmp_path / "again.ply"), "--radius", "2"]) == 0


def test_annotated_laz_is_refused_by_a_tiled_run_before_the_cluster_starts(annotated, tmp_path,
                                                                          capsys, monkeypatch):
    import meshcurv.tiled as tiled
    from meshcurv.tiled import run

    path, _ = annotated
    out = str(tmp_path / "twice.laz")
    monkeypatch.setattr(run, "dask_client", _no_computation)
    with pytest.raises(ValueError, match="already has dimension"):
        tiled.annotate_tiled(path, out, 2.0, 20.0)
    assert cli.main(["annotate", path, "-o", out, "--radius", "2", "--tile-size", "20"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"meshcurv: error: {path} already has dimension")
    assert os.listdir(tmp_path) == []  # no work folder, no output


# ----------------------------------------------------------------------------- info

def test_info_of_an_annotated_laz_reports_its_fields(annotated, capsys):
    path, res = annotated
    assert cli.main(["info", path]) == 0
    text = capsys.readouterr().out
    assert "not annotated" not in text
    assert f"valid: {int(res.valid.sum())} of {len(res)}" in text
    line = next(ln for ln in text.splitlines() if ln.startswith("k1 "))
    assert float(line.split()[-1]) == pytest.approx(np.nanmean(res.k1[res.valid]), rel=1e-4)
    data = meshcurv.io.read(path)
    np.testing.assert_array_equal(data.fields["k2"], res.k2)
    assert data.fields["valid"].dtype == np.uint8


def test_info_of_a_plain_las_still_says_not_annotated(las10, capsys):
    path, _ = las10
    assert cli.main(["info", path]) == 0
    assert "not annotated" in capsys.readouterr().out


# ----------------------------------------------------------------------------- tiled runs: noise

def _tiled_las(path, n, side, seed=0):
    """A point format 1 LAS 1.2 file of a wavy height field (see tests/test_tiled.py)."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, side, (n, 2))
    z = 0.04 * side * np.sin(6.0 * xy[:, 0] / side) * np.cos(5.0 * xy[:, 1] / side)
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales, header.offsets = [1e-4] * 3, [0.0] * 3
    data = laspy.LasData(header)
    data.x, data.y, data.z = xy[:, 0], xy[:, 1], z
    data.write(path)


def _meshcurv(*args, **popen):
    import subprocess
    import sys

    return subprocess.Popen([sys.executable, "-m", "meshcurv", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, **popen)


def _stderr_lines(text):
    return [ln for ln in text.splitlines() if ln.strip() and "compiling the numba" not in ln]


@pytest.fixture
def dashboard_port_taken():
    """Port 8787 (Dask's default dashboard) held, as by another cluster on the machine."""
    import socket

    sock = socket.socket()
    try:
        sock.bind(("", 8787))
        sock.listen()
    except OSError:
        pass  # already taken by someone else: the same situation
    yield
    sock.close()


def test_failing_tile_task_is_one_line_naming_the_tile(tmp_path, dashboard_port_taken):
    from meshcurv.tiled import annotate_tiled

    src, out = str(tmp_path / "scan.las"), str(tmp_path / "scan_curv.las")
    _tiled_las(src, 8000, 80.0)
    work = out + ".meshcurv-work"
    # the work folder of a finished run, as the CLI makes it (same options), kept
    annotate_tiled(src, out, 2.0, 20.0, n_workers=2, progress=False, keep_work=True,
                   n_directions=8, neighborhood="auto", orientation="+z")
    os.remove(out)
    broken = "t_1_2"
    shutil.rmtree(os.path.join(work, "results", broken))
    for name in os.listdir(os.path.join(work, "normals")):
        if name.startswith(broken + "."):
            os.remove(os.path.join(work, "normals", name))
    for piece in glob.glob(os.path.join(work, "pieces", broken, "*.npz")):
        with open(piece, "wb") as fh:
            fh.write(b"not an npz file")
    proc = _meshcurv("annotate", src, "-o", out, "--radius", "2", "--tile-size", "20")
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 1
    lines = _stderr_lines(err)
    assert len(lines) == 1, err  # the worker's "Compute Failed" block is not printed
    assert lines[0].startswith(f"meshcurv: error: tile {broken} of {src}")
    assert lines[0].endswith(f"(finished tiles are kept in {out}.meshcurv-work; re-run to "
                             "resume)")
    assert not os.path.exists(out)


@pytest.mark.skipif(signal.getsignal(signal.SIGINT) is signal.SIG_IGN,
                    reason="SIGINT is ignored in this session")
def test_ctrl_c_of_a_tiled_run_is_one_line_exit_130_and_no_process_left(tmp_path):
    import signal
    import time

    src, out = str(tmp_path / "big.las"), str(tmp_path / "big_curv.las")
    _tiled_las(src, 200_000, 450.0, seed=1)
    work = out + ".meshcurv-work"
    proc = _meshcurv("annotate", src, "-o", out, "--radius", "3.1", "--tile-size", "60",
                     start_new_session=True)
    try:
        deadline = time.monotonic() + 60
        # the work folder is made once the cluster is up; interrupt a little later, mid-run
        while not os.path.isdir(os.path.join(work, "chunks")) and proc.poll() is None:
            assert time.monotonic() < deadline, "the tiled run did not start"
            time.sleep(0.1)
        time.sleep(1.0)
        assert proc.poll() is None, "the run ended before the interrupt"
        os.killpg(proc.pid, signal.SIGINT)  # as a terminal does: the whole process group
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    assert proc.returncode == 130
    assert _stderr_lines(err) == [f"meshcurv: interrupted; finished tiles are kept in {work}, "
                                  "re-run to resume"]
    assert not os.path.exists(out) and os.path.isdir(work)
    # the cluster's workers went with it (they share the process group)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            os.killpg(proc.pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.2)
    else:
        import subprocess
        left = subprocess.run(["ps", "-o", "pid,etime,cmd", "-g", str(proc.pid)],
                              capture_output=True, text=True).stdout
        raise AssertionError(f"processes left in the run's group:\n{left}")


def test_tiled_run_of_a_quantized_georeferenced_cloud_equals_the_untiled_run_bit_for_bit():
    """LAS coordinates are multiples of the scale, so many points have z exactly 0: on a wall of
    the neighbor grid. Cells counted from the cloud's corner binned them by the rounding of
    z - (the first wall), which differed between a tile and the whole cloud (1 % of 200k points
    off by up to 8e-15 in curvature); cells counted from 0 bin them alike, so tiles equal the
    untiled run bit for bit, as the README says.
    """
    from meshcurv.tiled import principal_curvatures_tiled

    rng = np.random.default_rng(5)
    n, side = 60_000, 250.0
    xy = rng.uniform(0.0, side, (n, 2))
    z = 0.04 * side * np.sin(6.0 * xy[:, 0] / side) * np.cos(5.0 * xy[:, 1] / side)
    pts = np.round(np.column_stack([xy + (5e5, 4e6), z]) / 0.01) * 0.01  # UTM, 1 cm steps
    assert (pts[:, 2] == 0.0).sum() > 100
    radius = float(np.sqrt(30 / (np.pi * n / side**2)))
    viewpoint = (5e5 + side / 2, 4e6 + side / 2, 10 * side)
    tiled = principal_curvatures_tiled(pts, radius, side / 4 * 1.0001, orientation=viewpoint,
                                       n_workers=2, threads_per_task=1)
    untiled = meshcurv.principal_curvatures(pts, radius=radius, orientation=viewpoint,
                                            sparse_retry=False,    # as the tiles do
                                            coarse_fit="circles")
    for name in ("k1", "k2", "d1", "d2", "normals", "valid", "n_neighbors", "n_samples",
                 "residual", "noise"):
        np.testing.assert_array_equal(getattr(tiled, name), getattr(untiled, name), err_msg=name)

@pytest.mark.skipif(signal.getsignal(signal.SIGINT) is signal.SIG_IGN,
                    reason="SIGINT is ignored in this session")
def test_ctrl_c_before_a_dask_call_starts_logs_no_traceback(caplog):
    """distributed's sync() logs a NameError traceback (through tornado) when a Ctrl-C arrives
    before its task started; the tiled run reports the interrupt in one line instead. The
    client's event loop is held busy so the interrupt lands in that window every time."""
    import asyncio
    import threading
    import time

    from meshcurv.tiled.cluster import dask_client

    async def long_task():
        await asyncio.sleep(5)

    interrupted = False
    with dask_client(None, 1) as (client, _):
        try:
            client.loop.add_callback(time.sleep, 0.5)
            threading.Timer(0.1, os.kill, (os.getpid(), signal.SIGINT)).start()
            client.sync(long_task)
        except KeyboardInterrupt:
            interrupted = True
        time.sleep(1.0)  # the loop runs sync()'s cancel callback after its 0.5 s
    assert interrupted
    assert not [r for r in caplog.records if r.name.startswith("tornado")], caplog.text


def test_workers_restarted_after_a_crash_still_leave_ctrl_c_to_the_driver():
    # the nanny starts a crashed worker again: it must ignore SIGINT as the first one did
    from meshcurv.tiled.cluster import dask_client

    def sigint_ignored():
        return signal.getsignal(signal.SIGINT) is signal.SIG_IGN

    with dask_client(None, 1) as (client, _):
        assert all(client.run(sigint_ignored).values())
        client.restart()
        assert all(client.run(sigint_ignored).values())
