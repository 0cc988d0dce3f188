"""meshcurv.io.ply: the annotated PLY round-trips bit for bit (fields, faces, colour), point
clouds keep their extra fields, and the input file is never overwritten."""

import numpy as np
import pytest
from plyfile import PlyData

import meshcurv
from meshcurv import io, shape, surfaces


@pytest.fixture(scope="module")
def torus():
    return surfaces.torus(major=2.0, minor=0.5, n_major=64, n_minor=24)


@pytest.fixture(scope="module")
def torus_result(torus):
    return meshcurv.principal_curvatures(torus.vertices, torus.faces, radius=0.3)


def test_annotated_ply_fields_are_bit_identical_to_api_arrays(tmp_path, torus, torus_result):
    res = torus_result
    data = io.MeshData(torus.vertices, torus.faces)
    out = tmp_path / "t.ply"
    io.write_annotated(str(out), data, res, quality="k2")
    ply = PlyData.read(str(out))
    assert ply.text is False  # binary
    v = ply["vertex"].data
    expected = {"x": torus.vertices[:, 0], "y": torus.vertices[:, 1], "z": torus.vertices[:, 2],
                "k1": res.k1, "k2": res.k2, "mean": res.mean, "gaussian": res.gaussian,
                "shape_index": res.shape_index, "curvedness": res.curvedness,
                "nx": res.normals[:, 0], "ny": res.normals[:, 1], "nz": res.normals[:, 2],
                "d1x": res.d1[:, 0], "d1y": res.d1[:, 1], "d1z": res.d1[:, 2],
                "d2x": res.d2[:, 0], "d2y": res.d2[:, 1], "d2z": res.d2[:, 2],
                "residual": res.residual, "quality": np.where(res.valid, res.k2, 0.0)}
    for name, arr in expected.items():
        name = io.ply_property(name)  # scalar_k1 in the file (CloudCompare's spelling)
        assert v[name].dtype == np.float64, name
        # bit-identical: equal bytes, NaN included
        assert v[name].tobytes() == np.ascontiguousarray(arr, dtype="<f8").tobytes(), name
    assert v["scalar_valid"].dtype == np.uint8
    np.testing.assert_array_equal(v["scalar_valid"], res.valid)
    np.testing.assert_array_equal(v["scalar_n_neighbors"], res.n_neighbors)
    rgb = np.column_stack([v["red"], v["green"], v["blue"]])
    np.testing.assert_array_equal(rgb, shape.colorize(np.where(res.valid, res.k2, np.nan), "k2"))
    np.testing.assert_array_equal(np.stack(ply["face"].data["vertex_indices"]), torus.faces)

    back = io.read(str(out))  # and our own reader gives the same arrays
    np.testing.assert_array_equal(back.vertices, torus.vertices)
    np.testing.assert_array_equal(back.faces, torus.faces)
    for name in shape.FIELDS:
        np.testing.assert_array_equal(back.fields[name], getattr(res, name))


def test_the_mls_share_is_a_field_and_0_where_no_blend_ran(tmp_path, torus, torus_result):
    """The 64 x 24 torus takes the MLS blend (shares up to ~1): the file holds the result's
    shares bit for bit; a noisy one keeps its circle fits (result None): zeros."""
    assert torus_result.mls_share is not None and torus_result.mls_share.max() > 0.99
    noisy = surfaces.add_normal_noise(torus, 0.003, seed=2)
    plain = meshcurv.principal_curvatures(noisy.vertices, noisy.faces, radius=0.3)
    assert plain.mls_share is None
    for res, expected in ((torus_result, torus_result.mls_share),
                          (plain, np.zeros(len(torus.vertices)))):
        out = tmp_path / "s.ply"
        io.write_annotated(str(out), io.MeshData(torus.vertices, torus.faces), res)
        got = PlyData.read(str(out))["vertex"].data[io.ply_property("mls_share")]
        assert got.tobytes() == np.ascontiguousarray(expected, dtype="<f8").tobytes()


def test_the_jet_share_is_a_field_and_0_where_no_jet_blend_ran(tmp_path):
    """A clean ellipsoid at its default radius takes the ring jets on most rows: the file
    holds the result's shares bit for bit; at a given radius (result None): zeros."""
    s = surfaces.ellipsoid((2.0, 1.5, 1.0), 3)
    chosen = meshcurv.principal_curvatures(s.vertices, s.faces)
    given = meshcurv.principal_curvatures(s.vertices, s.faces, radius=0.5)
    assert chosen.jet_share.max() > 0.5 and given.jet_share is None
    for res, expected in ((chosen, chosen.jet_share), (given, np.zeros(len(s.vertices)))):
        out = tmp_path / "j.ply"
        io.write_annotated(str(out), io.MeshData(s.vertices, s.faces), res)
        got = PlyData.read(str(out))["vertex"].data[io.ply_property("jet_share")]
        assert got.tobytes() == np.ascontiguousarray(expected, dtype="<f8").tobytes()


def test_point_cloud_ply_has_no_faces_and_keeps_extra_fields(tmp_path):
    pts = np.random.default_rng(1).normal(size=(200, 3))
    src = tmp_path / "cloud.ply"
    io.write_ply(str(src), pts, None, {"intensity": np.arange(200, dtype=np.float32)})
    data = io.read(str(src))
    assert data.is_point_cloud and data.faces is None
    np.testing.assert_array_equal(data.vertices, pts)
    assert data.fields["intensity"].dtype == np.float32
    res = meshcurv.principal_curvatures(pts)
    out = tmp_path / "cloud_curv.ply"
    io.write_annotated(str(out), data, res)
    ply = PlyData.read(str(out))
    assert [e.name for e in ply.elements] == ["vertex"]
    np.testing.assert_array_equal(ply["vertex"].data["intensity"], np.arange(200))


def test_the_inputs_own_colour_and_quality_are_kept_beside_the_ramp(tmp_path):
    # a coloured scan (PLY or XYZ) or a MeshLab mesh with its own per-vertex quality: the ramp
    # took their place and they were lost
    rng = np.random.default_rng(2)
    pts = rng.normal(size=(300, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    rgb = {c: rng.integers(0, 256, 300).astype(np.uint8) for c in ("red", "green", "blue")}
    own = dict(rgb, quality=rng.random(300).astype(np.float32))
    src = tmp_path / "scan.ply"
    io.write_ply(str(src), pts, None, own)
    data = io.read(str(src))
    res = meshcurv.principal_curvatures(pts)
    out = tmp_path / "scan_curv.ply"
    io.write_annotated(str(out), data, res)
    v = PlyData.read(str(out))["vertex"].data
    for name, arr in own.items():
        assert v["scalar_" + name].dtype == arr.dtype
        np.testing.assert_array_equal(v["scalar_" + name], arr)
    ramp = shape.colorize(np.where(res.valid, res.mean, np.nan), "mean")
    np.testing.assert_array_equal(np.column_stack([v[c] for c in rgb]), ramp)
    np.testing.assert_array_equal(v["quality"], np.where(res.valid, res.mean, 0.0))
    # annotated again: the first input's colour stays once, the old ramp is replaced
    again = tmp_path / "scan_curv2.ply"
    io.write_annotated(str(again), io.read(str(out)), res, quality="k1")
    w = PlyData.read(str(again))["vertex"].data
    names = list(w.dtype.names)
    assert len(names) == len(set(names)) and names.count("scalar_red") == 1
    np.testing.assert_array_equal(w["scalar_red"], rgb["red"])
    np.testing.assert_array_equal(w["quality"], np.where(res.valid, res.k1, 0.0))
    # an XYZ cloud's colours too
    xyz = tmp_path / "scan.xyz"
    np.savetxt(xyz, np.column_stack([pts] + [rgb[c] for c in rgb]), fmt="%.17g")
    io.write_annotated(str(tmp_path / "xyz_curv.ply"), io.read(str(xyz)), res)
    x = PlyData.read(str(tmp_path / "xyz_curv.ply"))["vertex"].data
    np.testing.assert_array_equal(x["scalar_green"], rgb["green"])


def test_writing_over_the_input_file_is_refused(tmp_path, torus, torus_result):
    src = tmp_path / "in.ply"
    io.write_ply(str(src), torus.vertices, torus.faces)
    before = src.read_bytes()
    data = io.read(str(src))
    with pytest.raises(io.MeshFileError, match="input"):
        io.write_annotated(str(tmp_path / "." / "in.ply"), data, torus_result)
    assert src.read_bytes() == before
