"""Several radii on the command line and in files: ``--radius 0.35,0.5,6%`` writes the fields of
every radius, named with the radius's suffix (``k1_r0p35``), bit for bit what
``principal_curvatures(..., radius=[...])`` returns; one radius keeps the plain names; bad
lists fail in one line with exit code 2; ``io.read`` and ``info`` read the suffixed fields back."""

import os

import numpy as np
import pytest
from plyfile import PlyData

import meshcurv
from meshcurv import cli, io, surfaces
from meshcurv.io import ply
from meshcurv.result import CURVATURE_FIELDS

# every per-radius field of an annotated PLY, whatever CURVATURE_FIELDS holds
PLY_RADIUS_FIELDS = CURVATURE_FIELDS + ("n_neighbors", "n_samples", "residual")
RADII = "0.35,0.5,6%"
SUFFIXES = ["_r0p35", "_r0p5", "_r6pct"]


def run(capsys, *argv):
    """Run the command in-process; returns (exit code, stdout, stderr)."""
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _bits(a):
    a = np.asarray(a)
    return np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<")).tobytes()


def _radius_fields(res):
    """The per-radius fields of one result, as the writers compute them."""
    fields = meshcurv.result.curvature_fields(res)
    fields.update(n_neighbors=np.asarray(res.n_neighbors, np.int32),
                  n_samples=np.asarray(res.n_samples, np.int32),
                  residual=np.asarray(res.residual, np.float64))
    return fields


@pytest.fixture(scope="module")
def torus():
    return surfaces.torus(major=2.0, minor=0.5, n_major=96, n_minor=32)


@pytest.fixture(scope="module")
def mesh_file(tmp_path_factory, torus):
    path = tmp_path_factory.mktemp("mesh") / "torus.ply"
    io.write_ply(str(path), torus.vertices, torus.faces)
    return path


@pytest.fixture(scope="module")
def mesh_radii(torus):
    """The radii of RADII in model units, 6 % computed as the command line does."""
    return [0.35, 0.5, 6.0 / 100.0 * io.bbox_diagonal(torus.vertices)]


@pytest.fixture(scope="module")
def annotated_mesh(tmp_path_factory, mesh_file):
    """The output of ``meshcurv annotate torus.ply --radius 0.35,0.5,6%``."""
    out = tmp_path_factory.mktemp("out") / "torus_multi.ply"
    code = cli.main(["annotate", str(mesh_file), "-o", str(out), "--radius", RADII,
                     "--quality", "shape_index"])
    assert code == 0
    return out


@pytest.fixture(scope="module")
def las_file(tmp_path_factory):
    """A small LAS cloud: the paraboloid z = 0.3 (x^2 + y^2), 2000 random points, 1e-5 scale."""
    laspy = pytest.importorskip("laspy")
    rng = np.random.default_rng(4)
    xy = rng.uniform(-1.0, 1.0, size=(2000, 2))
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = [1e-5, 1e-5, 1e-5]
    header.offsets = [0.0, 0.0, 0.0]
    las = laspy.LasData(header)
    las.x, las.y, las.z = xy[:, 0], xy[:, 1], 0.3 * (xy ** 2).sum(axis=1)
    path = tmp_path_factory.mktemp("las") / "para.las"
    las.write(str(path))
    return path


# ---------------------------------------------------------------------------- the name rule

def test_the_suffix_names_the_radius_as_an_identifier_and_reads_back():
    assert [io.radius_suffix(v, p) for v, p in
            [(0.3, False), (0.5, False), (4.0, True), (2.0, False), (1e-5, False)]] == \
        ["_r0p3", "_r0p5", "_r4pct", "_r2", "_r1em05"]
    rng = np.random.default_rng(0)
    values = np.concatenate([10.0 ** rng.uniform(-8, 8, 200), [1.0, 0.1, 1e20, 123456789.0]])
    suffixes = {io.radius_suffix(v) for v in values}
    assert len(suffixes) == len(set(values.tolist()))  # distinct radii, distinct names
    for v in values:
        suffix = io.radius_suffix(v)
        assert suffix[2:].isalnum() and suffix[2:].islower() or suffix[2:].isdigit()
        assert float(io.suffix_radius_text(suffix)) == v  # the exact radius
        for field in PLY_RADIUS_FIELDS:
            assert io.split_radius_suffix(field + suffix) == (field, suffix)
    assert io.suffix_radius_text(io.radius_suffix(2.5, percent=True)) == "2.5%"
    for name in CURVATURE_FIELDS + ("intensity", "scan_rate", "x_r", "k1_rA", "k1_r"):
        assert io.split_radius_suffix(name) == (name, "")


def test_suffixed_fields_get_the_cloudcompare_prefix_and_lose_it_on_reading():
    assert ply.ply_property("k1_r0p5") == "scalar_k1_r0p5"
    assert ply.ply_property("quality_r0p5") == "quality_r0p5"  # quality is never suffixed
    assert ply.ply_property("intensity_r0p5") == "intensity_r0p5"
    names = ply.ply_field_names(["x", "scalar_k1_r0p5", "scalar_valid_r2pct", "scalar_foo_r1"])
    assert names == {"x": "x", "scalar_k1_r0p5": "k1_r0p5", "scalar_valid_r2pct": "valid_r2pct",
                     "scalar_foo_r1": "scalar_foo_r1"}


# ------------------------------------------------------------------------------ PLY meshes

def test_a_list_of_radii_writes_every_radius_bit_for_bit(annotated_mesh, torus, mesh_radii):
    results = meshcurv.principal_curvatures(torus.vertices, torus.faces, radius=mesh_radii)
    vertex = PlyData.read(str(annotated_mesh))["vertex"].data
    names = vertex.dtype.names
    for res, suffix in zip(results, SUFFIXES):
        for field, values in _radius_fields(res).items():
            stored = vertex[ply.ply_property(field + suffix)]
            assert stored.dtype == values.dtype, field + suffix
            assert _bits(stored) == _bits(values), field + suffix
    assert not any(f in names or ply.ply_property(f) in names for f in PLY_RADIUS_FIELDS)
    # normals, quality and colour: the first radius's
    first = results[0]
    for a, c in enumerate(("nx", "ny", "nz")):
        assert _bits(vertex[c]) == _bits(first.normals[:, a])
    assert _bits(vertex["quality"]) == _bits(np.where(first.valid, first.shape_index, 0.0))
    data = io.read(str(annotated_mesh))
    assert _bits(data.fields["k1_r0p5"]) == _bits(results[1].k1)
    assert _bits(data.fields["shape_index_r6pct"]) == _bits(results[2].shape_index)


def test_one_radius_keeps_the_plain_names(tmp_path, capsys, mesh_file, torus):
    out = tmp_path / "one.ply"
    code, stdout, err = run(capsys, "annotate", mesh_file, "-o", out, "--radius", "0.5")
    assert code == 0, err
    names = PlyData.read(str(out))["vertex"].data.dtype.names
    assert names == (("x", "y", "z", "nx", "ny", "nz")
                     + tuple(ply.ply_property(f) for f in PLY_RADIUS_FIELDS)
                     + ("quality", "red", "green", "blue"))
    res = meshcurv.principal_curvatures(torus.vertices, torus.faces, radius=0.5)
    assert _bits(io.read(str(out)).fields["k1"]) == _bits(res.k1)
    assert stdout.splitlines()[0].startswith(f"{out}: {len(torus.vertices)} of "
                                             f"{len(torus.vertices)} vertices estimated, "
                                             "radius 0.5 (model units)")


def test_the_summary_line_names_every_radius(tmp_path, capsys, mesh_file, torus, mesh_radii):
    out = tmp_path / "multi.ply"
    code, stdout, err = run(capsys, "annotate", mesh_file, "-o", out, "--radius", RADII)
    assert code == 0, err
    line = stdout.splitlines()[0]
    n = len(torus.vertices)
    assert line.startswith(f"{out}: of {n} vertices, estimated {n} at radius 0.35 (*_r0p35), "
                           f"{n} at radius 0.5 (*_r0p5), {n} at radius {mesh_radii[2]:.6g} "
                           "(*_r6pct) (model units"), line


def test_reannotating_replaces_the_curvature_of_every_radius(tmp_path, capsys, annotated_mesh):
    out = tmp_path / "again.ply"
    code, _, err = run(capsys, "annotate", annotated_mesh, "-o", out, "--radius", "0.4,0.6")
    assert code == 0, err
    fields = io.read(str(out)).fields
    assert {io.split_radius_suffix(f)[1] for f in fields} == {"", "_r0p4", "_r0p6"}
    assert "k1_r0p35" not in fields and "k1" not in fields


def test_info_lists_each_radius_with_its_fields(capsys, annotated_mesh, torus, mesh_radii):
    code, stdout, err = run(capsys, "info", annotated_mesh)
    assert code == 0, err
    lines = stdout.splitlines()
    n = len(torus.vertices)
    heads = [i for i, line in enumerate(lines) if line.startswith("radius ")]
    assert [lines[i] for i in heads] == [
        "radius 0.35 (fields k1_r0p35 ...):", "radius 0.5 (fields k1_r0p5 ...):",
        f"radius 6% = {mesh_radii[2]:.6g} (fields k1_r6pct ...):"]
    results = meshcurv.principal_curvatures(torus.vertices, torus.faces, radius=mesh_radii)
    for i, res, suffix in zip(heads, results, SUFFIXES):
        share = f"{100 * res.valid.mean():.1f}"
        assert lines[i + 1] == f"valid: {int(res.valid.sum())} of {n} ({share} %)"
        row = next(line for line in lines[i:] if line.startswith("k1" + suffix + " "))
        k1 = res.k1[res.valid]
        assert float(row.split()[3]) == pytest.approx(np.median(k1), rel=1e-4)  # 5 digits
    # the field names share one column
    assert len({line.index("min") for line in lines if line.startswith("field")}) == 1


# -------------------------------------------------------------------------------- LAS/LAZ

def test_a_list_of_radii_writes_every_radius_to_las_bit_for_bit(tmp_path, capsys, las_file):
    laspy = pytest.importorskip("laspy")
    from meshcurv.io import las

    xyz, normals = las.read_las_points(str(las_file))
    assert normals is None
    radii = [0.25, 0.4]
    results = meshcurv.principal_curvatures(xyz, radius=radii, orientation="+z")
    out = tmp_path / "para.laz"
    code, stdout, err = run(capsys, "annotate", las_file, "-o", out, "--radius", "0.25,0.4")
    assert code == 0, err
    cloud = laspy.read(str(out))
    for res, suffix in zip(results, ["_r0p25", "_r0p4"]):
        for field, values in meshcurv.result.curvature_fields(res).items():
            assert _bits(cloud[field + suffix]) == _bits(values), field + suffix
    for a, name in enumerate(las.NORMAL_FIELDS):  # estimated: the first radius's normals
        assert _bits(cloud[name]) == _bits(results[0].normals[:, a])
    extra = set(cloud.point_format.extra_dimension_names)
    assert not extra & set(CURVATURE_FIELDS)
    data = io.read(str(out))
    assert _bits(data.fields["k1_r0p4"]) == _bits(results[1].k1)
    code, stdout, err = run(capsys, "info", out)
    assert code == 0, err
    assert "radius 0.25 (fields k1_r0p25 ...):" in stdout.splitlines()
    assert any(line.startswith("mean_r0p4 ") for line in stdout.splitlines())


def test_a_las_name_longer_than_32_characters_is_refused_before_any_work(tmp_path, capsys,
                                                                         las_file):
    out = tmp_path / "long.las"
    code, stdout, err = run(capsys, "annotate", las_file, "-o", out,
                            "--radius", "0.25,1.2345678901234567e-05")
    assert code == 2 and stdout == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "longer than the 32 characters" in lines[0], err
    assert not out.exists()


def test_tiled_runs_refuse_a_list_in_one_line(tmp_path, capsys, las_file):
    code, stdout, err = run(capsys, "annotate", las_file, "-o", tmp_path / "t.las",
                            "--radius", "0.25,0.4", "--tile-size", "1")
    assert code == 2 and stdout == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "take one --radius, not a list" in lines[0], err


# ----------------------------------------------------------------------------- bad lists

@pytest.mark.parametrize("radius, message", [
    ("0.5,,1", "empty item"), ("0.5,", "empty item"), (",0.5", "empty item"),
    ("0.5,-1", "radius must be positive"), ("0.5,a", "radius must be a number"),
    ("0.5,nan", "radius must be positive"), ("0.5,1,5e-1", "names the radius 5e-1 twice"),
])
@pytest.mark.parametrize("command", ["annotate", "batch"])
def test_a_bad_list_fails_in_one_line_with_exit_code_2(tmp_path, capsys, mesh_file, radius,
                                                      message, command):
    out = tmp_path / "out"
    argv = ([command, mesh_file, "-o", out / "x.ply"] if command == "annotate"
            else [command, mesh_file, "--out-dir", out])
    code, stdout, err = run(capsys, *argv, "--radius", radius)
    assert code == 2 and stdout == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("meshcurv: error: "), err
    assert message in lines[0], err
    assert not out.exists()


def test_a_radius_that_gives_no_estimate_is_named(tmp_path, capsys, mesh_file):
    out = tmp_path / "x.ply"
    code, _, err = run(capsys, "annotate", mesh_file, "-o", out, "--radius", "0.5,0.01")
    assert code == 1 and "no vertex got a curvature estimate at radius 0.01 " in err, err
    assert not out.exists()


# ---------------------------------------------------------------------------------- batch

def test_batch_takes_the_list_and_writes_what_annotate_writes(tmp_path, capsys, mesh_file,
                                                              annotated_mesh):
    code, stdout, err = run(capsys, "batch", mesh_file, "--out-dir", tmp_path, "--radius",
                            RADII, "--quality", "shape_index")
    assert code == 0, err
    out = tmp_path / "torus_curvature.ply"
    assert os.path.isfile(out)
    got, want = (PlyData.read(str(p))["vertex"].data for p in (out, annotated_mesh))
    assert got.dtype == want.dtype
    for name in want.dtype.names:
        assert _bits(got[name]) == _bits(want[name]), name
