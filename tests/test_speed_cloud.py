"""The cloud path and meshes without normals search each neighborhood once before the
curvature blocks (outlier scores and the spanning tree's or plane-fit normals from the same
lists; a cloud's normal field then over its wider ball), with results equal bit for bit to
separate passes; the area weights of the orientation in one compiled pass equal their numpy
specification."""

import numpy as np
import pytest

import meshcurv
from meshcurv import pipeline, surfaces
from meshcurv.normals.orient import sample_areas
from meshcurv.normals.orient_spec import sample_area


def _counting(monkeypatch):
    """Patch the searches to count the query points whose lists they build."""
    searched = []
    for name in ("ball_search", "kring_search"):
        make = getattr(pipeline, name)

        def counted(*args, make=make):
            search = make(*args)

            def neighbors(idx):
                searched.append(len(idx))
                return search.neighbors(idx)
            return search._replace(neighbors=neighbors)
        monkeypatch.setattr(pipeline, name, counted)
    return searched


@pytest.mark.parametrize("faces", [False, True])
def test_clean_torus_lists_are_searched_once_per_radius_before_the_blocks(monkeypatch, faces):
    # outlier pass (with the tree's or the plane-fit normals) + curvature blocks, and refits
    # of the few points near down-weighted ones; a cloud's normal field has its own, wider
    # ball (pipeline.FIELD_RATIO) and pass, and its mix one more (the means over each ball of
    # the split-half fits, which come with the outlier pass: pipeline.field_mix). Before,
    # the normals had a pass of their own at the radius too (one pass more). A mesh first
    # measures on a sample of 2048 vertices whether it is noisy enough for the wide field
    # (pipeline.WIDE_FIELD_GAIN): this fine one is not
    t = surfaces.torus(n_major=200, n_minor=50)
    searched = _counting(monkeypatch)
    res = meshcurv.principal_curvatures(t.vertices, t.faces if faces else None, radius=0.3)
    passes = 2 if faces else 4
    assert passes * len(t.vertices) <= sum(searched) < (passes + 0.75) * len(t.vertices)
    assert np.all(res.valid)


def test_fused_pass_equals_separate_passes():
    # outlier_scores and mst_normals run one after the other give the same bits as the pass
    # that serves both
    rng = np.random.default_rng(4)
    t = surfaces.torus(n_major=60, n_minor=20)
    v = t.vertices + rng.normal(0.0, 0.003, t.vertices.shape)
    finite = np.arange(len(v))
    search = pipeline.ball_search(v, finite, 0.3)
    plan = meshcurv.options.resolve_plan(False, False)
    score, tree, plain, halves = pipeline._outlier_pass(v, None, 0.3, search, finite, plan,
                                                        False, pipeline.BLOCK, None,
                                                        split=True)
    separate = pipeline.outlier_scores(v, 0.3, search, finite, False)
    normals, note = pipeline.mst_normals(v, 0.3, search, False)
    indptr, indices = search.neighbors(finite)
    split = pipeline.split_disagreement(search.points, v, indptr, indices, 0.3)
    assert np.array_equal(score, separate, equal_nan=True)
    assert np.array_equal(tree[0], normals, equal_nan=True) and tree[1] == note
    assert np.array_equal(halves, split, equal_nan=True)


def test_weighted_field_refits_only_near_down_weighted_points():
    # the plane-fit field with outlier weights from the unweighted one plus the refits within
    # the radius of the few down-weighted points equals the field fitted everywhere
    rng = np.random.default_rng(6)
    t = surfaces.torus(n_major=80, n_minor=25)
    v = t.vertices.copy()
    spikes = rng.choice(len(v), 5, replace=False)
    v[spikes] += 0.05 * t.normals[spikes]
    finite = np.arange(len(v))
    search = pipeline.kring_search(v, t.faces, 0.3)
    plan = meshcurv.options.resolve_plan(True, False)
    assert plan.normals == "pca" and plan.normal_constraints
    face_normals = meshcurv.normals.face_vertex_normals(v, t.faces)
    score, _, plain, _ = pipeline._outlier_pass(v, t.faces, 0.3, search, finite, plan, False,
                                             pipeline.BLOCK, face_normals)
    weights = meshcurv.fit.outliers.outlier_weight(score)
    light = np.flatnonzero(weights < 1.0)
    assert 0 < len(light) < 50
    near = pipeline._near_points(v, v[light], finite, 0.3)
    assert len(near) < len(v) // 4
    full = pipeline._pca_field(v, face_normals, search, None, 0.3, plan, False, weights)
    fast = pipeline._pca_field(v, face_normals, search, None, 0.3, plan, False, weights,
                               plain.copy())     # filled in place
    assert np.array_equal(fast, full, equal_nan=True)
    # and the weights changed something: the refits were needed
    assert not np.array_equal(plain, full, equal_nan=True)


@pytest.mark.parametrize("n, k", [(5000, 10), (300, 3), (7, 1)])
def test_sample_areas_kernel_equals_its_numpy_specification(n, k):
    rng = np.random.default_rng(n)
    p = rng.normal(size=(n, 3)) * rng.lognormal(0.0, 2.0, size=(n, 1))
    nb = rng.integers(-1, n, size=(n, k)).astype(np.int32)
    got = sample_areas(p, nb)
    assert np.array_equal(got, sample_area(p, nb))
    # measured on points * scale: a power of two scales the squares exactly
    assert np.array_equal(sample_areas(p, nb, 0.3), sample_area(p, nb, 0.3))
    assert np.array_equal(sample_areas(p, nb, 2.0 ** -20), got * 2.0 ** -40)
    # exact values: the farthest graph neighbor's squared distance, 0 without neighbors
    i = int(np.flatnonzero((nb >= 0).any(axis=1))[0])
    j = nb[i][nb[i] >= 0]
    assert got[i] == pytest.approx(np.max(np.sum((p[j] - p[i]) ** 2, axis=1)), rel=1e-15)
    assert np.all(got[(nb < 0).all(axis=1)] == 0.0)


def test_fits_made_without_the_outlier_weights_are_redone_exactly_where_they_count(
        monkeypatch):
    # the unweighted plane fits and split halves of the outlier pass are fitted again only
    # near down-weighted points (pipeline._refit_rows): on a clean cloud with a few spikes,
    # fitting every point again with the weights must give the same result bit for bit
    # (oriented towards +z the plane fits are also the frames' normals; not refitting them
    # at all moves k1 by up to 2 here)
    s = surfaces.sphere(sampling="random", n=3000, seed=4)
    v = s.vertices.copy()
    spikes = np.arange(0, 3000, 600)
    v[spikes] *= 1.05
    fast = meshcurv.principal_curvatures(v, radius=0.25, orientation="+z")
    with monkeypatch.context() as m:
        m.setattr(pipeline, "_refit_rows", lambda *args: None)
        full = meshcurv.principal_curvatures(v, radius=0.25, orientation="+z")
    assert np.all(fast.outlier_score[spikes] > 2.0)
    for a, b in ((fast.k1, full.k1), (fast.k2, full.k2), (fast.normals, full.normals)):
        np.testing.assert_array_equal(a, b)
