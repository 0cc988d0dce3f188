"""What the programs that open meshcurv's PLY files really read: plyfile (and meshcurv's reader)
every field at full precision under its ``scalar_<field>`` name, pymeshlab through
``meshcurv.filters.save_curvature_mesh`` / ``load_curvature_mesh``, CloudCompare every field as
a single-precision scalar field, MeshLab only normals, quality and colour.

Tests marked ``clients`` run Debian's CloudCompare and meshlabserver when they are installed
(``apt-get install cloudcompare meshlab xvfb``) and are skipped otherwise."""

import os
import shutil
import subprocess

import numpy as np
import pytest
from plyfile import PlyData

pymeshlab = pytest.importorskip("pymeshlab")

import meshcurv  # noqa: E402
import meshcurv.filters  # noqa: E402,F401  (registers the filter on MeshSet)
from meshcurv import cli, io, result, shape, surfaces  # noqa: E402

# every per-vertex field of an annotated file besides geometry, normals, quality and colour
FIELDS = result.CURVATURE_FIELDS + ("n_neighbors", "n_samples", "residual")
# the fields the pymeshlab filter leaves on a mesh (valid as 0/1, d1 d2 as point attributes)
FILTER_SCALARS = shape.FIELDS + ("valid", "status", "outlier_score", "radius_used", "mls_share",
                                 "jet_share")


@pytest.fixture(scope="module")
def torus():
    return surfaces.torus(major=2.0, minor=0.5, n_major=48, n_minor=16)


@pytest.fixture(scope="module")
def cloud():
    """Points on a sphere of radius 2 plus one far-away point that gets no estimate (NaN)."""
    s = surfaces.sphere(radius=2.0, sampling="random", n=800, seed=5)
    return np.vstack([s.vertices, [[40.0, 0.0, 0.0]]])


def _annotate(path, vertices, faces=None, quality="mean"):
    data = io.MeshData(vertices, faces)
    res = meshcurv.principal_curvatures(vertices, faces, radius=0.6)
    io.write_annotated(str(path), data, res, quality=quality)
    return res


def _expected(res):
    """The annotated fields of ``res`` by field name, as written (float64, uint8, int32)."""
    out = result.curvature_fields(res)
    out["n_neighbors"] = np.asarray(res.n_neighbors, dtype=np.int32)
    out["n_samples"] = np.asarray(res.n_samples, dtype=np.int32)
    out["residual"] = np.asarray(res.residual, dtype=np.float64)
    return out


def _bits(a, dtype=None):
    a = np.asarray(a)
    return np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<") if dtype is None
                                else dtype).tobytes()


def _filtered_meshset(vertices, faces=None, **options):
    ms = pymeshlab.MeshSet()
    if faces is None:
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices), "cloud")
    else:
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=vertices, face_matrix=faces), "mesh")
    ms.compute_curvature_cga_per_vertex(radius=0.6, **options)
    return ms


# ------------------------------------------------------------------- the file, by plyfile

def test_annotated_ply_names_every_field_scalar_prefixed_and_keeps_full_precision(tmp_path, torus):
    out = tmp_path / "t.ply"
    res = _annotate(out, torus.vertices, torus.faces)
    v = PlyData.read(str(out))["vertex"].data
    assert v.dtype.names == (("x", "y", "z", "nx", "ny", "nz")
                             + tuple("scalar_" + f for f in FIELDS)
                             + ("quality", "red", "green", "blue"))
    for name, arr in _expected(res).items():
        assert v["scalar_" + name].dtype == arr.dtype, name
        assert _bits(v["scalar_" + name]) == _bits(arr), name
    back = io.read(str(out))  # and meshcurv's reader gives them under their own names
    assert set(FIELDS) | {"quality", "red", "green", "blue"} == set(back.fields)
    for name, arr in _expected(res).items():
        assert _bits(back.fields[name]) == _bits(arr), name


def test_files_with_the_old_plain_names_read_and_summarise_the_same(tmp_path, torus):
    new = tmp_path / "new.ply"
    res = _annotate(new, torus.vertices, torus.faces)
    old = tmp_path / "old.ply"  # the layout meshcurv wrote before the scalar_ prefix
    a = io.read(str(new))
    io.write_ply(str(old), torus.vertices, torus.faces,
                 {**_expected(res), "quality": np.where(res.valid, res.mean, 0.0),
                  **{c: a.fields[c] for c in ("red", "green", "blue")}})
    b = io.read(str(old))
    assert a.fields.keys() == b.fields.keys()
    for name in a.fields:
        assert _bits(a.fields[name]) == _bits(b.fields[name]), name
    text_new, text_old = cli.info_text(str(new)), cli.info_text(str(old))
    assert "not annotated" not in text_new and "valid:" in text_new
    assert text_new.splitlines()[1:] == text_old.splitlines()[1:]


def test_reannotating_an_annotated_file_replaces_its_fields_instead_of_doubling_them(tmp_path,
                                                                                    torus):
    first = tmp_path / "first.ply"
    _annotate(first, torus.vertices, torus.faces)
    data = io.read(str(first))
    res = meshcurv.principal_curvatures(data.vertices, data.faces, radius=0.4)
    second = tmp_path / "second.ply"
    io.write_annotated(str(second), data, res)
    names = PlyData.read(str(second))["vertex"].data.dtype.names
    assert len(names) == len(set(names))
    assert not any(n.startswith("scalar_scalar_") for n in names)
    assert "k1" not in names and "scalar_k1" in names
    assert _bits(io.read(str(second)).fields["k1"]) == _bits(res.k1)


def test_a_file_with_both_spellings_keeps_both():
    names = io.ply_field_names(["x", "k1", "scalar_k1", "scalar_k2", "scalar_intensity",
                                "quality", "scalar_quality"])
    assert names == {"x": "x", "k1": "k1", "scalar_k1": "scalar_k1", "scalar_k2": "k2",
                     "scalar_intensity": "scalar_intensity", "quality": "quality",
                     "scalar_quality": "scalar_quality"}


# ------------------------------------------------------------------------------ pymeshlab

def test_pymeshlab_reader_keeps_only_normals_quality_and_colour(tmp_path, torus):
    # the fact behind load_curvature_mesh: MeshLab drops every other vertex property
    out = tmp_path / "t.ply"
    res = _annotate(out, torus.vertices, torus.faces, quality="k1")
    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(str(out))
    m = ms.current_mesh()
    assert _bits(m.vertex_scalar_array()) == _bits(np.where(res.valid, res.k1, 0.0))
    assert _bits(m.vertex_normal_matrix()) == _bits(res.normals)
    for name in ("k1", "scalar_k1", "valid", "scalar_valid"):
        with pytest.raises(pymeshlab.PyMeshLabException):
            m.vertex_custom_scalar_attribute_array(name)


def test_save_current_mesh_writes_the_fields_only_when_each_is_asked_for(tmp_path, torus):
    ms = _filtered_meshset(torus.vertices, torus.faces)
    plain = tmp_path / "plain.ply"
    ms.save_current_mesh(str(plain))
    names = PlyData.read(str(plain))["vertex"].data.dtype.names
    assert not {"k1", "scalar_k1", "d1"} & set(names) and "quality" in names
    asked = tmp_path / "asked.ply"
    ms.save_current_mesh(str(asked), __ca_vs__k1=True, __ca_vp__d1=True)
    v = PlyData.read(str(asked))["vertex"].data
    assert _bits(v["k1"]) == _bits(ms.current_mesh().vertex_custom_scalar_attribute_array("k1"))


@pytest.mark.parametrize("kind", ["mesh", "cloud"])
def test_filter_fields_survive_save_curvature_mesh_and_reload_bit_for_bit(tmp_path, torus, cloud,
                                                                          kind):
    vertices, faces = (torus.vertices, torus.faces) if kind == "mesh" else (cloud, None)
    ms = _filtered_meshset(vertices, faces, quality="shape_index")
    m = ms.current_mesh()
    out = tmp_path / "filtered.ply"
    meshcurv.filters.save_curvature_mesh(ms, str(out))

    ply = PlyData.read(str(out))
    v = ply["vertex"].data
    assert [e.name for e in ply.elements] == (["vertex", "face"] if faces is not None
                                              else ["vertex"])
    assert _bits(np.column_stack([v["x"], v["y"], v["z"]])) == _bits(vertices)
    for name in shape.FIELDS:
        assert v["scalar_" + name].dtype == np.float64
        assert _bits(v["scalar_" + name]) == _bits(m.vertex_custom_scalar_attribute_array(name))
    valid = m.vertex_custom_scalar_attribute_array("valid")
    assert v["scalar_valid"].dtype == np.uint8 and (v["scalar_valid"] == valid).all()
    if kind == "cloud":
        assert v["scalar_valid"][-1] == 0 and np.isnan(v["scalar_k1"][-1])
    for name in ("d1", "d2"):
        got = np.column_stack([v[f"scalar_{name}{c}"] for c in "xyz"])
        assert _bits(got) == _bits(m.vertex_custom_point_attribute_matrix(name))
    assert _bits(v["quality"]) == _bits(m.vertex_scalar_array())
    rgb = np.column_stack([v["red"], v["green"], v["blue"]])
    np.testing.assert_array_equal(rgb / 255.0, m.vertex_color_matrix()[:, :3])

    # back into pymeshlab: the same attributes, and saving again gives the same file
    ms2 = pymeshlab.MeshSet()
    meshcurv.filters.load_curvature_mesh(ms2, str(out))
    m2 = ms2.current_mesh()
    for name in FILTER_SCALARS:
        assert (_bits(m2.vertex_custom_scalar_attribute_array(name))
                == _bits(m.vertex_custom_scalar_attribute_array(name))), name
    for name in ("d1", "d2"):
        assert (_bits(m2.vertex_custom_point_attribute_matrix(name))
                == _bits(m.vertex_custom_point_attribute_matrix(name)))
    again = tmp_path / "again.ply"
    meshcurv.filters.save_curvature_mesh(ms2, str(again))
    assert again.read_bytes() == out.read_bytes()


def test_load_curvature_mesh_reads_a_cli_file_with_its_diagnostics(tmp_path, torus):
    out = tmp_path / "cli.ply"
    res = _annotate(out, torus.vertices, torus.faces)
    ms = pymeshlab.MeshSet()
    meshcurv.filters.load_curvature_mesh(ms, str(out))
    m = ms.current_mesh()
    for name, arr in _expected(res).items():
        if name[:2] in ("d1", "d2"):
            continue
        assert _bits(m.vertex_custom_scalar_attribute_array(name)) == _bits(arr, "<f8"), name
    assert _bits(m.vertex_custom_point_attribute_matrix("d2")) == _bits(res.d2)
    ms.compute_selection_by_condition_per_vertex(condselect="k1 > 0")  # usable in expressions
    assert m.selected_vertex_number() == int((res.k1 > 0).sum())
    resaved = tmp_path / "resaved.ply"
    meshcurv.filters.save_curvature_mesh(ms, str(resaved))
    back = io.read(str(resaved))
    for name, arr in _expected(res).items():
        assert _bits(back.fields[name]) == _bits(arr), name


def test_save_and_load_refuse_what_they_cannot_do_with_one_line_messages(tmp_path, torus):
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=torus.vertices, face_matrix=torus.faces), "m")
    with pytest.raises(ValueError, match="no curvature attribute.*compute_curvature_cga"):
        meshcurv.filters.save_curvature_mesh(ms, str(tmp_path / "x.ply"))
    assert not os.listdir(tmp_path)
    ms.compute_curvature_cga_per_vertex(radius=0.6)
    with pytest.raises(ValueError, match="not a .ply file"):
        meshcurv.filters.save_curvature_mesh(ms, str(tmp_path / "x.obj"))
    plain = tmp_path / "plain.ply"
    io.write_ply(str(plain), torus.vertices, torus.faces)
    n = ms.mesh_number()
    with pytest.raises(ValueError, match="not annotated.*load_new_mesh") as exc:
        meshcurv.filters.load_curvature_mesh(ms, str(plain))
    assert "\n" not in str(exc.value) and ms.mesh_number() == n


# ------------------------------------------------------------------- the real programs

def _cloudcompare():
    exe = shutil.which("CloudCompare") or shutil.which("cloudcompare")
    if exe is None:
        pytest.skip("CloudCompare is not installed (Debian: apt-get install cloudcompare)")
    return exe


def _headless(cmd, tmp_path, xvfb=False):
    """Run a Qt program without a display: under xvfb-run when asked (MeshLab needs OpenGL),
    else on Qt's offscreen platform."""
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", XDG_RUNTIME_DIR=str(tmp_path))
    if xvfb:
        if shutil.which("xvfb-run") is None:
            pytest.skip("xvfb-run is not installed (Debian: apt-get install xvfb)")
        env.pop("QT_QPA_PLATFORM")
        cmd = ["xvfb-run", "-a"] + cmd
    return subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=300)


def _cloudcompare_scalar_fields(path, mesh, tmp_path):
    """The scalar fields CloudCompare loads from ``path``, as CloudCompare saves them again
    (binary PLY, ``scalar_<name>`` float32), read with plyfile: {name: array}."""
    out = tmp_path / "cc_out.ply"
    cmd = [_cloudcompare(), "-SILENT", "-AUTO_SAVE", "OFF", "-O", str(path)]
    cmd += ["-EXTRACT_VERTICES"] if mesh else []
    cmd += ["-C_EXPORT_FMT", "PLY", "-PLY_EXPORT_FMT", "BINARY_LE", "-SAVE_CLOUDS", "FILE",
            str(out)]
    run = _headless(cmd, tmp_path)
    assert run.returncode == 0 and out.exists(), run.stdout[-2000:] + run.stderr[-2000:]
    v = PlyData.read(str(out))["vertex"].data
    return {n[len("scalar_"):]: v[n] for n in v.dtype.names if n.startswith("scalar_")}


@pytest.mark.clients
@pytest.mark.parametrize("kind", ["mesh", "cloud"])
def test_cloudcompare_loads_every_field_as_a_single_precision_scalar_field(tmp_path, torus, cloud,
                                                                           kind):
    vertices, faces = (torus.vertices, torus.faces) if kind == "mesh" else (cloud, None)
    path = tmp_path / f"{kind}.ply"
    res = _annotate(path, vertices, faces)
    loaded = _cloudcompare_scalar_fields(path, faces is not None, tmp_path)
    assert list(loaded) == list(FIELDS)
    for name, arr in _expected(res).items():
        assert _bits(loaded[name]) == _bits(arr.astype(np.float32)), name
    if kind == "cloud":
        assert loaded["valid"][-1] == 0 and np.isnan(loaded["k1"][-1])


@pytest.mark.clients
def test_cloudcompare_shows_a_coloured_inputs_own_colour_and_every_field(tmp_path, cloud):
    # the input's colour and quality kept as scalar_red ... scalar_quality: CloudCompare takes
    # scalar_red, scalar_green, scalar_blue (before the ramp's red green blue in the file) as
    # the cloud's colour, and scalar_quality as a scalar field
    rng = np.random.default_rng(4)
    rgb = {c: rng.integers(0, 256, len(cloud)).astype(np.uint8) for c in ("red", "green", "blue")}
    own = dict(rgb, quality=rng.random(len(cloud)).astype(np.float32))
    data = io.MeshData(cloud, None, fields=own)
    res = meshcurv.principal_curvatures(cloud, radius=0.6)
    path = tmp_path / "coloured.ply"
    io.write_annotated(str(path), data, res)
    out = tmp_path / "cc_out.ply"
    run = _headless([_cloudcompare(), "-SILENT", "-AUTO_SAVE", "OFF", "-O", str(path),
                     "-C_EXPORT_FMT", "PLY", "-PLY_EXPORT_FMT", "BINARY_LE", "-SAVE_CLOUDS",
                     "FILE", str(out)], tmp_path)
    assert run.returncode == 0 and out.exists(), run.stdout[-2000:] + run.stderr[-2000:]
    v = PlyData.read(str(out))["vertex"].data
    for c in rgb:
        np.testing.assert_array_equal(v[c], rgb[c])
    np.testing.assert_array_equal(v["scalar_quality"], own["quality"])
    assert _bits(v["scalar_k1"]) == _bits(res.k1.astype(np.float32))


@pytest.mark.clients
def test_cloudcompare_loads_the_fields_of_save_curvature_mesh(tmp_path, torus):
    ms = _filtered_meshset(torus.vertices, torus.faces)
    path = tmp_path / "filtered.ply"
    meshcurv.filters.save_curvature_mesh(ms, str(path))
    loaded = _cloudcompare_scalar_fields(path, True, tmp_path)
    assert list(loaded) == list(result.CURVATURE_FIELDS)
    k1 = ms.current_mesh().vertex_custom_scalar_attribute_array("k1")
    assert _bits(loaded["k1"]) == _bits(k1.astype(np.float32))


def _meshlabserver(tmp_path, *args):
    exe = shutil.which("meshlabserver")
    if exe is None:
        pytest.skip("meshlabserver is not installed (Debian: apt-get install meshlab)")
    return _headless([exe, *map(str, args)], tmp_path, xvfb=True)


_QUALITY_SCRIPT = """<!DOCTYPE FilterScript>
<FilterScript>
 <filter name="Per Vertex Quality Function">
  <Param type="RichString" value="{expr}" name="q"/>
  <Param type="RichBool" value="false" name="normalize"/>
  <Param type="RichBool" value="false" name="map"/>
  <Param type="RichBool" value="false" name="onselected"/>
 </filter>
</FilterScript>
"""


@pytest.mark.clients
def test_meshlab_reads_normals_quality_and_colour_but_no_other_field(tmp_path, torus):
    path = tmp_path / "t.ply"
    res = _annotate(path, torus.vertices, torus.faces, quality="k2")
    out = tmp_path / "ml.ply"
    run = _meshlabserver(tmp_path, "-i", path, "-o", out, "-m", "vc", "vq", "vn", "vr", "vt")
    assert run.returncode == 0 and out.exists(), run.stdout[-2000:] + run.stderr[-2000:]
    v = PlyData.read(str(out))["vertex"].data
    assert not {"k1", "scalar_k1", "valid", "scalar_valid"} & set(v.dtype.names)
    # MeshLab 2020.09 (Debian 12) holds single precision, MeshLab 2022+ double
    q = np.where(res.valid, res.k2, 0.0).astype(v["quality"].dtype)
    assert _bits(v["quality"]) == _bits(q)
    np.testing.assert_array_equal(np.column_stack([v["red"], v["green"], v["blue"]]),
                                  shape.colorize(np.where(res.valid, res.k2, np.nan), "k2"))
    # MeshLab's expressions see every custom vertex attribute it has: k1 is not one of them
    for expr, works in (("x", True), ("k1", False), ("scalar_k1", False)):
        script = tmp_path / "q.mlx"
        script.write_text(_QUALITY_SCRIPT.format(expr=expr))
        run = _meshlabserver(tmp_path, "-i", path, "-o", tmp_path / "q.ply", "-s", script)
        assert (run.returncode == 0) is works, (expr, run.stdout[-1500:])
