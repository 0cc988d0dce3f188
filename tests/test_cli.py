"""The ``meshcurv`` command: annotate writes what the API computes, bad input fails in one line
with no output, batch goes on past bad files and resumes, Dask runs give the same files, and the
LAS/LAZ tiling flags reach :func:`meshcurv.tiled.annotate_tiled`."""

import os
import subprocess
import sys

import numpy as np
import pytest
from plyfile import PlyData

import meshcurv
from meshcurv import cli, io, shape, surfaces

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope="module")
def torus():
    return surfaces.torus(major=2.0, minor=0.5, n_major=96, n_minor=32)


@pytest.fixture(scope="module")
def inputs(tmp_path_factory, torus):
    """A mesh (PLY), a small mesh (OBJ) and a point cloud with normals (XYZ)."""
    d = tmp_path_factory.mktemp("inputs")
    io.write_ply(str(d / "torus.ply"), torus.vertices, torus.faces)
    sphere = surfaces.sphere(radius=1.5, subdivisions=4)
    with open(d / "sphere.obj", "w") as fh:
        fh.writelines(f"v {x:.17g} {y:.17g} {z:.17g}\n" for x, y, z in sphere.vertices)
        fh.writelines(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in sphere.faces)
    cloud = surfaces.sphere(radius=2.0, sampling="random", n=1500, seed=5)
    np.savetxt(d / "cloud.xyz", np.column_stack([cloud.vertices, cloud.normals]), fmt="%.17g")
    return d


@pytest.fixture(scope="module")
def dask_cluster():
    """An in-process Dask cluster: one worker thread, no subprocesses, no dashboard."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=":0") as cluster:
        yield cluster


def run(capsys, *argv):
    """Run the command in-process; returns (exit code, stdout, stderr)."""
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _bits(a):
    return np.ascontiguousarray(a, dtype="<f8").tobytes()


# ----------------------------------------------------------------------------------- annotate

def test_annotate_writes_the_api_arrays_bit_for_bit(tmp_path, capsys, inputs, torus):
    out = tmp_path / "torus_curvature.ply"
    code, stdout, err = run(capsys, "annotate", inputs / "torus.ply", "-o", out,
                            "--radius", "0.45", "--quality", "shape_index")
    assert code == 0, err
    assert "radius 0.45" in stdout and "3072 of 3072" in stdout
    res = meshcurv.principal_curvatures(torus.vertices, torus.faces, radius=0.45)
    ply = PlyData.read(str(out))
    assert not ply.text
    v = ply["vertex"].data
    for name in shape.FIELDS:
        assert _bits(v["scalar_" + name]) == _bits(getattr(res, name)), name
    for i, c in enumerate("xyz"):
        assert _bits(v["scalar_d1" + c]) == _bits(res.d1[:, i])
        assert _bits(v["scalar_d2" + c]) == _bits(res.d2[:, i])
    assert _bits(v["quality"]) == _bits(np.where(res.valid, res.shape_index, 0.0))
    np.testing.assert_array_equal(np.stack(ply["face"].data["vertex_indices"]), torus.faces)


def test_annotate_point_cloud_takes_percent_radius_and_file_normals(tmp_path, capsys, inputs):
    data = io.read(str(inputs / "cloud.xyz"))
    out = tmp_path / "cloud.ply"
    code, _, err = run(capsys, "annotate", inputs / "cloud.xyz", "-o", out, "--radius", "12%")
    assert code == 0, err
    radius = 12.0 / 100.0 * io.bbox_diagonal(data.vertices)
    res = meshcurv.principal_curvatures(data.vertices, normals=data.normals, radius=radius)
    back = io.read(str(out))
    assert back.is_point_cloud
    np.testing.assert_array_equal(back.vertices, data.vertices)
    for name in shape.FIELDS:
        assert _bits(back.fields[name]) == _bits(getattr(res, name)), name
    # the file's outward normals fix the sign: a sphere of radius 2 is convex, k ~ +0.5
    assert np.nanmedian(back.fields["k2"]) == pytest.approx(0.5, rel=0.05)


def test_viewpoint_orients_estimated_cloud_normals(tmp_path, capsys, inputs):
    """--viewpoint at the sphere's centre turns the estimated normals inward: k ~ -0.5."""
    data = io.read(str(inputs / "cloud.xyz"))
    centre = data.vertices.mean(axis=0)
    out = tmp_path / "cloud_inward.ply"
    code, _, err = run(capsys, "annotate", inputs / "cloud.xyz", "-o", out, "--radius", "12%",
                       "--normals", "estimate", "--viewpoint", *map(str, centre))
    assert code == 0, err
    radius = 12.0 / 100.0 * io.bbox_diagonal(data.vertices)
    res = meshcurv.principal_curvatures(data.vertices, radius=radius,
                                        orientation=tuple(float(c) for c in map(str, centre)))
    back = io.read(str(out))
    assert _bits(back.fields["k1"]) == _bits(res.k1)
    assert np.nanmedian(back.fields["k1"]) == pytest.approx(-0.5, rel=0.05)


def test_readme_command_writes_ply_and_png_and_creates_the_directory(tmp_path, capsys):
    out = tmp_path / "out" / "torus_curvature.ply"
    png = tmp_path / "out" / "torus_shape_index.png"
    code, stdout, err = run(capsys, "annotate", os.path.join(ROOT, "examples", "torus.ply"),
                            "-o", out, "--preview", png)
    assert code == 0, err
    assert PlyData.read(str(out))["vertex"].count > 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(os.listdir(out.parent)) == ["torus_curvature.ply", "torus_shape_index.png"]
    code, stdout, _ = run(capsys, "info", out)
    assert code == 0 and "valid:" in stdout and "shape_index" in stdout


@pytest.mark.parametrize("warm", [False, True])
def test_first_run_says_it_compiles(tmp_path, capsys, inputs, monkeypatch, warm):
    """A cold numba cache (first run after installing) is announced on stderr, once per run."""
    from meshcurv.fit import fused

    assert isinstance(fused.cache_is_warm(), bool)
    monkeypatch.setattr(fused, "cache_is_warm", lambda: warm)
    code, stdout, err = run(capsys, "annotate", inputs / "torus.ply", "-o", tmp_path / "t.ply")
    assert code == 0
    assert ("compiling the numba kernels" in err) != warm
    assert "compiling" not in stdout


def test_nan_rows_are_reported_and_get_no_estimate(tmp_path, capsys, inputs):
    table = np.loadtxt(inputs / "cloud.xyz")
    table[7, :3] = np.nan
    src = tmp_path / "holes.xyz"
    np.savetxt(src, table)
    code, _, err = run(capsys, "annotate", src, "-o", tmp_path / "holes.ply")
    assert code == 0
    assert "warning" in err and "1 vertices have non-finite" in err
    back = io.read(str(tmp_path / "holes.ply"))
    assert len(back.vertices) == len(table)  # the row is kept, in place
    assert back.fields["valid"][7] == 0 and np.isnan(back.fields["k1"][7])
    assert back.fields["valid"].sum() > 0.95 * len(table)
    # the reason is written beside it, and info counts the rows by reason
    from meshcurv.result import Status

    status = back.fields["status"]
    assert status[7] == Status.NO_POSITION
    assert ((status == Status.OK) == (back.fields["valid"] == 1)).all()
    code, out, _ = run(capsys, "info", tmp_path / "holes.ply")
    assert code == 0 and "NO_POSITION" in out
    line = next(x for x in out.splitlines() if x.startswith("no estimate: "))
    assert sum(int(p.split()[0]) for p in line[len("no estimate: "):].split(", ")) == (
        (status != Status.OK).sum())


BAD = {
    "missing.ply": (None, "no such file"),
    "corrupt.ply": (b"ply\nformat binary_little_endian 1.0\nelement vertex 10\n"
                    b"property double x\nproperty double y\nproperty double z\nend_header\n\x00",
                    "not a valid PLY"),
    "garbage.ply": (bytes(range(256)) * 4, "not a valid PLY"),
    "mesh.abc": (b"whatever", "unsupported file type"),
    "empty.ply": (b"ply\nformat ascii 1.0\nelement vertex 0\nproperty float x\n"
                  b"property float y\nproperty float z\nend_header\n", "no vertices"),
    "nan.xyz": (b"nan 0 0\n0 nan 0\n0 0 nan\nnan nan nan\n", "no vertex has finite"),
    "three.xyz": (b"0 0 0\n1 0 0\n0 1 0\n", "too few points (3)"),
    "broken.obj": (b"v 0 0 0\nv 1 0 0\nf 1 2 9\n", "broken.obj"),
}


@pytest.mark.parametrize("name", sorted(BAD))
def test_bad_input_fails_in_one_line_naming_the_file_and_writes_nothing(tmp_path, capsys,
                                                                         name):
    content, message = BAD[name]
    src = tmp_path / name
    if content is not None:
        src.write_bytes(content)
    before = sorted(os.listdir(tmp_path))
    code, stdout, err = run(capsys, "annotate", src, "-o", tmp_path / "out" / "x.ply",
                            "--preview", tmp_path / "out" / "x.png")
    assert code == 1
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("meshcurv: error: "), err
    assert str(src) in lines[0] and message in lines[0]
    assert "Traceback" not in err and stdout == ""
    assert sorted(os.listdir(tmp_path)) == before  # no output, no temporary file, no out/


@pytest.mark.parametrize("argv, message", [
    (["--radius", "-2"], "radius must be positive"),
    (["--radius", "two"], "radius must be a number"),
    (["--directions", "2"], "from 3 to 64"),
    (["--viewpoint", "nan", "0", "10"], "finite (3,) viewpoint"),
    (["--colormap", "Jet"], "--colormap"),
    (["-o", "{in}"], "refusing to overwrite the input"),
    (["-o", "{tmp}/x.obj"], "output must be"),
    (["-o", "{tmp}/x.las"], "LAS/LAZ output needs a LAS/LAZ input"),
    (["--preview", "{tmp}/x.jpg"], "must be a .png"),
    (["--tile-size", "5"], "need a .las or .laz input"),
])
def test_bad_options_exit_2_before_reading_anything(tmp_path, capsys, inputs, argv, message):
    src = inputs / "torus.ply"
    before = src.read_bytes()
    argv = [a.format(tmp=tmp_path, **{"in": src}) for a in argv]
    if "-o" not in argv:
        argv += ["-o", str(tmp_path / "x.ply")]
    code, _, err = run(capsys, "annotate", src, *argv)
    assert code == 2
    assert err.count("\n") == 1 and message in err, err
    assert os.listdir(tmp_path) == [] and src.read_bytes() == before


def test_an_output_that_is_a_directory_is_refused_before_reading(tmp_path, capsys, inputs):
    # the run went to the end, then the rename failed naming the temporary file
    (tmp_path / "out.ply").mkdir()
    code, _, err = run(capsys, "annotate", inputs / "torus.ply", "-o", tmp_path / "out.ply")
    assert code == 2 and err.count("\n") == 1 and "is a directory" in err, err
    assert ".part" not in err and os.listdir(tmp_path / "out.ply") == []


def test_console_entry_point_prints_no_traceback(tmp_path):
    # the installed entry point and ``python -m meshcurv`` share cli.main; run the module for real
    proc = subprocess.run([sys.executable, "-m", "meshcurv", "annotate",
                           str(tmp_path / "nope.off"), "-o", str(tmp_path / "o.ply")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 1
    assert proc.stderr.strip() == f"meshcurv: error: {tmp_path / 'nope.off'}: no such file"
    assert os.listdir(tmp_path) == []


def test_help_explains_units_sign_and_radius(capsys):
    with pytest.raises(SystemExit) as exc:
        cli.main(["annotate", "--help"])
    assert exc.value.code == 0
    text = capsys.readouterr().out
    for phrase in ("1/model units", "OUTWARD normals, convex positive", "k1 >= k2",
                   "k1 = k2 = +1/r", "percent of the bounding-box diagonal (--radius 2%)",
                   "--tile-size", "--dask-scheduler"):
        assert phrase in text, phrase


# -------------------------------------------------------------------------------------- batch

def _batch_dir(tmp_path, inputs, corrupt=True):
    d = tmp_path / "in"
    d.mkdir()
    for name in ("torus.ply", "sphere.obj", "cloud.xyz"):
        (d / name).write_bytes((inputs / name).read_bytes())
    if corrupt:
        (d / "bad.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x"
                                    b"\nproperty float y\nproperty float z\nend_header\n1 2\n")
    return d


GOOD = ["cloud_curvature.ply", "sphere_curvature.ply", "torus_curvature.ply"]


def test_batch_finishes_the_other_files_names_the_failure_and_resumes(tmp_path, capsys, inputs):
    src = _batch_dir(tmp_path, inputs)
    out = tmp_path / "out"
    code, stdout, err = run(capsys, "batch", src, "--out-dir", out, "--radius", "8%")
    assert code == 1
    assert "3 annotated, 0 skipped (output exists), 1 failed" in stdout
    assert f"FAILED {src / 'bad.ply'}: not a valid PLY" in err
    assert "Traceback" not in err
    assert sorted(os.listdir(out)) == GOOD  # no partial file for the bad one
    stamps = {f: os.stat(out / f).st_mtime_ns for f in GOOD}

    # a re-run skips finished outputs and retries only the failure
    os.remove(src / "bad.ply")
    code, stdout, err = run(capsys, "batch", src, "--out-dir", out, "--radius", "8%")
    assert code == 0, err
    assert "0 annotated, 3 skipped (output exists), 0 failed" in stdout
    assert {f: os.stat(out / f).st_mtime_ns for f in GOOD} == stamps

    # --overwrite recomputes, to the same bytes
    before = {f: (out / f).read_bytes() for f in GOOD}
    code, stdout, _ = run(capsys, "batch", *sorted(src.iterdir()), "--out-dir", out,
                          "--radius", "8%", "--overwrite")
    assert code == 0 and "3 annotated" in stdout
    assert {f: (out / f).read_bytes() for f in GOOD} == before


def test_batch_output_matches_annotate(tmp_path, capsys, inputs):
    code, _, _ = run(capsys, "batch", inputs / "sphere.obj", "-O", tmp_path / "b",
                     "--quality", "k1")
    assert code == 0
    code, _, _ = run(capsys, "annotate", inputs / "sphere.obj", "-o", tmp_path / "a.ply",
                     "--quality", "k1")
    assert code == 0
    assert (tmp_path / "b" / "sphere_curvature.ply").read_bytes() == \
        (tmp_path / "a.ply").read_bytes()


def test_batch_on_a_dask_cluster_gives_identical_files(tmp_path, capsys, inputs, dask_cluster):
    src = _batch_dir(tmp_path, inputs)
    code, _, _ = run(capsys, "batch", src, "--out-dir", tmp_path / "serial", "--radius", "8%")
    assert code == 1
    code, stdout, err = run(capsys, "batch", src, "--out-dir", tmp_path / "dask",
                            "--radius", "8%", "--dask-scheduler", dask_cluster.scheduler_address)
    assert code == 1
    assert "3 annotated, 0 skipped (output exists), 1 failed" in stdout
    assert f"FAILED {src / 'bad.ply'}" in err
    assert sorted(os.listdir(tmp_path / "dask")) == GOOD
    for f in GOOD:
        assert (tmp_path / "dask" / f).read_bytes() == (tmp_path / "serial" / f).read_bytes()


def test_batch_with_an_unreachable_scheduler_fails_in_one_line(tmp_path, capsys, inputs,
                                                               monkeypatch):
    def refuse(scheduler, timeout="20s"):
        raise OSError("Timed out trying to connect to tcp://127.0.0.1:9 after 20 s")

    distributed = pytest.importorskip("distributed")
    monkeypatch.setattr(distributed, "Client", refuse)
    code, _, err = run(capsys, "batch", inputs / "sphere.obj", "-O", tmp_path / "out",
                       "--dask-scheduler", "tcp://127.0.0.1:9")
    assert code == 1
    assert err == ("meshcurv: error: cannot connect to the Dask scheduler tcp://127.0.0.1:9: "
                   "Timed out trying to connect to tcp://127.0.0.1:9 after 20 s\n")
    assert not (tmp_path / "out").exists()


@pytest.mark.slow
def test_batch_with_process_pool_gives_identical_files(tmp_path, capsys, inputs):
    src = _batch_dir(tmp_path, inputs)
    run(capsys, "batch", src, "--out-dir", tmp_path / "serial")
    code, stdout, _ = run(capsys, "batch", src, "--out-dir", tmp_path / "pool", "--jobs", "2")
    assert code == 1 and "3 annotated" in stdout
    for f in GOOD:
        assert (tmp_path / "pool" / f).read_bytes() == (tmp_path / "serial" / f).read_bytes()


# ------------------------------------------------------------------------------------ LAS/LAZ

@pytest.fixture(scope="module")
def las_file(tmp_path_factory):
    """A small LAS cloud: the paraboloid z = 0.3 (x^2 + y^2), 3000 random points, 1e-5 scale."""
    laspy = pytest.importorskip("laspy")
    rng = np.random.default_rng(2)
    xy = rng.uniform(-1.0, 1.0, size=(3000, 2))
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = [1e-5, 1e-5, 1e-5]
    header.offsets = [0.0, 0.0, 0.0]
    las = laspy.LasData(header)
    las.x, las.y, las.z = xy[:, 0], xy[:, 1], 0.3 * (xy ** 2).sum(axis=1)
    las.intensity = rng.integers(0, 65535, 3000).astype(np.uint16)
    las.classification = rng.integers(0, 20, 3000).astype(np.uint8)
    las.gps_time = rng.uniform(0.0, 1e6, 3000)
    las.add_extra_dim(laspy.ExtraBytesParams(name="amp dB", type=np.float32))
    las["amp dB"] = rng.normal(size=3000).astype(np.float32)
    path = tmp_path_factory.mktemp("las") / "para.las"
    las.write(str(path))
    return path


def test_las_input_annotates_in_memory_to_las_and_ply(tmp_path, capsys, las_file):
    laspy = pytest.importorskip("laspy")
    from meshcurv.io import las

    xyz, normals = las.read_las_points(str(las_file))
    # the command line orients LAS input towards +z
    res = meshcurv.principal_curvatures(xyz, normals=normals, radius=0.25, orientation="+z")
    code, _, err = run(capsys, "annotate", las_file, "-o", tmp_path / "para.laz",
                       "--radius", "0.25")
    assert code == 0, err
    out = laspy.read(str(tmp_path / "para.laz"))
    assert len(out.points) == len(xyz)
    for name in shape.FIELDS:
        assert _bits(out[name]) == _bits(getattr(res, name)), name
    code, _, err = run(capsys, "annotate", las_file, "-o", tmp_path / "para.ply",
                       "--radius", "0.25")
    assert code == 0, err
    assert _bits(io.read(str(tmp_path / "para.ply")).fields["k1"]) == _bits(res.k1)
    # the points' own attributes come along, by CloudCompare's spelling of a scalar field
    from plyfile import PlyData
    vertex = PlyData.read(str(tmp_path / "para.ply"))["vertex"]
    src = laspy.read(str(las_file))
    for name in ("intensity", "classification", "gps_time", "return_number", "red", "amp dB"):
        got = vertex["scalar_" + name.replace(" ", "_")]    # no whitespace in a PLY name
        assert got.dtype == np.asarray(src[name]).dtype, name
        np.testing.assert_array_equal(got, np.asarray(src[name]), err_msg=name)


def test_las_dimensions_a_ply_has_no_type_for_are_carried_or_named(tmp_path, capsys):
    """A '3f8' array of extra bytes goes to PLY as three properties; 64-bit integers as
    doubles when every value fits in 53 bits, else they are left out and the command says so
    (a LAS output keeps them: it copies the input's records)."""
    laspy = pytest.importorskip("laspy")
    from plyfile import PlyData

    rng = np.random.default_rng(3)
    xy = rng.uniform(-1.0, 1.0, size=(2000, 2))
    las = laspy.LasData(laspy.LasHeader(point_format=6, version="1.4"))
    las.header.scales = [1e-5] * 3
    las.x, las.y, las.z = xy[:, 0], xy[:, 1], 0.3 * (xy ** 2).sum(axis=1)
    las.add_extra_dims([laspy.ExtraBytesParams("offset", "3f8"),
                        laspy.ExtraBytesParams("segment", "u8"),
                        laspy.ExtraBytesParams("uid", "i8")])
    offset = rng.normal(size=(2000, 3))
    segment = np.arange(2000, dtype=np.uint64) + np.uint64(2 ** 53 - 2000)   # max 2^53 - 1
    uid = np.arange(2000, dtype=np.int64) - 2 ** 62                          # beyond 2^53
    las.offset, las.segment, las.uid = offset, segment, uid
    las.write(str(tmp_path / "dims.las"))

    code, _, err = run(capsys, "annotate", tmp_path / "dims.las", "-o", tmp_path / "dims.ply")
    assert code == 0, err
    vertex = PlyData.read(str(tmp_path / "dims.ply"))["vertex"]
    for i in range(3):
        assert _bits(vertex[f"scalar_offset_{i}"]) == _bits(offset[:, i])
    assert vertex["scalar_segment"].dtype == np.float64
    np.testing.assert_array_equal(vertex["scalar_segment"].astype(np.uint64), segment)
    assert "scalar_uid" not in vertex.data.dtype.names
    assert err.count("warning") == 1 and "uid" in err and "2^53" in err, err

    code, _, err = run(capsys, "annotate", tmp_path / "dims.las", "-o", tmp_path / "dims.laz")
    assert code == 0 and "warning" not in err, err
    out = laspy.read(str(tmp_path / "dims.laz"))
    np.testing.assert_array_equal(out.uid, uid)
    np.testing.assert_array_equal(out.offset, offset)


def test_tiling_flags_reach_annotate_tiled(tmp_path, capsys, las_file, monkeypatch,
                                           dask_cluster):
    from meshcurv import tiled

    calls = []

    def fake(in_path, out_path, radius=None, tile_size=None, **kwargs):
        calls.append(dict(in_path=in_path, out_path=out_path, radius=radius,
                          tile_size=tile_size, **kwargs))
        return tiled.TiledReport(n_points=3000, n_tiles=4, radius=radius or 1.0,
                                 tile_size=tile_size or 1.0, halo=0.0, seconds=0.1)

    monkeypatch.setattr(tiled, "annotate_tiled", fake)
    out = tmp_path / "para_curv.laz"
    code, stdout, err = run(capsys, "annotate", las_file, "-o", out, "--tile-size", "0.5",
                            "--radius", "0.25", "--directions", "6")
    assert code == 0, err
    (call,) = calls
    assert (call["in_path"], call["out_path"]) == (str(las_file), str(out))
    assert call["radius"] == 0.25 and call["tile_size"] == 0.5
    assert call["scheduler"] is None and call["n_directions"] == 6
    assert call["orientation"] == "+z"        # LAS input: seen from above by default
    assert "3000 points in 4 tiles" in stdout

    # --viewpoint reaches the tiles as their orientation
    calls.clear()
    code, _, err = run(capsys, "annotate", las_file, "-o", out, "--tile-size", "0.5",
                       "--viewpoint", "0", "0", "100")
    assert code == 0, err
    assert calls[0]["orientation"] == (0.0, 0.0, 100.0)

    # --dask-scheduler alone: connected client, default tile size; percent radius from header
    calls.clear()
    code, _, err = run(capsys, "annotate", las_file, "-o", out, "--radius", "10%",
                       "--dask-scheduler", dask_cluster.scheduler_address)
    assert code == 0, err
    (call,) = calls
    assert call["tile_size"] is None and hasattr(call["scheduler"], "submit")
    laspy = pytest.importorskip("laspy")
    with laspy.open(str(las_file)) as f:
        diagonal = np.linalg.norm(np.asarray(f.header.maxs) - np.asarray(f.header.mins))
    assert call["radius"] == pytest.approx(0.1 * diagonal, rel=1e-12)


def test_tiled_errors_are_one_line(tmp_path, capsys, las_file, monkeypatch):
    from meshcurv import tiled

    def failing(in_path, out_path, **kwargs):
        raise tiled.TileError(f"tile t_0_0 of {in_path} failed: MemoryError: \nmore")

    monkeypatch.setattr(tiled, "annotate_tiled", failing)
    code, _, err = run(capsys, "annotate", las_file, "-o", tmp_path / "o.las", "--tile-size", "1")
    assert code == 1
    assert err.count("\n") == 1 and "tile t_0_0" in err and "re-run to resume" in err
    for argv, message in ((["-o", tmp_path / "o.ply"], "need a .las or .laz output"),
                          (["-o", tmp_path / "o.las", "--preview", tmp_path / "p.png"],
                           "--preview is not available"),
                          (["-o", tmp_path / "o.las", "--neighborhood", "kring"], "kring")):
        code, _, err = run(capsys, "annotate", las_file, "--tile-size", "1", *argv)
        assert code == 2 and message in err and err.count("\n") == 1


@pytest.mark.slow
def test_tiled_run_end_to_end_on_a_local_cluster(tmp_path, capsys, las_file, dask_cluster):
    laspy = pytest.importorskip("laspy")
    out = tmp_path / "para_tiled.laz"
    code, stdout, err = run(capsys, "annotate", las_file, "-o", out, "--radius", "0.25",
                            "--tile-size", "0.5", "--dask-scheduler",
                            dask_cluster.scheduler_address)
    assert code == 0, err
    data = laspy.read(str(out))
    assert len(data.points) == 3000
    assert np.isfinite(np.asarray(data["k1"])).mean() > 0.9
    assert not os.path.exists(str(out) + ".meshcurv-work")
