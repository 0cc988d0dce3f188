"""Point-level robustness: stray points (scanner spikes) are scored by the outlier pass
(meshcurv.fit.outliers, held to its numpy specification), left out of their neighbors' fits,
and flagged; clean surfaces lose nothing."""

import numpy as np
import pytest

import meshcurv
from meshcurv import surfaces
from meshcurv.fit import fused, fused_spec, jet, jet_spec, outliers, outliers_spec
from meshcurv.fit.constants import OUTLIER_TRUSTED, TUKEY_C
from meshcurv.normals import pca_normals
from meshcurv.result import CURVATURE_FIELDS, Status, curvature_fields

from neighbor_lists import ball_csr


def with_spikes(surface, noise, fraction, seed):
    """``(vertices, spikes)``: ``surface`` with Gaussian noise along the normals (``noise`` of
    the diagonal) and ``fraction`` of its vertices pushed out or in along the normal by 1-4 %
    of the diagonal; ``spikes`` (n,) bool marks them."""
    s = surfaces.add_normal_noise(surface, noise, seed=seed) if noise else surface
    rng = np.random.default_rng(seed + 1)
    n = len(s.vertices)
    idx = rng.choice(n, int(round(fraction * n)), replace=False)
    push = rng.uniform(0.01, 0.04, len(idx)) * rng.choice([-1.0, 1.0], len(idx))
    v = s.vertices.copy()
    v[idx] += (push * s.diagonal)[:, None] * s.normals[idx]
    spikes = np.zeros(n, bool)
    spikes[idx] = True
    return v, spikes


def errors(res, surface, rows):
    """``(mean |dk| over k1 and k2, fraction of rows off by more than 10 %)``: invalid rows count
    as off; the relative error is the larger of |dk1|, |dk2| over the larger |k|."""
    e1 = np.abs(res.k1[rows] - surface.k1[rows])
    e2 = np.abs(res.k2[rows] - surface.k2[rows])
    scale = np.maximum(np.abs(surface.k1[rows]), np.abs(surface.k2[rows]))
    rel = np.maximum(e1, e2) / scale
    return float(np.nanmean(np.concatenate([e1, e2]))), float(np.mean(~(rel <= 0.1)))


def test_point_residuals_match_the_numpy_specification():
    """Kernel and specification agree to round-off on a noisy torus with spikes, at radii whose
    balls hold plane-, quadric- and cubic-sized neighborhoods (and too few points: NaN)."""
    s = surfaces.torus(n_major=80, n_minor=24)
    v, _ = with_spikes(s, 5e-4, 0.03, seed=3)
    orders = set()
    for radius in (0.12, 0.2, 0.3, 0.45):
        indptr, indices = ball_csr(v, radius)
        residual, scale, dof = (np.empty(len(v)) for _ in range(3))
        outliers.point_residuals(v, v, indptr, indices, radius, residual, scale, dof)
        for i in range(0, len(v), 17):
            nbr = v[indices[indptr[i]:indptr[i + 1]]]
            ref = outliers_spec.point_residual(v[i], nbr, radius)
            assert residual[i] == pytest.approx(ref[0], rel=1e-8, abs=1e-12, nan_ok=True)
            assert scale[i] == pytest.approx(ref[1], rel=1e-8, nan_ok=True)
            assert dof[i] == ref[2]
            orders.add(outliers.model_terms(len(nbr) - 1))
    assert orders >= {0, 3, 6, 10}


def test_a_fit_that_leaves_out_much_of_the_neighborhood_judges_nothing():
    # trimesh's 32 x 12 torus 1 / 0.3 at radius 0.34: a top-ring vertex's 10 neighbors are its
    # two ring neighbors (as high as itself) and 6 below, 2 further down. The robust plane fit
    # kept the 6 (residual 0), left out 4 and read the vertex 0.12 radii off at a scale of
    # 0.001 (score 6.7): its whole ring flagged as spikes. A fit leaving out more than
    # OUTLIER_MAX_REJECTED of the neighbors gives no score (weight 1, not flagged)
    import trimesh

    t = trimesh.creation.torus(1.0, 0.3, major_sections=32, minor_sections=12)
    v = np.asarray(t.vertices)
    top = np.flatnonzero(np.isclose(v[:, 2], 0.3))
    radius = 0.3379
    indptr, indices = ball_csr(v, radius)
    residual, scale, dof = (np.empty(len(v)) for _ in range(3))
    outliers.point_residuals(v, v, indptr, indices, radius, residual, scale, dof)
    assert len(top) == 32 and np.isnan(residual[top]).all() and (dof[top] == 0).all()
    ref = outliers_spec.point_residual(v[top[0]], v[indices[indptr[top[0]]:indptr[top[0] + 1]]],
                                       radius)
    assert np.isnan(ref[0]) and ref[2] == 0
    # the rows of the tube's sides are judged (fits of all their neighbors), none an outlier
    score = outliers.outlier_score(residual, scale, dof)
    side = np.isfinite(score)
    assert side.sum() >= len(v) - 2 * len(top) and (score[side] < OUTLIER_TRUSTED).all()


def test_clean_neighborhoods_stop_after_the_least_squares_start():
    """On a clean torus (~46 points per ball, cubic fits) no residual reaches TUKEY_C scales
    (the scale is floored above them), so the reweighting rounds are skipped: the same bits as
    no rounds at all, and the specification's. A spike in a ball keeps its rounds: those rows
    differ from the plain least-squares fit. (Where the cubic leaves residuals of its own above
    the floor, e.g. a sphere at radius 0.5, 30 % of the balls still run their rounds.)"""
    s = surfaces.torus(n_major=240, n_minor=60)
    radius = 0.2
    indptr, indices = ball_csr(s.vertices, radius)
    runs = []
    for iterations in (0, 3):
        out = tuple(np.empty(len(s.vertices)) for _ in range(3))
        outliers.point_residuals(s.vertices, s.vertices, indptr, indices, radius, *out,
                                 iterations=iterations)
        runs.append(out)
    for a, b in zip(*runs):
        np.testing.assert_array_equal(a, b)
    for i in range(0, len(s.vertices), 331):
        ref = outliers_spec.point_residual(s.vertices[i],
                                           s.vertices[indices[indptr[i]:indptr[i + 1]]], radius)
        assert runs[1][0][i] == pytest.approx(ref[0], rel=1e-8, abs=1e-12)
        assert runs[1][1][i] == pytest.approx(ref[1], rel=1e-8)
    v, spikes = with_spikes(s, 0.0, 0.01, seed=5)
    indptr, indices = ball_csr(v, radius)
    # rows other than the spikes with a spike in their ball
    near = np.add.reduceat(spikes[indices].astype(int), indptr[:-1]) > 0
    near[spikes] = False
    scales = []
    for iterations in (0, 3):
        out = tuple(np.empty(len(v)) for _ in range(3))
        outliers.point_residuals(v, v, indptr, indices, radius, *out, iterations=iterations)
        scales.append(out[1])
    assert np.mean(scales[0][near] != scales[1][near]) > 0.9
    np.testing.assert_array_equal(scales[0][~near & ~spikes], scales[1][~near & ~spikes])


def test_scores_of_gaussian_noise_stay_below_the_cutoff_in_small_and_large_balls():
    """A noisy plane sampled at random, balls of 6 to 60 points: at most one point in a
    thousand flagged (measured <= 3.5e-4 in 9-30 point balls, none beyond). The raw ratio of
    residual to MAD scale would flag 3 % of the points of 6-8 point balls, 0.1 % at 30-60."""
    rng = np.random.default_rng(6)
    for per_ball in (8, 15, 60):
        n = 6000
        side = np.sqrt(n * np.pi / per_ball)
        p = np.column_stack([rng.uniform(0, side, (n, 2)), rng.normal(scale=0.01, size=n)])
        indptr, indices = ball_csr(p, 1.0)
        residual, scale, dof = (np.empty(n) for _ in range(3))
        outliers.point_residuals(p, p, indptr, indices, 1.0, residual, scale, dof)
        score = outliers.outlier_score(residual, scale, dof)
        assert np.isfinite(score).mean() > 0.75      # balls of fewer than 6 points: no score
        assert np.mean(score >= TUKEY_C) <= 1e-3
        # the t-calibrated score is below the raw ratio, and equal to it for many residuals
        assert np.all(score[np.isfinite(score)] <= (residual / scale)[np.isfinite(score)] + 1e-9)
    assert outliers.outlier_score([1.0], [1.0], [1e9])[0] == pytest.approx(1.0, rel=1e-6)


def test_outlier_weight_is_one_within_the_noise_then_redescends_to_zero():
    half = (OUTLIER_TRUSTED + TUKEY_C) / 2
    w = outliers.outlier_weight([0.0, OUTLIER_TRUSTED, half, TUKEY_C, 2 * TUKEY_C, np.nan])
    np.testing.assert_allclose(w, [1.0, 1.0, 0.5625, 0.0, 0.0, 1.0])


def test_weighted_kernels_match_their_specifications():
    """Jet, circle fits and plane fits with per-point weights (a tenth of them 0) agree with the
    numpy specifications given the same weights."""
    rng = np.random.default_rng(4)
    s = surfaces.torus(n_major=100, n_minor=30)
    v = s.vertices + rng.normal(scale=0.005, size=(len(s.vertices), 1)) * s.normals
    weights = np.where(rng.random(len(v)) < 0.1, 0.0, rng.uniform(0.2, 1.0, len(v)))
    radius = 0.4
    indptr, indices = ball_csr(v, radius)
    m = len(v)
    refined, noise = s.normals.copy(), np.empty(m)
    jet.local_jet(v, v, refined, indptr, indices, radius, True, noise, weights)
    out = (np.empty(m), np.empty(m), np.empty((m, 3)), np.empty((m, 3)), np.empty(m),
           np.empty(m), np.empty(m), np.empty(m, dtype=np.int8))
    fit = (8, 0.25, 3.0, 0.25, False, True, False, True)
    fused.curvature_cga(v, v, s.normals, indptr, indices, radius, np.full(m, 0.6), fit, out,
                        None, point_weights=weights)
    planes = pca_normals(v, v, indptr, indices, radius, weights)
    checked = 0
    for i in range(0, m, 11):
        rows = indices[indptr[i]:indptr[i + 1]]
        normal, nz = jet_spec.local_jet(v[i], s.normals[i], v[rows], radius, weights[rows])
        np.testing.assert_allclose(refined[i], normal, atol=1e-9)
        assert noise[i] == pytest.approx(nz, rel=1e-9)
        ref = fused_spec.curvature_at_point(v[i], s.normals[i], v[rows], radius, blend=0.6,
                                            point_weights=weights[rows])
        assert out[0][i] == pytest.approx(ref["k1"], rel=1e-9, nan_ok=True)
        assert out[1][i] == pytest.approx(ref["k2"], rel=1e-9, nan_ok=True)
        # the weighted plane through the neighbors and x (weight 1)
        keep = rows[(rows != i) & (weights[rows] > 0)]
        pts = np.vstack([v[i], v[keep]])
        w = np.concatenate([[1.0], weights[keep]])
        mean = w @ pts / w.sum()
        ref_n = np.linalg.eigh((w[:, None] * (pts - mean)).T @ (pts - mean))[1][:, 0]
        assert abs(planes[i] @ ref_n) == pytest.approx(1.0, abs=1e-9)
        checked += np.isfinite(out[0][i])
    assert checked > 150


def test_weight_zero_is_the_same_as_leaving_the_point_out():
    """A neighbor of weight 0 changes no fit: as if it were not in the lists at all."""
    s = surfaces.sphere(subdivisions=3)
    v, spikes = with_spikes(s, 5e-4, 0.05, seed=5)
    radius = 0.45
    indptr, indices = ball_csr(v, radius)
    weights = np.where(spikes, 0.0, 1.0)
    kept = ~spikes[indices]
    indptr_kept = np.concatenate([[0], np.cumsum(np.add.reduceat(kept, indptr[:-1]))])
    m = len(v)
    results = []
    for ip, ind, w in ((indptr, indices, weights), (indptr_kept, indices[kept], None)):
        normals, noise = s.normals.copy(), np.empty(m)
        jet.local_jet(v, v, normals, ip, ind, radius, True, noise, w)
        out = (np.empty(m), np.empty(m), np.empty((m, 3)), np.empty((m, 3)), np.empty(m),
               np.empty(m), np.empty(m), np.empty(m, dtype=np.int8))
        fused.curvature_cga(v, v, normals, ip, ind, radius, np.full(m, 0.5),
                            (8, 0.25, 3.0, 0.25, False, True, False, True), out, None,
                            point_weights=w)
        results.append((noise, out[0], out[1], pca_normals(v, v, ip, ind, radius, w)))
    for a, b in zip(*results):
        np.testing.assert_allclose(np.abs(a), np.abs(b), rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("mesh", [True, False], ids=["mesh", "cloud"])
@pytest.mark.parametrize("name", ["sphere", "torus"])
def test_spikes_do_not_move_their_neighbors_curvature(name, mesh):
    """2 % of the vertices pushed 1-4 % of the diagonal off a surface with 0.05 % noise: the
    spikes are flagged, and the other 98 % keep about the accuracy they have without spikes.

    Sphere (~60 neighbors, spikes 0.1-0.5 radius off): the issue's targets, <= 2 % of the good
    vertices off by more than 10 % and mean |dk| <= 0.5 x MeshLab APSS's 0.058; without the
    outlier pass 45 % are off. Torus (~44 neighbors, spikes up to 0.95 radius off, where a
    spike's ball holds a thin cap of ~10 points and 10 % of them go unflagged): at most 2
    points more in a hundred off than without spikes and 1.3x the mean error (measured 1.7
    points, 1.22x); without the outlier pass 27 % are off and the error triples.
    """
    if name == "sphere":
        s, radius = surfaces.sphere(subdivisions=4), 0.3
    else:
        s, radius = surfaces.torus(n_major=160, n_minor=40), 0.3
    v, spikes = with_spikes(s, 5e-4, 0.02, seed=11)
    noisy_v = surfaces.add_normal_noise(s, 5e-4, seed=11).vertices
    faces = s.faces if mesh else None
    res = meshcurv.principal_curvatures(v, faces, radius=radius)
    noisy = meshcurv.principal_curvatures(noisy_v, faces, radius=radius)
    good = ~spikes
    mean, off = errors(res, s, good)
    mean_noisy, off_noisy = errors(noisy, s, good)
    if name == "sphere":
        assert off <= 0.02
        assert mean <= 0.5 * 0.058
        assert mean <= 1.05 * mean_noisy
        assert np.all(res.status[spikes] == Status.OUTLIER)
    else:
        assert off <= off_noisy + 0.02
        assert mean <= 1.3 * mean_noisy
        assert np.mean(res.status[spikes] == Status.OUTLIER) >= 0.85
    flagged = res.status == Status.OUTLIER
    assert not res.valid[flagged].any() and np.all(np.isnan(res.k1[flagged]))
    assert np.mean(flagged[good]) <= 1e-3
    # the spikes' scores are far beyond the cutoff, the good vertices' within the noise
    assert np.nanmedian(res.outlier_score[spikes]) > 1.5 * TUKEY_C
    assert np.nanpercentile(res.outlier_score[good], 99) < 0.75 * TUKEY_C


@pytest.mark.parametrize("name", ["sphere", "torus", "paraboloid"])
def test_clean_surfaces_lose_nothing(name):
    """Clean samples: no point is flagged and every weight is 1, so the results are exactly
    those without the outlier pass."""
    if name == "sphere":
        s, radius = surfaces.sphere(sampling="random", n=4000, seed=2), 0.3
    elif name == "torus":
        s, radius = surfaces.torus(n_major=120, n_minor=30), 0.3
    else:
        s, radius = surfaces.paraboloid(extent=3.0, spacing=0.1), 1.0
    for faces in (s.faces, None):
        res = meshcurv.principal_curvatures(s.vertices, faces, radius=radius)
        plain = meshcurv.principal_curvatures(s.vertices, faces, radius=radius,
                                              robust_points=False)
        assert not np.any(res.status == Status.OUTLIER)
        assert np.nanmax(res.outlier_score) < OUTLIER_TRUSTED
        assert np.all(np.isnan(plain.outlier_score))
        for name in ("k1", "k2", "d1", "normals", "noise", "status"):
            np.testing.assert_array_equal(getattr(res, name), getattr(plain, name))


def test_a_few_queries_score_only_their_neighborhoods_and_agree():
    """Estimates at a few query points use the scores of their neighbors only, and equal the
    rows of the full run."""
    s = surfaces.sphere(subdivisions=4)
    v, spikes = with_spikes(s, 5e-4, 0.02, seed=7)
    full = meshcurv.principal_curvatures(v, radius=0.3, orientation=(0, 0, 0))
    query = np.flatnonzero(spikes)[:5].tolist() + [0, 1, 2, 3, 4]
    part = meshcurv.principal_curvatures(v, radius=0.3, orientation=(0, 0, 0), query=query)
    np.testing.assert_array_equal(part.status, full.status[query])
    np.testing.assert_allclose(part.outlier_score, full.outlier_score[query], rtol=1e-12)
    np.testing.assert_allclose(part.k1, full.k1[query], rtol=1e-12)


def test_the_outlier_score_is_a_written_field():
    s = surfaces.sphere(subdivisions=2)
    res = meshcurv.principal_curvatures(s.vertices, s.faces, radius=0.5)
    assert "outlier_score" in CURVATURE_FIELDS
    fields = curvature_fields(res)
    assert list(fields) == list(CURVATURE_FIELDS)
    np.testing.assert_array_equal(fields["outlier_score"], res.outlier_score)
