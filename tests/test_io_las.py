"""meshcurv.io.las: chunked reading, curvature fields as extra-bytes dimensions, bad files."""

import os

import laspy
import numpy as np
import pytest

import meshcurv
from meshcurv import result
from meshcurv.io import las

VIEWPOINT = (20.0, 20.0, 500.0)


def _cloud(n, seed=0):
    """(n, 3) points of a wavy height field over a 40 x 40 square, shuffled order."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, 40.0, (n, 2))
    z = 2.0 * np.sin(xy[:, 0] / 6.0) * np.cos(xy[:, 1] / 7.0)
    return np.column_stack([xy, z])


def _write_las(path, xyz, normals=None, normal_names=("nx", "ny", "nz")):
    """A point format 3 file (GPS time, RGB) with an extra float32 'reflectance' dimension."""
    rng = np.random.default_rng(1)
    header = laspy.LasHeader(point_format=3, version="1.4")
    header.scales = [1e-4] * 3
    header.offsets = [1000.0, 2000.0, 0.0]
    header.add_extra_dims([laspy.ExtraBytesParams(name="reflectance", type=np.float32)])
    if normals is not None:
        header.add_extra_dims([laspy.ExtraBytesParams(name=n, type=np.float64)
                               for n in normal_names])
    data = laspy.LasData(header)
    # coordinates far from the origin, as in georeferenced scans
    data.x, data.y, data.z = xyz[:, 0] + 1000.0, xyz[:, 1] + 2000.0, xyz[:, 2]
    n = len(xyz)
    data.intensity = rng.integers(0, 65535, n).astype(np.uint16)
    data.classification = rng.integers(0, 20, n).astype(np.uint8)
    data.return_number = rng.integers(1, 4, n).astype(np.uint8)
    data.gps_time = rng.uniform(0, 1e6, n)
    data.red = rng.integers(0, 65535, n).astype(np.uint16)
    data.reflectance = rng.normal(size=n).astype(np.float32)
    if normals is not None:
        for a, name in enumerate(normal_names):
            data[name] = normals[:, a]
    data.write(path)
    # the stored (quantised) coordinates are what every reader sees
    return np.asarray(laspy.read(path).xyz, dtype=np.float64)


@pytest.fixture(scope="module")
def las_file(tmp_path_factory):
    path = str(tmp_path_factory.mktemp("las") / "cloud.las")
    xyz = _write_las(path, _cloud(6000))
    return path, xyz


def test_chunked_reading_returns_the_file_in_order(las_file):
    path, xyz = las_file
    chunks = list(las.iter_las_chunks(path, chunk_size=1700))
    assert [c[0] for c in chunks] == list(range(0, 6000, 1700))
    got, normals = las.read_las_points(path, chunk_size=1700)
    assert normals is None
    np.testing.assert_array_equal(got, xyz)
    # a range read (as a scatter task does) starts at the asked point
    (first, part, _), = las.iter_las_chunks(path, 1000, start=2500, stop=3500)
    assert first == 2500
    np.testing.assert_array_equal(part, xyz[2500:3500])


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_curvature_fields_round_trip_by_name_and_input_dims_unchanged(las_file, tmp_path, suffix):
    path, xyz = las_file
    res = meshcurv.principal_curvatures(xyz, radius=2.0, orientation=VIEWPOINT)
    out = str(tmp_path / f"annotated{suffix}")
    las.write_las_curvature(path, out, res, chunk_size=2500)

    src, got = laspy.read(path), laspy.read(out)
    # float64 fields are stored as they are: equality, not a tolerance
    expected = {"k1": res.k1, "k2": res.k2, "mean": res.mean, "gaussian": res.gaussian,
                "shape_index": res.shape_index, "curvedness": res.curvedness,
                "d1x": res.d1[:, 0], "d1y": res.d1[:, 1], "d1z": res.d1[:, 2],
                "d2x": res.d2[:, 0], "d2y": res.d2[:, 1], "d2z": res.d2[:, 2],
                "NormalX": res.normals[:, 0], "NormalY": res.normals[:, 1],
                "NormalZ": res.normals[:, 2]}
    for name, values in expected.items():
        np.testing.assert_array_equal(np.asarray(got[name]), values, err_msg=name)
    np.testing.assert_array_equal(np.asarray(got["valid"]), res.valid.astype(np.uint8))
    assert np.asarray(got["valid"]).dtype == np.uint8
    assert res.valid.mean() > 0.95

    # the input's own dimensions, raw integers and existing extra bytes, bit for bit
    for name in src.point_format.dimension_names:
        np.testing.assert_array_equal(np.asarray(src[name]), np.asarray(got[name]), err_msg=name)
    np.testing.assert_array_equal(src.header.scales, got.header.scales)
    np.testing.assert_array_equal(src.header.offsets, got.header.offsets)
    assert got.header.point_format.id == src.header.point_format.id
    assert list(got.point_format.extra_dimension_names) == (
        ["reflectance"] + list(result.CURVATURE_FIELDS) + list(las.NORMAL_FIELDS))
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".part")]


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_records_after_the_points_are_kept(tmp_path, suffix):
    # a LAS 1.4 file's coordinate system as an extended record (EVLR): laspy's writer leaves
    # such records out unless asked, and the output lost it while its header still said WKT
    header = laspy.LasHeader(point_format=6, version="1.4")
    header.scales = [1e-3] * 3
    header.offsets = [500000.0, 4200000.0, 100.0]
    header.global_encoding.wkt = True
    wkt = b'PROJCS["WGS 84 / UTM zone 33N"]\0'
    header.evlrs = laspy.vlrs.vlrlist.VLRList([laspy.VLR(
        user_id="LASF_Projection", record_id=2112, description="OGC WKT", record_data=wkt)])
    header.vlrs.append(laspy.VLR(user_id="meshcurv_test", record_id=7, record_data=b"kept"))
    data = laspy.LasData(header)
    xyz = _cloud(3000)
    data.x, data.y, data.z = xyz[:, 0] + 500000.0, xyz[:, 1] + 4200000.0, xyz[:, 2] + 100.0
    path = str(tmp_path / f"crs{suffix}")
    data.write(path)
    res = meshcurv.principal_curvatures(np.asarray(laspy.read(path).xyz), radius=2.0)
    out = str(tmp_path / f"out{suffix}")
    las.write_las_curvature(path, out, res, chunk_size=1000)
    got = laspy.read(out)
    assert [(r.user_id, r.record_id, r.record_data_bytes()) for r in got.header.evlrs] == [
        ("LASF_Projection", 2112, wkt)]
    assert got.header.global_encoding.wkt
    assert [(r.user_id, r.record_id) for r in got.header.vlrs
            if r.user_id == "meshcurv_test"] == [("meshcurv_test", 7)]
    np.testing.assert_array_equal(np.asarray(got["k1"]), res.k1)


def test_float32_fields_hold_the_rounded_values(las_file, tmp_path):
    path, xyz = las_file
    res = meshcurv.principal_curvatures(xyz, radius=2.0, orientation=VIEWPOINT)
    out = str(tmp_path / "f4.laz")
    las.write_las_curvature(path, out, res, float_type="f4")
    got = laspy.read(out)
    assert np.asarray(got["k1"]).dtype == np.float32
    np.testing.assert_array_equal(np.asarray(got["k1"]), res.k1.astype(np.float32))


def test_normals_in_the_input_are_read_and_not_written_again(tmp_path):
    pts = _cloud(3000, seed=2)
    given = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    path = str(tmp_path / "with_normals.laz")
    _write_las(path, pts, normals=given, normal_names=("NormalX", "NormalY", "NormalZ"))
    xyz, normals = las.read_las_points(path)
    np.testing.assert_array_equal(normals, given)
    res = meshcurv.principal_curvatures(xyz, normals=normals, radius=2.0)
    out = str(tmp_path / "out.laz")
    las.write_las_curvature(path, out, res)
    names = list(laspy.read(out).point_format.extra_dimension_names)
    assert names.count("NormalX") == 1
    assert names[-len(result.CURVATURE_FIELDS):] == list(result.CURVATURE_FIELDS)


def test_truncated_laz_is_named_and_leaves_no_output(las_file, tmp_path):
    path, xyz = las_file
    laz = str(tmp_path / "whole.laz")
    laspy.read(path).write(laz)
    data = open(laz, "rb").read()
    bad = str(tmp_path / "truncated.laz")
    with open(bad, "wb") as fh:
        fh.write(data[: len(data) * 2 // 3])
    with pytest.raises(las.LasReadError, match="truncated.laz"):
        las.read_las_points(bad)
    out = str(tmp_path / "out.laz")
    with pytest.raises(las.LasReadError, match="truncated.laz"):
        las.annotate_las(bad, out, lambda first, count: {}, ["k1"])
    assert sorted(os.listdir(tmp_path)) == ["truncated.laz", "whole.laz"]


def test_not_a_las_file_is_named(tmp_path):
    bad = str(tmp_path / "noise.las")
    with open(bad, "wb") as fh:
        fh.write(b"this is not a point cloud" * 10)
    with pytest.raises(las.LasReadError, match="noise.las"):
        las.las_point_count(bad)


def test_bad_requests_are_refused(las_file, tmp_path):
    path, xyz = las_file
    res = meshcurv.principal_curvatures(xyz, radius=2.0, orientation=VIEWPOINT)
    with pytest.raises(ValueError, match="overwrite the input"):
        las.write_las_curvature(path, path, res)
    with pytest.raises(ValueError, match="rows"):
        las.write_las_curvature(path, str(tmp_path / "o.las"), meshcurv.principal_curvatures(
            xyz[:10], radius=2.0, orientation=VIEWPOINT))
    once = str(tmp_path / "once.las")
    las.write_las_curvature(path, once, res)
    # annotating an annotated file would clash with its curvature dimensions
    with pytest.raises(ValueError, match="already has dimension"):
        las.write_las_curvature(once, str(tmp_path / "twice.las"), res)
    assert not os.path.exists(tmp_path / "twice.las")


def test_las_output_folder_is_created_and_holds_only_the_output(las_file, tmp_path):
    path, xyz = las_file
    res = meshcurv.principal_curvatures(xyz, radius=2.0, orientation=VIEWPOINT)
    out = tmp_path / "new" / "annotated.laz"
    las.write_las_curvature(path, str(out), res)
    assert laspy.read(str(out)).header.point_count == len(xyz)
    assert os.listdir(out.parent) == ["annotated.laz"]
