"""Balls that reach around the surface (meshcurv.fit.wrap): the kernel against its numpy
specification, and rows marked WRAPS_AROUND, with no estimate, only where the ball reaches
a third of the way around a tube or sphere - not across a thin sheet, which the fits cope
with."""

import numpy as np
import pytest

import meshcurv
from meshcurv import surfaces
from meshcurv.result import Status
from meshcurv.fit import wrap, wrap_spec

from neighbor_lists import ball_csr


def test_folding_weight_matches_numpy_reference():
    """A torus's tube (minor radius 0.4) in balls of 0.9, normals with noise, a NaN normal, a
    flipped one, point weights: every row as the spec."""
    rng = np.random.default_rng(7)
    s = surfaces.torus(3.0, 0.4, 120, 24)
    normals = s.normals + rng.normal(scale=0.1, size=s.normals.shape)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[5] = np.nan
    normals[30] *= -1.0
    weights = rng.uniform(0.0, 1.0, len(s.vertices))
    rows = np.arange(0, len(s.vertices), 11)
    indptr, indices = ball_csr(s.vertices, 0.9, s.vertices[rows])
    got = wrap.folding_weight(s.vertices, normals, s.vertices[rows], normals[rows], indptr,
                               indices, 0.9, weights)
    assert got.max() > 10.0
    for q, i in enumerate(rows):
        nbrs = indices[indptr[q]:indptr[q + 1]]
        expected = wrap_spec.folding_weight(s.vertices[i], normals[i], s.vertices[nbrs],
                                            normals[nbrs], 0.9, weights[nbrs])
        assert got[q] == pytest.approx(expected, rel=1e-12, abs=1e-12)


def test_a_flipped_neighbor_beside_the_point_is_not_the_far_side():
    """A plane whose normals a failed orientation flipped on one half, with a bend of 90
    degrees in it: no folding counted."""
    x, y = np.meshgrid(np.linspace(-1, 1, 21), np.linspace(-1, 1, 21))
    v = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    n[v[:, 0] > 0] *= -1.0
    n[np.abs(v[:, 0] - 0.5) < 0.01] = [1.0, 0.0, 0.0]
    indptr, indices = ball_csr(v, 0.5)
    assert not wrap.folding_weight(v, n, v, n, indptr, indices, 0.5).any()


@pytest.mark.parametrize("faces", [True, False], ids=["mesh", "cloud"])
def test_balls_past_a_third_of_the_tube_are_marked_and_smaller_ones_are_not(faces):
    """Torus 3 / 0.4, 300 x 24 vertices. At 1.2 and 1.6 times the tube's radius (the ball
    reaching 74 and 106 degrees around it) every row keeps its estimate (mean |dk| / k1
    measured 0.0002 and 0.006); at 2 and 2.4 (the whole section) every row is WRAPS_AROUND,
    where the estimate was 0.11 k1 off (0.056 for k1 = 2.5 at 2.4 r, all marked valid). The
    cloud at 2.4 r, whose plane-fit normals are anything there, is marked by its balls'
    flatness (71 % of its rows kept before, 0.88 k1 off)."""
    s = surfaces.torus(3.0, 0.4, 300, 24)
    f = s.faces if faces else None
    for factor in (1.2, 1.6):
        res = meshcurv.principal_curvatures(s.vertices, f, radius=factor * 0.4)
        assert res.valid.all()
        assert np.mean(np.abs(res.k1 - s.k1)) < 0.03 * 2.5
    for factor in (2.0, 2.4):
        res = meshcurv.principal_curvatures(s.vertices, f, radius=factor * 0.4,
                                            sparse_retry=False)
        assert np.all(res.status == Status.WRAPS_AROUND)
        assert not res.valid.any() and np.isnan(res.k1).all()
        # by default a mesh's rows are served by half the ball, as a call at that radius
        # serves them; a cloud's plane-fit normals leave the smaller balls unchecked (see
        # test_smaller_balls_serve_what_wraps_around): no estimate
        res = meshcurv.principal_curvatures(s.vertices, f, radius=factor * 0.4)
        if not faces:
            assert np.all(res.status == Status.WRAPS_AROUND)
            continue
        half = meshcurv.principal_curvatures(s.vertices, f, radius=factor * 0.2)
        assert res.valid.all() and np.all(res.radius_used == factor * 0.2)
        assert res.radius == factor * 0.4
        for name in ("k1", "k2", "d1", "d2", "normals", "noise", "n_neighbors"):
            assert np.array_equal(getattr(res, name), getattr(half, name)), name


def test_a_sphere_smaller_than_the_ball_is_marked_and_a_thin_sheet_is_not():
    """An icosphere of radius 0.3 in balls of 0.54 (1.8 r: 128 degrees around): every row
    marked. Two flat sheets 0.1 apart, facing away, in balls of 0.3 with their normals: far
    sides without a bend between them; every row keeps its exact estimate (k = 0)."""
    s = surfaces.sphere(0.3, 4)
    res = meshcurv.principal_curvatures(s.vertices, s.faces, radius=0.54, sparse_retry=False)
    assert np.all(res.status == Status.WRAPS_AROUND)
    x, y = (a.ravel() for a in np.meshgrid(np.linspace(-1, 1, 41), np.linspace(-1, 1, 41)))
    v = np.concatenate([np.column_stack([x, y, np.full_like(x, 0.05)]),
                        np.column_stack([x, y, np.full_like(x, -0.05)])])
    n = np.concatenate([np.tile([0.0, 0.0, 1.0], (len(x), 1)),
                        np.tile([0.0, 0.0, -1.0], (len(x), 1))])
    res = meshcurv.principal_curvatures(v, normals=n, radius=0.3)
    assert res.valid.all()
    inner = (np.abs(v[:, 0]) < 0.6) & (np.abs(v[:, 1]) < 0.6)
    assert np.abs(res.k1[inner]).max() < 1e-9 and np.abs(res.k2[inner]).max() < 1e-9


@pytest.mark.parametrize("sigma", [0.1, 0.25])
def test_a_ball_of_noise_is_no_fold(sigma):
    """A square of 40k random points with Gaussian heights of ``sigma`` (a fifth and half of
    the radius 0.5; balls of ~800 points, whose flatness the noise takes to 0.16 and 1): the
    flatness rises as the balls shrink and their width falls, so no row a radius from the
    border is beyond a cap (at the border, where the noise is as wide as the half-ball,
    measured 3 and 1 rows of 40k). Poles of radius 0.1 in balls of 0.44 and a tube's ball at
    2.4 times its radius, whose width stays or whose flatness falls, are."""
    rng = np.random.default_rng(3)
    p = np.column_stack([rng.uniform(-3, 3, (40_000, 2)), rng.normal(scale=sigma, size=40_000)])
    indptr, indices = ball_csr(p, 0.5)
    marked = wrap.beyond_a_cap(p, p, indptr, indices, 0.5)
    inside = np.abs(p[:, :2]).max(axis=1) < 2.5
    assert not marked[inside].any() and marked.sum() <= 10
    t = rng.uniform(0.0, 2.0 * np.pi, 3000)
    pole = np.column_stack([0.1 * np.cos(t), 0.1 * np.sin(t), rng.uniform(0.0, 6.0, 3000)])
    middle = np.flatnonzero(np.abs(pole[:, 2] - 3.0) < 2.0)
    indptr, indices = ball_csr(pole, 0.44, pole[middle])
    assert wrap.beyond_a_cap(pole, pole[middle], indptr, indices, 0.44).all()
    s = surfaces.torus(3.0, 0.4, 300, 24)
    indptr, indices = ball_csr(s.vertices, 0.96, s.vertices[::50])
    assert wrap.beyond_a_cap(s.vertices, s.vertices[::50], indptr, indices, 0.96).all()


def test_the_sparse_retrys_wider_balls_are_tested_too():
    """A torus 3 / 0.08 of 300 x 8 points beside a plane 100 times denser, exact normals: the
    default radius (0.056, the plane's) holds too few of the tube's points, and the retry's
    first ball that holds enough, 3 times wider, holds the tube's whole section (2.1 times its
    radius). Those rows were served from it (k1 4.6 % off, all valid); now the ball is folded
    as at the call's own radius, and the rows keep the reason they had (TOO_FEW_NEIGHBORS)."""
    t = surfaces.torus(3.0, 0.08, 300, 8)
    x, y = np.meshgrid(np.linspace(10, 12, 201), np.linspace(0, 2, 201))
    plane = np.column_stack([x.ravel(), y.ravel(), np.zeros(x.size)])
    v = np.vstack([t.vertices, plane])
    n = np.vstack([t.normals, np.tile([0.0, 0.0, 1.0], (len(plane), 1))])
    res = meshcurv.principal_curvatures(v, normals=n)
    tube = slice(0, len(t.vertices))
    assert res.radius == pytest.approx(0.0559, rel=0.01)
    assert np.all(res.status[tube] == Status.TOO_FEW_NEIGHBORS)
    assert res.valid[len(t.vertices):].all()


def test_smaller_balls_serve_what_wraps_around():
    """One mesh of two icospheres, radius 1 and 0.05 (2562 vertices each): the default
    radius (0.40, the large sphere's ~100 vertices) holds all of the small one, whose rows
    were all WRAPS_AROUND. Its rows are now estimated at an eighth of it (0.049; a half and a
    quarter still hold the whole sphere and are not tried): max |dk| measured 4.7e-4 of
    k = 20 (1e-12 on the large sphere); with trimesh's vertex normals given on the points
    alone 0.0038 (0.0009 on the large one, whose given normals are those of its 320-face
    subdivision). Without faces or normals the plane fits over balls 2.2-4 times a part's
    width pass the shape test, so the rows keep WRAPS_AROUND rather than risk a wrong
    estimate. ``radius="auto"`` does the same."""
    import trimesh
    big, small = trimesh.creation.icosphere(4, radius=1.0), trimesh.creation.icosphere(4, 0.05)
    v = np.vstack([big.vertices, small.vertices + [3.0, 0.0, 0.0]])
    f = np.vstack([big.faces, small.faces + len(big.vertices)])
    n = np.vstack([big.vertex_normals, small.vertex_normals])
    k = np.r_[np.full(len(big.vertices), 1.0), np.full(len(small.vertices), 20.0)]
    on_small = np.arange(len(v)) >= len(big.vertices)
    for res in (meshcurv.principal_curvatures(v, f),
                meshcurv.principal_curvatures(v, normals=n)):
        assert res.valid.all()
        dk = np.maximum(np.abs(res.k1 - k), np.abs(res.k2 - k))
        assert dk[on_small].max() < 0.01 and dk[~on_small].max() < 0.003
        assert np.all(res.radius_used[~on_small] == res.radius)
        assert np.allclose(res.radius_used[on_small], res.radius / 8)
    # the per-vertex scale's ladder starts at the default radius: the small sphere's rows
    # wrapped at every scale and were left WRAPS_AROUND; now as the default radius's
    auto = meshcurv.principal_curvatures(v, f, radius="auto")
    assert auto.valid.all()
    dk = np.maximum(np.abs(auto.k1 - k), np.abs(auto.k2 - k))
    assert dk[on_small].max() < 0.01
    assert np.allclose(auto.radius_used[on_small], auto.radius / 8)
    plain = meshcurv.principal_curvatures(v, f, sparse_retry=False)
    assert np.all(plain.status[on_small] == Status.WRAPS_AROUND)
    assert plain.valid[~on_small].all()
    res = meshcurv.principal_curvatures(v)
    assert np.all(res.status[on_small] == Status.WRAPS_AROUND)


def test_tubes_two_to_four_times_narrower_than_the_ball_are_marked_on_clouds():
    """Clouds without normals at 3 and 3.5 times a tube's radius: a pole of radius 0.1 (3000
    random points) and the torus 3 / 0.4 (300 x 24 points). Their balls' section is still
    whole at radius / sqrt 2, whose width keeps ~all of the ball's (a surface's and noise's
    half), so every row is WRAPS_AROUND; before, 95-98 % of the rows were valid, k1 0.2-0.3
    for 10 on the pole and 0.9 k1 off on the torus."""
    rng = np.random.default_rng(0)
    t = rng.uniform(0.0, 2.0 * np.pi, 3000)
    pole = np.column_stack([0.1 * np.cos(t), 0.1 * np.sin(t), rng.uniform(0.3, 3.0, 3000)])
    middle = np.abs(pole[:, 2] - 1.65) < 1.0          # a ball from either end
    s = surfaces.torus(3.0, 0.4, 300, 24)
    for points, tube, rows in ((pole, 0.1, middle), (s.vertices, 0.4, slice(None))):
        for factor in (3.0, 3.5):
            res = meshcurv.principal_curvatures(points, radius=factor * tube)
            assert np.all(res.status[rows] == Status.WRAPS_AROUND), (tube, factor)


@pytest.mark.parametrize("unit", [2.0 ** -700, 2.0 ** 600])
def test_smaller_balls_at_extreme_scales_as_at_unit_scale(unit):
    # the ellipsoid 3 / 1 / 0.5 of 642 vertices: 40 rows whose default ball reaches around its
    # ends are estimated again in smaller balls. Their balls were counted on the raw
    # coordinates: at 2^600 the k-d tree's squares overflowed (ValueError), at 2^-700 they
    # underflowed and those rows kept WRAPS_AROUND
    s = surfaces.ellipsoid((3.0, 1.0, 0.5), 3)
    base = meshcurv.principal_curvatures(s.vertices, s.faces)
    res = meshcurv.principal_curvatures(s.vertices * unit, s.faces)
    assert np.array_equal(res.status, base.status)
    scale = np.nanmax(np.abs(base.k1))
    assert np.allclose(res.k1 * unit, base.k1, rtol=0, atol=1e-9 * scale, equal_nan=True)
    assert np.allclose(res.radius_used / unit, base.radius_used, rtol=1e-12, equal_nan=True)
