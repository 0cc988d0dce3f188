"""Tiled runs on a 2-worker Dask LocalCluster: equal to the untiled run, bounded memory per tile,
LAS/LAZ in and out, clear errors and resumable reruns."""

import glob
import os
import shutil

import laspy
import numpy as np
import pytest

import meshcurv
from meshcurv.io import las
from meshcurv.tiled import TileError, annotate_tiled, principal_curvatures_tiled

# Every per-point field of CurvatureResult; the tiled run must reproduce all of them.
FIELDS = ("k1", "k2", "d1", "d2", "normals", "valid", "n_neighbors", "n_samples", "residual",
          "noise", "status")


def untiled_run(*args, **kwargs):
    """The untiled estimate a tiled run reproduces: at the one radius its halo covers (tiles
    do not retry sparse points at larger radii, nor blend in the MLS surface's wider
    supports)."""
    return meshcurv.principal_curvatures(*args, sparse_retry=False, coarse_fit="circles",
                                         **kwargs)


def on(client):
    """Run on the shared cluster, one numba thread per task (two workers on two cores)."""
    return {"scheduler": client, "threads_per_task": 1}


@pytest.fixture(scope="module")
def client():
    """Two single-thread worker processes, as on a 2-core machine; closed after the module."""
    from distributed import Client, LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as c:
        yield c


def wavy_cloud(n, side, seed=0, n_bad=0):
    """(n, 3) points of a smooth height field over a ``side`` x ``side`` square, random order.

    Density n / side^2 points per unit area; ``n_bad`` rows are NaN or infinite.
    """
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, side, (n, 2))
    z = 0.04 * side * np.sin(6.0 * xy[:, 0] / side) * np.cos(5.0 * xy[:, 1] / side)
    pts = np.column_stack([xy, z])
    if n_bad:
        bad = rng.choice(n, n_bad, replace=False)
        pts[bad[::2], 0] = np.nan
        pts[bad[1::2], 2] = np.inf
    return pts


def radius_for(n_neighbors, density):
    """Radius whose ball holds about ``n_neighbors`` points at ``density`` points per unit area."""
    return float(np.sqrt(n_neighbors / (np.pi * density)))


def assert_same_result(tiled, untiled, atol=1e-12):
    """Every per-point field equal within ``atol``, NaN in the same rows."""
    assert len(tiled) == len(untiled)
    for name in FIELDS:
        a, b = np.asarray(getattr(tiled, name)), np.asarray(getattr(untiled, name))
        assert a.shape == b.shape, name
        if a.dtype.kind == "f":
            np.testing.assert_array_equal(np.isnan(a), np.isnan(b), err_msg=name)
            ok = ~np.isnan(a)
            worst = np.max(np.abs(a[ok] - b[ok]), initial=0.0)
            assert worst <= atol, f"{name}: max |tiled - untiled| = {worst:.3g}"
        else:
            np.testing.assert_array_equal(a, b, err_msg=name)


def write_las(path, xyz):
    """A point format 1 file with intensity and classification; returns the stored (n, 3) xyz."""
    rng = np.random.default_rng(3)
    header = laspy.LasHeader(point_format=1, version="1.2")
    header.scales = [1e-4] * 3
    header.offsets = [0.0, 0.0, 0.0]
    data = laspy.LasData(header)
    data.x, data.y, data.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    data.intensity = rng.integers(0, 65535, len(xyz)).astype(np.uint16)
    data.classification = rng.integers(0, 20, len(xyz)).astype(np.uint8)
    data.write(path)
    return np.asarray(laspy.read(path).xyz, dtype=np.float64)


# ----------------------------------------------------------------------------- equality, memory

# 16 tiles of ~6 000 points each, ~30 neighbors per point; 40 non-finite rows.
N_DEFAULT, SIDE_DEFAULT = 96_000, 310.0
TILE = SIDE_DEFAULT / 4 * 1.0001


@pytest.fixture(scope="module")
def default_run(client):
    pts = wavy_cloud(N_DEFAULT, SIDE_DEFAULT, n_bad=40)
    radius = radius_for(30, N_DEFAULT / SIDE_DEFAULT**2)
    viewpoint = (SIDE_DEFAULT / 2, SIDE_DEFAULT / 2, 10 * SIDE_DEFAULT)
    tiled, report = principal_curvatures_tiled(pts, radius, TILE, orientation=viewpoint,
                                               chunk_size=25_000, measure_memory=True,
                                               return_report=True, **on(client))
    untiled = untiled_run(pts, radius=radius, orientation=viewpoint)
    return pts, radius, tiled, untiled, report


def test_tiled_run_equals_untiled_run_with_viewpoint(default_run):
    pts, radius, tiled, untiled, report = default_run
    assert report.n_tiles == 16
    # a tile's own points see exactly their whole-cloud neighborhood, in the same order, so
    # every value (normals included) is the same floating-point result: 1e-12 is pure margin
    assert_same_result(tiled, untiled, atol=1e-12)
    assert untiled.valid.mean() > 0.95
    assert not tiled.valid[~np.isfinite(pts).all(axis=1)].any()


def test_noisy_tiled_run_equals_untiled_run(client):
    """With noise the normal-aware rows count, and with them each neighbor's field normal,
    which mixes plane fits over balls of up to twice the radius by means over its own ball:
    the halo covers 5 radii (with 4, measured: k1 differs by up to 2e-6 at tile borders)."""
    pts = wavy_cloud(24_000, 155.0, seed=5)
    pts[:, 2] += np.random.default_rng(6).normal(scale=0.3, size=len(pts))
    radius = radius_for(30, 24_000 / 155.0**2)
    viewpoint = (77.5, 77.5, 1550.0)
    tiled, report = principal_curvatures_tiled(pts, radius, 38.76, orientation=viewpoint,
                                               return_report=True, **on(client))
    assert report.n_tiles == 16
    assert_same_result(tiled, untiled_run(pts, radius=radius, orientation=viewpoint))


def test_tile_task_memory_is_bounded_by_the_tile_not_the_cloud(client, default_run):
    """Same tile size and density, cloud 4x smaller: the per-tile peak barely changes."""
    *_, big_report = default_run
    n_small, side_small = N_DEFAULT // 4, SIDE_DEFAULT / 2
    pts = wavy_cloud(n_small, side_small, seed=1)
    radius = radius_for(30, n_small / side_small**2)
    _, small_report = principal_curvatures_tiled(
        pts, radius, TILE, orientation=(0.0, 0.0, 5000.0), chunk_size=25_000,
        measure_memory=True, return_report=True, **on(client))
    assert small_report.n_tiles == 4

    def peak(report, key):
        return max(s[key] for s in report.tile_stats.values())

    n_total = peak(big_report, "n_total")
    # stated bound: the Python/numpy allocations of a tile task stay under 3 kB per point of
    # tile + halo at ~30 neighbors (measured 2.69 kB: neighbor lists, among them those of the
    # normal field's ball of twice the radius, ~120 entries a point in one block here, fits,
    # results), with no term that grows with the cloud
    assert peak(big_report, "peak_traced_bytes") <= 3000.0 * n_total
    # the cloud grew 4x; the largest tile task grew only by its halo (interior tiles have one
    # on every side, the small run's corner tiles on two): per point of tile + halo, the same
    assert peak(big_report, "peak_traced_bytes") / n_total <= \
        1.3 * peak(small_report, "peak_traced_bytes") / peak(small_report, "n_total")
    # resident memory of the worker during a task (interpreter, numba, libraries included)
    assert peak(big_report, "peak_rss_bytes") <= 1.2 * peak(small_report, "peak_rss_bytes")
    assert peak(big_report, "peak_rss_bytes") < 600e6


def test_mst_orientation_agrees_across_tiles_and_with_the_untiled_run(client):
    pts = wavy_cloud(24_000, 155.0, seed=4)
    radius = radius_for(30, 24_000 / 155.0**2)
    tiled, report = principal_curvatures_tiled(pts, radius, 38.76, orientation="mst",
                                               return_report=True, **on(client))
    untiled = untiled_run(pts, radius=radius, orientation="mst")
    assert report.n_tiles == 16
    # each tile's own pieces are open and already turned towards +z: the votes agree with them
    assert set(report.flips.values()) == {1}
    # one consistent side everywhere: the height field's normals all have nz of one sign
    nz = tiled.normals[:, 2][tiled.valid]
    assert (np.sign(nz) == np.sign(nz[0])).all()
    # on a smooth surface the tiles' propagation agrees with the global one: same normals,
    # and the curvature pass then sees the same inputs as the untiled run
    assert_same_result(tiled, untiled, atol=1e-12)


def test_given_normals_are_used_as_they_are(client):
    pts = wavy_cloud(12_000, 150.0, seed=5)
    radius = radius_for(30, 12_000 / 150.0**2)
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    tiled = principal_curvatures_tiled(pts, radius, 40.0, normals=normals, **on(client))
    untiled = untiled_run(pts, normals=normals, radius=radius)
    assert_same_result(tiled, untiled, atol=1e-12)


N_BIG, SIDE_BIG = 2_000_000, 1414.0


def _big_cloud():
    pts = wavy_cloud(N_BIG, SIDE_BIG, seed=6, n_bad=100)
    return pts, radius_for(30, N_BIG / SIDE_BIG**2), (SIDE_BIG / 2, SIDE_BIG / 2, 10 * SIDE_BIG)


def test_two_million_points_in_16_tiles_equal_the_untiled_run_at_every_tile_border(client):
    """The full 2M-point tiled run, compared with the untiled estimator at every point within
    two radii of a tile border (where tiling could go wrong) and 50 000 points elsewhere.

    ``query`` makes the untiled estimator compute exactly the whole-cloud values at those rows
    (neighbors from all 2M points) at a fraction of the cost; the full comparison of all 2M
    rows is the slow test below.
    """
    pts, radius, viewpoint = _big_cloud()
    tile = SIDE_BIG / 4 * 1.0001
    tiled, report = principal_curvatures_tiled(pts, radius, tile, orientation=viewpoint,
                                               return_report=True, **on(client))
    assert report.n_tiles == 16 and len(tiled) == N_BIG
    with np.errstate(invalid="ignore"):
        rel = (pts[:, :2] - np.nanmin(pts[:, :2], axis=0)) / tile
        to_border = np.abs(rel - np.round(rel)).min(axis=1) * tile
    rng = np.random.default_rng(0)
    rows = np.union1d(np.flatnonzero(~(to_border > 2 * radius)),  # NaN rows included
                      rng.choice(N_BIG, 50_000, replace=False))
    assert len(rows) > 60_000
    untiled = untiled_run(pts, radius=radius, orientation=viewpoint,
                                            query=rows)
    sample = type(untiled)(radius=tiled.radius,
                           **{k: np.asarray(getattr(tiled, k))[rows] for k in FIELDS})
    assert_same_result(sample, untiled, atol=1e-12)


@pytest.mark.slow
def test_two_million_points_in_16_tiles_equal_the_untiled_run_everywhere():
    pts, radius, viewpoint = _big_cloud()
    tiled, report = principal_curvatures_tiled(pts, radius, SIDE_BIG / 4 * 1.0001, n_workers=2,
                                               orientation=viewpoint, return_report=True)
    assert report.n_tiles == 16
    untiled = untiled_run(pts, radius=radius, orientation=viewpoint)
    assert_same_result(tiled, untiled, atol=1e-12)


# ----------------------------------------------------------------------------- LAS/LAZ files

@pytest.fixture(scope="module")
def laz_input(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tiled_laz")
    path = str(folder / "scan.laz")
    xyz = write_las(path, wavy_cloud(16_000, 120.0, seed=7))
    return path, xyz, radius_for(30, 16_000 / 120.0**2)


def test_annotate_laz_in_tiles_equals_untiled_and_keeps_input_dims(client, laz_input, tmp_path):
    path, xyz, radius = laz_input
    out = str(tmp_path / "scan_curv.laz")
    viewpoint = (60.0, 60.0, 1000.0)
    report = annotate_tiled(path, out, radius, 30.0, orientation=viewpoint, chunk_size=4000,
                            progress=False, **on(client))
    assert report.n_tiles == 16 and len(report.computed) == 16
    untiled = untiled_run(xyz, radius=radius, orientation=viewpoint)
    got, src = laspy.read(out), laspy.read(path)
    # float64 fields written and read back as they are
    np.testing.assert_array_equal(np.asarray(got["k1"]), untiled.k1)
    np.testing.assert_array_equal(np.asarray(got["shape_index"]), untiled.shape_index)
    np.testing.assert_array_equal(np.asarray(got["d2z"]), untiled.d2[:, 2])
    np.testing.assert_array_equal(np.asarray(got["NormalY"]), untiled.normals[:, 1])
    np.testing.assert_array_equal(np.asarray(got["valid"]), untiled.valid.astype(np.uint8))
    for name in src.point_format.dimension_names:
        np.testing.assert_array_equal(np.asarray(src[name]), np.asarray(got[name]), err_msg=name)
    assert sorted(os.listdir(tmp_path)) == ["scan_curv.laz"]  # no work folder, no temporary


def test_normals_in_the_file_are_used_and_not_written_again(client, tmp_path):
    pts = wavy_cloud(8_000, 80.0, seed=8)
    normals = np.tile([0.0, 0.0, 1.0], (len(pts), 1))
    header = laspy.LasHeader(point_format=0, version="1.4")
    header.scales, header.offsets = [1e-4] * 3, [0.0] * 3
    header.add_extra_dims([laspy.ExtraBytesParams(name=n, type=np.float32)
                           for n in ("nx", "ny", "nz")])
    data = laspy.LasData(header)
    data.x, data.y, data.z = pts[:, 0], pts[:, 1], pts[:, 2]
    data.nx, data.ny, data.nz = normals[:, 0], normals[:, 1], normals[:, 2]
    path, out = str(tmp_path / "with_normals.laz"), str(tmp_path / "out.laz")
    data.write(path)
    xyz = np.asarray(laspy.read(path).xyz, dtype=np.float64)
    radius = radius_for(30, 8_000 / 80.0**2)
    annotate_tiled(path, out, radius, 20.0, chunk_size=3000, progress=False, **on(client))
    got = laspy.read(out)
    assert "NormalX" not in got.point_format.extra_dimension_names
    untiled = untiled_run(xyz, normals=normals, radius=radius)
    np.testing.assert_array_equal(np.asarray(got["k1"]), untiled.k1)
    np.testing.assert_array_equal(np.asarray(got["d1x"]), untiled.d1[:, 0])


def test_failed_tile_is_named_leaves_no_output_and_rerun_resumes(client, laz_input, tmp_path):
    path, xyz, radius = laz_input
    out = str(tmp_path / "scan_curv.laz")
    work = str(tmp_path / "work")
    kw = dict(orientation=(60.0, 60.0, 1000.0), chunk_size=4000, **on(client),
              progress=False, work_dir=work)
    annotate_tiled(path, out, radius, 30.0, keep_work=True, **kw)
    reference = laspy.read(out)
    os.remove(out)
    # damage one tile's input piece and forget its result: its task fails on the worker
    broken = "t_3_3"
    shutil.rmtree(os.path.join(work, "results", broken))
    piece = sorted(glob.glob(os.path.join(work, "pieces", broken, "*.npz")))[0]
    shutil.copy(piece, piece + ".good")
    with open(piece, "wb") as fh:
        fh.write(b"not an npz file")
    with pytest.raises(TileError, match=rf"tile {broken} of .*scan\.laz"):
        annotate_tiled(path, out, radius, 30.0, **kw)
    assert not os.path.exists(out)
    assert not [f for f in os.listdir(tmp_path) if f.endswith(".part")]
    # repaired, the rerun computes the one missing tile and reuses the 15 others
    os.replace(piece + ".good", piece)
    report = annotate_tiled(path, out, radius, 30.0, **kw)
    assert report.computed == [broken] and len(report.skipped) == 15
    np.testing.assert_array_equal(np.asarray(laspy.read(out)["k1"]), np.asarray(reference["k1"]))
    assert not os.path.exists(work)


def _die_on_tile(tile):
    """Replace the curvature task in this worker by one that kills the process on ``tile``."""
    from meshcurv.tiled import tasks

    task = tasks.curvature_task

    def dying(name, *args, **kwargs):
        if name == tile:
            os._exit(1)
        return task(name, *args, **kwargs)

    tasks.curvature_task = dying


def _set_allowed_failures(dask_scheduler, count):
    previous = dask_scheduler.allowed_failures
    dask_scheduler.allowed_failures = count
    return previous


def test_dead_worker_is_reported_with_its_tile_and_no_output(client, laz_input, tmp_path):
    path, _, radius = laz_input
    out = str(tmp_path / "scan_curv.laz")
    # by default Dask retries a task whose worker died; fail at once to see the error
    previous = client.run_on_scheduler(_set_allowed_failures, count=0)
    client.run(_die_on_tile, "t_1_2")
    try:
        with pytest.raises(TileError, match=r"tile t_-?\d+_-?\d+ of .*scan\.laz.*KilledWorker"):
            annotate_tiled(path, out, radius, 30.0, orientation=(60.0, 60.0, 1000.0),
                           chunk_size=4000, progress=False, **on(client))
    finally:
        client.run_on_scheduler(_set_allowed_failures, count=previous)
        client.restart()  # fresh worker processes without the patched task
    assert not os.path.exists(out)
    # the finished tiles stay for a rerun
    assert os.path.isdir(out + ".meshcurv-work")


def test_truncated_laz_is_named_and_leaves_nothing(client, laz_input, tmp_path):
    path, _, radius = laz_input
    data = open(path, "rb").read()
    bad = str(tmp_path / "cut.laz")
    with open(bad, "wb") as fh:
        fh.write(data[: len(data) // 2])
    out = str(tmp_path / "cut_curv.laz")
    with pytest.raises(las.LasReadError, match="cut.laz"):
        annotate_tiled(bad, out, radius, 30.0, chunk_size=4000, progress=False, **on(client))
    assert sorted(os.listdir(tmp_path)) == ["cut.laz"]


def test_bad_arguments_are_refused_before_any_work(laz_input, tmp_path):
    path, xyz, radius = laz_input
    out = str(tmp_path / "o.laz")
    with pytest.raises(ValueError, match="overwrite the input"):
        annotate_tiled(path, path, radius, 30.0)
    with pytest.raises(ValueError, match="unknown estimator option"):
        annotate_tiled(path, out, radius, 30.0, no_such_option=1)
    with pytest.raises(ValueError, match="n_directions"):
        annotate_tiled(path, out, radius, 30.0, n_directions=2)
    with pytest.raises(ValueError, match="orientation"):
        annotate_tiled(path, out, radius, 30.0, orientation="centroid")
    with pytest.raises(ValueError, match="at least the radius"):
        annotate_tiled(path, out, radius, 0.5 * radius)
    with pytest.raises(ValueError, match="tile_size"):
        annotate_tiled(path, out, radius, -1.0)
    with pytest.raises(ValueError, match="radius in model units"):
        annotate_tiled(path, out, "auto", 30.0)
    with pytest.raises(ValueError, match="sparse_retry must be False"):
        annotate_tiled(path, out, radius, 30.0, sparse_retry=True)
    with pytest.raises(ValueError, match="coarse_fit must be 'circles'"):
        annotate_tiled(path, out, radius, 30.0, coarse_fit="mls")
    with pytest.raises(ValueError, match="sets"):
        principal_curvatures_tiled(xyz, radius, 30.0, query=[0])
    assert os.listdir(tmp_path) == []


def test_unreachable_scheduler_fails_in_one_line_and_leaves_no_work_folder(laz_input, tmp_path,
                                                                          monkeypatch):
    distributed = pytest.importorskip("distributed")
    path, _, radius = laz_input

    def refuse(scheduler, timeout="20s"):
        raise OSError("Timed out trying to connect to tcp://127.0.0.1:9 after 20 s")

    monkeypatch.setattr(distributed, "Client", refuse)
    before = sorted(os.listdir(tmp_path))
    with pytest.raises(OSError, match="^cannot connect to the Dask scheduler tcp://127.0.0.1:9: "):
        annotate_tiled(path, str(tmp_path / "o.laz"), radius, 30.0, scheduler="tcp://127.0.0.1:9")
    assert sorted(os.listdir(tmp_path)) == before


@pytest.mark.parametrize("order", ["random", "strips"])
def test_default_radius_from_the_first_chunk_is_the_whole_files(tmp_path, order):
    """The default radius of a tiled run comes from the file's first chunk. In a file in random
    order that chunk is a sample of the whole, 5 % of it here: its own default radius is
    sqrt(20) = 4.5x too large, and the chunk's share of the points where it lies brings it
    back. In a file sorted in strips the first chunk is all the points of one strip, and the
    radius is its own."""
    from meshcurv.tiled.run import _first_chunk_radius, _header_summary

    pts = wavy_cloud(60_000, 200.0, seed=5)
    if order == "strips":
        pts = pts[np.lexsort((pts[:, 1], np.floor(pts[:, 0] / 10.0)))]
    path = str(tmp_path / "cloud.las")
    stored = write_las(path, pts)
    n, mins, maxs, _ = _header_summary(path)
    whole = meshcurv.default_radius(stored)
    chunk = 3000
    plain = meshcurv.default_radius(stored[:chunk])
    assert plain / whole == pytest.approx(4.47 if order == "random" else 1.0, rel=0.1)
    # a 3000-point sample's median nearest-neighbour distance scatters by ~2 %
    assert _first_chunk_radius(path, chunk, n, mins, maxs) == pytest.approx(whole, rel=0.05)
