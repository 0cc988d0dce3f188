"""LAS/LAZ and tiled runs under faults: LAS 1.0 inputs, annotated inputs refused before any work,
``info`` of annotated LAS/LAZ, Ctrl-C and failing tiles in one line."""

import os

import laspy
import numpy as np
import pytest

import meshcurv
from meshcurv import cli, las

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
    res = meshcurv.principal_curvatures(xyz, radius=2.0, orientation=VIEWPOINT)
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
    monkeypatch.setattr(meshcurv.estimator, "principal_curvatures", _no_computation)
    assert cli.main(["annotate", path, "-o", out, "--radius", "2"]) == 1
    err = [ln for ln in capsys.readouterr().err.splitlines() if "compiling" not in ln]
    assert err == [f"meshcurv: error: {path} already has dimension(s) k1, k2, mean and 10 more "
                   "(an annotated file?); annotate the original file"]
    assert os.listdir(tmp_path) == []
    # to PLY the annotated LAZ is an ordinary input
    monkeypatch.undo()
    assert cli.main(["annotate", path, "-o", str(tmp_path / "again.ply"), "--radius", "2"]) == 0


def test_annotated_laz_is_refused_by_a_tiled_run_before_the_cluster_starts(annotated, tmp_path,
                                                                          capsys, monkeypatch):
    import meshcurv.tiled as tiled

    path, _ = annotated
    out = str(tmp_path / "twice.laz")
    monkeypatch.setattr(tiled, "_dask_client", _no_computation)
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
