"""Per-vertex scale (radius="auto", meshcurv.scale): the radius each vertex chooses, the rows
it takes, and the radius_used field."""

import numpy as np
import pytest

import meshcurv
from meshcurv import scale, surfaces
from meshcurv.neighbors import default_radius
from meshcurv.result import CURVATURE_FIELDS, Status, curvature_fields, oriented_like


def _interior(surface, radius):
    return surface.border_distance >= radius


@pytest.fixture(scope="module")
def noisy_spheres():
    """A unit icosphere of 2562 vertices clean, with 0.05 % and with 0.3 % of the diagonal of
    noise along the normal: {sigma_fraction: (Surface, auto result)}."""
    clean = surfaces.sphere(1.0, 4)
    out = {}
    for noise in (0.0, 0.0005, 0.003):
        s = surfaces.add_normal_noise(clean, noise, seed=3) if noise else clean
        out[noise] = s, meshcurv.principal_curvatures(s.vertices, s.faces, radius="auto")
    return out


def test_ladder_is_around_the_default_radius():
    radii = scale.ladder(2.0)
    assert radii == pytest.approx([2.0 * 2 ** (j / 2) for j in (-1, 0, 1, 2, 3)])
    assert radii == sorted(radii)


def test_chosen_radius_grows_with_the_noise_on_a_sphere(noisy_spheres):
    # no bias on a sphere (every normal section is a circle): the noise alone sets the ball
    medians = [np.nanmedian(res.radius_used) for _, res in
               (noisy_spheres[n] for n in (0.0005, 0.003))]
    assert medians[1] > medians[0]
    s, res = noisy_spheres[0.003]
    r0 = default_radius(s.vertices, faces=s.faces)
    assert medians[1] > 1.9 * r0
    # and the error falls below the default radius' (all variance there: a larger ball helps)
    fixed = meshcurv.principal_curvatures(s.vertices, s.faces)
    err_auto = np.nanmean(np.abs(res.k1 - 1) + np.abs(res.k2 - 1))
    err_fixed = np.nanmean(np.abs(fixed.k1 - 1) + np.abs(fixed.k2 - 1))
    assert err_auto < 0.5 * err_fixed


def test_radius_used_lies_on_the_ladder_and_is_nan_where_invalid(noisy_spheres):
    s, res = noisy_spheres[0.003]
    radii = scale.ladder(res.radius)
    used = res.radius_used[res.valid]
    assert np.all(np.isin(used, radii))
    assert np.all(np.isnan(res.radius_used[~res.valid]))
    assert res.radius == pytest.approx(default_radius(s.vertices, faces=s.faces))


def test_clean_surfaces_keep_small_balls():
    # where the curvature varies (bias ~ r^2) and there is no noise, small balls win
    for s in (surfaces.torus(2.0, 0.5, 120, 30), surfaces.paraboloid(spacing=0.4)):
        res = meshcurv.principal_curvatures(s.vertices, s.faces, radius="auto")
        inner = _interior(s, 2 * res.radius) & res.valid
        assert inner.sum() > 100
        assert np.nanmedian(res.radius_used[inner]) <= res.radius * (1 + 1e-12)


def test_auto_rows_equal_the_run_at_the_chosen_radius():
    # auto's runs keep the normal field at each radius (Plan.wide_field): its ladder widens
    # the balls where the noise asks for it
    from meshcurv import pipeline
    from meshcurv.options import resolve_plan

    s = surfaces.add_normal_noise(surfaces.torus(2.0, 0.5, 120, 30), 0.002, seed=5)
    res = meshcurv.principal_curvatures(s.vertices, s.faces, radius="auto")
    radii = scale.ladder(res.radius)
    plan = resolve_plan(True, False)._replace(wide_field=False)
    runs = pipeline.run_radii(s.vertices, s.faces, None, radii, np.arange(len(s.vertices)),
                              plan)
    chosen = np.flatnonzero(res.valid)
    assert len(np.unique(res.radius_used[chosen])) >= 2       # the test compares something
    for r, run in zip(radii, runs):
        rows = chosen[res.radius_used[chosen] == r]
        for name in ("k1", "k2", "d1", "d2", "normals", "n_neighbors", "n_samples", "residual",
                     "noise", "status"):
            np.testing.assert_array_equal(getattr(res, name)[rows], getattr(run, name)[rows])


def test_auto_rows_keep_the_default_radius_orientation():
    # trimesh's coarse torus as a cloud: the ladder's smallest radius (0.37) oriented every
    # normal inward, and auto mixed its rows with outward ones (78 % of the signs wrong, mean
    # |dk| 1.66); each radius now re-orients along its fitted normals where its plane fits
    # misled the tree (test_orientation), and auto reads every radius' rows with the default
    # radius' normals
    import trimesh

    v = trimesh.creation.torus(2.0, 0.5).vertices
    res = meshcurv.principal_curvatures(v, radius="auto")
    base = meshcurv.principal_curvatures(v, radius=res.radius)
    assert res.valid.all() and np.all(np.einsum("ij,ij->i", res.normals, base.normals) > 0)
    rho = np.hypot(v[:, 0], v[:, 1])
    k1, k2 = np.full(len(v), 2.0), (rho - 2.0) / (0.5 * rho)
    assert np.mean(0.5 * (np.abs(res.k1 - k1) + np.abs(res.k2 - k2))) < 0.05
    run = meshcurv.principal_curvatures(v, radius=scale.ladder(res.radius)[0])
    assert np.all(np.einsum("ij,ij->i", run.normals, base.normals) > 0)


def test_oriented_like_turns_the_rows_facing_away():
    import trimesh

    run = meshcurv.principal_curvatures(trimesh.creation.torus(2.0, 0.5).vertices)
    reference = run.normals.copy()
    reference[::3] *= -1.0
    turned = oriented_like(run, reference)
    away = np.zeros(len(run), bool)
    away[::3] = True
    np.testing.assert_array_equal(turned.normals[away], -run.normals[away])
    np.testing.assert_array_equal(turned.k1[away], -run.k2[away])
    np.testing.assert_array_equal(turned.k2[away], -run.k1[away])
    np.testing.assert_array_equal(turned.d1[away], run.d2[away])
    np.testing.assert_array_equal(turned.d2[away], run.d1[away])
    for name in ("normals", "k1", "k2", "d1", "d2"):
        np.testing.assert_array_equal(getattr(turned, name)[~away], getattr(run, name)[~away])
    # read with inward normals the tube's k1 = 1 / 0.5 becomes k2 = -2
    assert np.all(np.abs(turned.k2[away] + 2.0) < 0.1)
    np.testing.assert_allclose(np.cross(turned.normals, turned.d1), turned.d2, atol=1e-12)
    assert oriented_like(run, run.normals) is run


def test_auto_rows_of_a_query_equal_those_of_the_whole_run():
    # each row's choice averages its nearest vertices' error terms: a query used to average
    # over the queried rows only (radius_used 0.51 where the whole run chose 0.72)
    p = surfaces.sphere(1.0, sampling="random", n=3000, seed=0).vertices
    v = p + 0.003 * np.random.default_rng(0).standard_normal(p.shape)
    full = meshcurv.principal_curvatures(v, radius="auto")
    # rows of two chosen radii, one of them twice
    values, counts = np.unique(full.radius_used[full.valid], return_counts=True)
    common = values[np.argsort(counts)[-2:]]
    q = np.concatenate([np.flatnonzero(full.radius_used == r)[[5, 0, 0, -1]] for r in common])
    part = meshcurv.principal_curvatures(v, radius="auto", query=q)
    for name in ("k1", "k2", "d1", "d2", "normals", "status", "radius_used", "noise"):
        np.testing.assert_array_equal(getattr(part, name), getattr(full, name)[q], err_msg=name)
    mask = np.zeros(len(v), dtype=bool)
    mask[q] = True
    part = meshcurv.principal_curvatures(v, radius="auto", query=mask)
    np.testing.assert_array_equal(part.radius_used, full.radius_used[np.sort(np.unique(q))])


def test_sparse_patch_gets_a_larger_ball():
    # a clean paraboloid sampled 16x more sparsely on one half: the default ball is widened
    # where it holds too few points (the sparse retry, 1.5x; the corrected default radius is
    # kept on clean data), and every row of the sparse half is estimated
    rng = np.random.default_rng(0)
    dense = rng.uniform(-1, 1, size=(12000, 2))
    dense = dense[dense[:, 0] < 0]
    sparse = rng.uniform(-1, 1, size=(800, 2))
    sparse = sparse[sparse[:, 0] >= 0]
    xy = np.vstack([dense, sparse])
    pts = np.column_stack([xy, 0.3 * (xy ** 2).sum(axis=1)])        # a gentle paraboloid
    res = meshcurv.principal_curvatures(pts, radius="auto")
    dense_in = (xy[:, 0] < -0.4) & (np.abs(xy[:, 1]) < 0.6)
    sparse_in = (xy[:, 0] > 0.4) & (np.abs(xy[:, 1]) < 0.6)
    assert np.nanmedian(res.radius_used[sparse_in]) > 1.4 * np.nanmedian(
        res.radius_used[dense_in])
    assert res.valid[sparse_in].mean() > 0.99


def test_clean_data_keep_the_corrected_default_without_running_the_ladder():
    """Where the bias correction is on at every row the result is the default radius' bit for
    bit and the ladder's other radii are never run; under noise they are."""
    calls = []

    def counting(v, f, normals, radii, query, plan, progress=False):
        calls.append(list(radii))
        return meshcurv.api._run_radii(v, f, normals, radii, query, plan, progress)

    s = surfaces.torus(2.0, 0.5, 240, 60)
    # the circle fits at the default radius (its default blends in the MLS surface, which
    # "auto" does not)
    fixed = meshcurv.principal_curvatures(s.vertices, s.faces, coarse_fit="circles")
    r0 = fixed.radius
    plan = meshcurv.options.resolve_plan(True, False)
    query = np.arange(len(s.vertices))
    res = scale.run_auto(s.vertices, s.faces, None, r0, query, plan, radii=scale.ladder(r0),
                         run_radii=counting)
    assert calls == [[r0]]
    assert scale.corrected_rows(fixed, plan).all()
    for name in ("k1", "k2", "d1", "d2", "normals", "valid", "status", "radius_used"):
        np.testing.assert_array_equal(getattr(res, name), getattr(fixed, name))
    noisy = surfaces.add_normal_noise(s, 0.002, seed=5)
    calls.clear()
    scale.run_auto(noisy.vertices, noisy.faces, None, r0, query, plan,
                   radii=scale.ladder(r0), run_radii=counting)
    assert len(calls) == 2 and sorted(calls[0] + calls[1]) == scale.ladder(r0)


def _result(k1, valid, n_neighbors, noise=0.0, radius=1.0):
    q = len(k1)
    k1 = np.where(valid, k1, np.nan)
    return meshcurv.CurvatureResult(
        k1=k1, k2=k1.copy(), d1=np.zeros((q, 3)), d2=np.zeros((q, 3)), normals=np.zeros((q, 3)),
        valid=np.asarray(valid), n_neighbors=np.full(q, n_neighbors, dtype=np.int32),
        n_samples=np.full(q, 16, dtype=np.int32), residual=np.zeros(q),
        noise=np.full(q, noise), radius=radius,
        status=np.where(valid, Status.OK, Status.TOO_FEW_HALF_SETS).astype(np.int8),
        radius_used=np.where(valid, radius, np.nan))


def test_invalid_rows_are_never_chosen_while_another_radius_has_an_estimate():
    q = 40
    pts = np.column_stack([np.arange(q, dtype=float), np.zeros(q), np.zeros(q)])
    rng = np.random.default_rng(1)
    radii = scale.ladder(1.0)
    valid = rng.uniform(size=(len(radii), q)) < 0.4
    valid[:, :3] = False                                          # no radius has one
    results = [_result(np.full(q, 0.1), valid[j], 30 * 2 ** j, noise=0.01, radius=r)
               for j, r in enumerate(radii)]
    choice = scale.select(results, radii, pts, fallback=1)
    has = valid.any(axis=0)
    assert np.all(valid[choice[has], np.flatnonzero(has)])
    assert np.all(choice[~has] == 1)
    out = scale.assemble(results, choice)
    assert np.all(out.valid == has)
    assert np.all(out.status[~has] == Status.TOO_FEW_HALF_SETS)
    assert np.all(np.isnan(out.radius_used[~has]))


def test_too_little_support_or_too_large_an_arc_is_avoided():
    q = 10
    pts = np.column_stack([np.arange(q, dtype=float), np.zeros(q), np.zeros(q)])
    radii = [1.0, 2.0, 4.0]
    ok = np.ones(q, dtype=bool)
    # the default radius 2 in the middle; the smallest ball holds 5 points (below
    # MIN_SUPPORT); the largest spans an arc of 0.5 x 4 = 2 rad (above MAX_ARC)
    results = [_result(np.full(q, 0.5), ok, 5, noise=0.0, radius=1.0),
               _result(np.full(q, 0.5), ok, 100, noise=0.0, radius=2.0),
               _result(np.full(q, 0.5), ok, 400, noise=0.0, radius=4.0)]
    assert np.all(scale.select(results, radii, pts, fallback=1) == 1)


def test_given_normal_noise_adds_its_variance_and_favours_larger_balls():
    """The variance term gains NORMAL_GAIN a2 / (r^2 N) with a2 the given normals' noise; with
    the same curvature at every radius (no bias) and clean points, noisy given normals make
    the largest admissible ball the choice, exact ones keep the default."""
    q = 12
    pts = np.column_stack([np.arange(q, dtype=float), np.zeros(q), np.zeros(q)])
    radii = [0.5, 1.0, 2.0]
    ok = np.ones(q, dtype=bool)
    results = [_result(np.full(q, 0.2), ok, n, noise=0.0, radius=r)
               for r, n in zip(radii, (25, 100, 400))]
    var0, _ = scale.error_terms(results, radii)
    var, _ = scale.error_terms(results, radii, normal_var=0.01)
    expected = scale.NORMAL_GAIN * 0.01 / (np.array(radii) ** 2 * [25, 100, 400])
    np.testing.assert_allclose(var - var0, np.repeat(expected[:, None], q, axis=1))
    assert np.all(scale.select(results, radii, pts, fallback=1, normal_var=0.01) == 2)
    # no variance at all: every radius ties at zero error and the first (smallest) is taken
    assert np.all(scale.select(results, radii, pts, fallback=1) == 0)


def test_fixed_radius_reports_it_per_row_and_writers_carry_radius_used():
    s = surfaces.sphere(1.0, 3)
    res = meshcurv.principal_curvatures(s.vertices, s.faces, radius=0.4)
    assert np.all(res.radius_used[res.valid] == 0.4)
    assert "radius_used" in CURVATURE_FIELDS
    np.testing.assert_array_equal(curvature_fields(res)["radius_used"], res.radius_used)


def test_cli_auto_writes_radius_used(tmp_path):
    from meshcurv import io
    from meshcurv.cli import main

    s = surfaces.add_normal_noise(surfaces.sphere(1.0, 4), 0.003, seed=3)
    src, dst = tmp_path / "in.xyz", tmp_path / "out.ply"
    np.savetxt(src, s.vertices)
    assert main(["annotate", str(src), "-o", str(dst), "--radius", "auto"]) == 0
    used = np.asarray(io.read(dst).fields["radius_used"])
    res = meshcurv.principal_curvatures(s.vertices, radius="auto")
    np.testing.assert_allclose(used, res.radius_used, equal_nan=True)
    assert np.nanmax(used) > np.nanmin(used) or np.nanmin(used) > res.radius


def test_tiled_cli_refuses_auto_in_one_line(tmp_path, capsys):
    from meshcurv.cli import main

    src = tmp_path / "in.laz"
    code = main(["annotate", str(src), "-o", str(tmp_path / "out.laz"), "--radius", "auto",
                 "--tile-size", "10"])
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert "--radius auto" in err and len(err.splitlines()) == 1


@pytest.mark.parametrize("with_faces", [False, True])
def test_ladder_stops_where_the_balls_reach_around_a_thin_tube(with_faces):
    # a tube of radius 0.1 (curvature 10): balls of curvature x radius 0.6 - 1.2 are patches,
    # at 2.4 they hold the tube's whole section (flatness near 1), far fewer than a quarter of
    # the points all the same
    from meshcurv.neighbors.radius import local_radii

    tube = surfaces.cylinder(0.1, height=8.0, n_around=64)
    radii = [0.06, 0.085, 0.12, 0.24, 0.34]
    points = tube.vertices
    if not with_faces:
        rng = np.random.default_rng(3)
        points = points + rng.normal(scale=1e-4, size=points.shape)   # not a grid
    faces = tube.faces if with_faces else None
    assert local_radii(points, radii, faces) == radii[:3]


def test_ladder_keeps_the_radii_of_noisy_flat_balls():
    # noise makes small balls thick (flatness ~ 4 sigma^2 / r^2, above PATCH_FLATNESS at the
    # smallest radius here) and thinner as they grow: nothing is beyond a patch
    from meshcurv.neighbors.radius import PATCH_FLATNESS, _grid_balls, local_radii

    rng = np.random.default_rng(4)
    points = np.column_stack([rng.uniform(0, 1, (20000, 2)), rng.normal(scale=0.01, size=20000)])
    radii = [0.02 * 2 ** (j / 2) for j in range(5)]
    assert _grid_balls(points)(radii[0])[0] > PATCH_FLATNESS
    assert local_radii(points, radii) == radii


def test_ladder_stops_before_balls_of_a_quarter_of_the_points():
    from meshcurv.neighbors.radius import local_radii

    rng = np.random.default_rng(5)
    points = np.column_stack([rng.uniform(0, 1, (400, 2)), np.zeros(400)])
    # a flat square: balls of radius 0.45 hold about half of it
    assert local_radii(points, [0.1, 0.2, 0.45, 0.6]) == [0.1, 0.2]


def test_auto_ladder_of_a_large_cloud_is_measured_at_its_own_radii():
    # the ladder's limit came from a radius holding a quarter of the points, measured with
    # balls that large (57 s and 8.9 GB at 100k points); its own balls hold ~50 - 800 points.
    # Here the largest, 0.49, is a patch of the tube (curvature x radius 0.99)
    from meshcurv.api import _auto_ladder

    v = surfaces.torus(2.0, 0.5, 400, 100).vertices
    r0 = default_radius(v)
    assert _auto_ladder(v, None, r0) == scale.ladder(r0)
    assert 0.48 < max(scale.ladder(r0)) < 0.5
