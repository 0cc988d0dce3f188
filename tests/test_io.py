"""meshcurv.io: readers keep vertex order, the annotated PLY round-trips bit for bit, writes are
atomic, bad files fail with the file name; meshcurv.shape colour maps."""

import os

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


def test_text_and_trimesh_readers_keep_vertex_order(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [5, 5, 5], [1, 1, 0.5]], float)
    f = np.array([[2, 0, 1], [3, 5, 2]])
    # OBJ with a duplicate position (3 == 1) and an unreferenced vertex (4): both kept, in order
    obj = tmp_path / "a.obj"
    obj.write_text("".join(f"v {a} {b} {c}\n" for a, b, c in v)
                   + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f))
    off = tmp_path / "a.off"
    off.write_text(f"OFF\n{len(v)} {len(f)} 0\n" + "".join(f"{a} {b} {c}\n" for a, b, c in v)
                   + "".join(f"3 {a} {b} {c}\n" for a, b, c in f))
    for path in (obj, off):
        data = io.read(str(path))
        np.testing.assert_array_equal(data.vertices, v)
        np.testing.assert_array_equal(data.faces, f)
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    xyz = tmp_path / "a.xyz"
    np.savetxt(xyz, np.column_stack([v, n]))
    data = io.read(str(xyz))
    np.testing.assert_array_equal(data.vertices, v)
    np.testing.assert_array_equal(data.normals, n)
    pts = tmp_path / "a.pts"  # Leica PTS: count line, x y z intensity
    pts.write_text(f"{len(v)}\n" + "".join(f"{a},{b},{c},7\n" for a, b, c in v))
    data = io.read(str(pts))
    np.testing.assert_array_equal(data.vertices, v)
    assert data.normals is None and (data.fields["intensity"] == 7).all()


def test_stl_corners_are_merged_in_order_of_first_appearance(tmp_path):
    import trimesh

    sphere = surfaces.sphere(subdivisions=2)
    path = tmp_path / "s.stl"
    trimesh.Trimesh(sphere.vertices, sphere.faces, process=False).export(str(path))
    data = io.read(str(path))
    # STL is float32: compare positions at float32 precision, order of first use in faces
    first_use = np.unique(sphere.faces.ravel(), return_index=True)[1]
    order = sphere.faces.ravel()[np.sort(first_use)]
    np.testing.assert_array_equal(data.vertices, sphere.vertices[order].astype(np.float32))
    assert len(data.faces) == len(sphere.faces)
    np.testing.assert_array_equal(data.vertices[data.faces],
                                  sphere.vertices[sphere.faces].astype(np.float32))


def test_atomic_write_removes_the_temporary_file_on_failure(tmp_path):
    target = tmp_path / "out.ply"

    def failing(tmp):
        with open(tmp, "wb") as fh:
            fh.write(b"half a file")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        io.atomic_write(str(target), failing)
    assert os.listdir(tmp_path) == []


def test_writing_over_the_input_file_is_refused(tmp_path, torus, torus_result):
    src = tmp_path / "in.ply"
    io.write_ply(str(src), torus.vertices, torus.faces)
    before = src.read_bytes()
    data = io.read(str(src))
    with pytest.raises(io.MeshFileError, match="input"):
        io.write_annotated(str(tmp_path / "." / "in.ply"), data, torus_result)
    assert src.read_bytes() == before


@pytest.mark.parametrize("name, content, message", [
    ("missing.ply", None, "no such file"),
    ("mesh.abc", b"whatever", "unsupported"),
    ("corrupt.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty "
                    b"double x\nend_header\n\x00\x01", "not a valid PLY"),
    ("garbage.ply", b"\x89PNG\r\n\x1a\n" + bytes(range(256)), "not a valid PLY"),
    ("empty.xyz", b"", "no vertices"),
    ("nan.xyz", b"nan nan nan\nnan 1 2\n", "finite"),
    ("columns.xyz", b"1 2\n3 4\n", "columns"),
])
def test_bad_files_raise_meshfileerror_naming_the_file(tmp_path, name, content, message):
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(io.MeshFileError, match=message) as exc:
        io.read(str(path))
    assert str(exc.value).startswith(str(path))


def test_colorize_shape_index_uses_the_fixed_scale_and_grey_for_invalid():
    rgb = shape.colorize(np.array([-1.0, 1.0, 0.0, np.nan, 7.0]), "shape_index", "RGB")
    # MeshLab's RGB ramp: red at the low end, blue at the high end, green in the middle
    np.testing.assert_array_equal(rgb, [[255, 0, 0], [0, 0, 255], [0, 255, 0],
                                        list(shape.INVALID_COLOR), [0, 0, 255]])


def test_color_range_clips_outliers_at_percentiles():
    values = np.r_[np.linspace(0.0, 1.0, 1000), 1e6, np.nan]
    lo, hi = shape.color_range(values, "k1", clamp=2.0)
    assert 0.0 < lo < 0.05 and 0.95 < hi < 1.05  # the single 1e6 outlier does not stretch it
    assert shape.color_range(values, "shape_index") == (-1.0, 1.0)
