"""Plane-fit normals (meshcurv.normals.pca): the split-half disagreement kernel against its
numpy specification, quadric height fits of each half of the lists."""

import numpy as np
import pytest

from meshcurv.neighbors import ball_grid, ball_neighbors
from meshcurv.normals.pca import pca_normals, split_disagreement


def _solve(mat, rhs, fits):
    sol = np.full(rhs.shape, np.nan)
    sol[fits] = np.linalg.solve(mat[fits], rhs[fits][..., None])[..., 0]
    return sol


def _fit(owner, sel, w, phi, h, m, terms):
    """Weighted least squares of h by the first ``terms`` columns of phi per owner, the query
    point (u = v = h = 0) with weight 1 in each; NaN rows with fewer points than terms."""
    p = phi[:, :terms]
    mat = np.zeros((m, terms, terms))
    rhs = np.zeros((m, terms))
    np.add.at(mat, owner[sel], w[sel, None, None] * p[sel, :, None] * p[sel, None, :])
    np.add.at(rhs, owner[sel], w[sel, None] * p[sel] * h[sel, None])
    mat[:, 2, 2] += 1.0
    return _solve(mat, rhs, np.bincount(owner[sel], minlength=m) + 1 >= terms)


def _ball_covariance(points, query, indptr, indices, radius, weights=None):
    """``(owner, offset, w, used, cov)``: each list entry's query row, its offset in units of
    the radius, its weight and whether it counts (inside the ball, not the point itself,
    weight > 0); and (m, 3, 3) the plane fit's covariance of each ball about its centroid,
    the query point included with weight 1."""
    m = len(query)
    owner = np.repeat(np.arange(m), np.diff(indptr))
    offset = (points[indices] - query[owner]) / radius
    d2 = np.sum((points[indices] - query[owner]) ** 2, axis=1)
    w = np.ones(len(indices)) if weights is None else weights[indices]
    used = (d2 > 0) & (d2 <= radius * radius) & (w > 0)
    wu = np.where(used, w, 0.0)
    total = np.bincount(owner, wu, minlength=m) + 1.0
    centroid = np.stack([np.bincount(owner, wu * offset[:, a], minlength=m)
                         for a in range(3)], axis=1) / total[:, None]
    cov = np.zeros((m, 3, 3))
    np.add.at(cov, owner, wu[:, None, None] * offset[:, :, None] * offset[:, None, :])
    cov = cov / total[:, None, None] - centroid[:, :, None] * centroid[:, None, :]
    return owner, offset, w, used, cov


def split_spec(points, query, indptr, indices, radius, weights=None):
    """The split disagreement in numpy: in the frame of the whole ball's :func:`pca_normals`
    (weighted; the query point included with weight 1), the quadric height fit (u, v, 1, u^2,
    u v, v^2) of the whole ball, then plane height fits (u, v, 1) of the entries at even and
    at odd list positions after the quadric's second-order part is taken off their heights;
    sin^2 between the two tangent planes times (l2 / (l2 - l1))^2, l1 <= l2 the smallest
    eigenvalues of the ball's covariance."""
    m = len(query)
    normal = pca_normals(points, query, indptr, indices, radius, weights)
    helper = np.where(np.abs(normal[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(normal, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(normal, t1)
    counts = np.diff(indptr)
    owner, offset, w, used, cov = _ball_covariance(points, query, indptr, indices, radius,
                                                   weights)
    position = np.arange(len(indices)) - np.repeat(indptr[:-1], counts)
    lam = np.linalg.eigvalsh(np.where(np.isfinite(cov), cov, 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        gap = lam[:, 1] / (lam[:, 1] - lam[:, 0])
    u, v, h = (np.einsum("ij,ij->i", offset, axis[owner]) for axis in (t1, t2, normal))
    phi = np.stack([u, v, np.ones_like(u), u * u, u * v, v * v], axis=1)
    quadric = _fit(owner, used, w, phi, h, m, 6)
    flat = h - np.sum(phi[:, 3:] * quadric[owner, 3:], axis=1)
    a, b = (_fit(owner, used & (position % 2 == half), w, phi, flat, m, 3)[:, :2]
            for half in (0, 1))
    cos = (np.sum(a * b, axis=1) + 1.0) / np.sqrt((1.0 + np.sum(a * a, axis=1))
                                                  * (1.0 + np.sum(b * b, axis=1)))
    return np.maximum(0.0, 1.0 - cos * cos) * gap * gap


@pytest.mark.parametrize("weighted", [False, True])
def test_split_disagreement_equals_its_numpy_specification(weighted):
    rng = np.random.default_rng(5)
    xy = rng.uniform(-1.0, 1.0, (3000, 2))
    points = np.column_stack([xy, 0.3 * xy[:, 0] ** 2 + rng.normal(scale=0.01, size=3000)])
    weights = rng.uniform(0.0, 1.0, 3000) if weighted else None
    query = points[::7]
    # sparse balls too: some have fewer than 6 points (NaN)
    for radius in (0.03, 0.2):
        indptr, indices = ball_neighbors(ball_grid(points, radius), None, query, radius)
        got = split_disagreement(points, query, indptr, indices, radius, weights)
        want = split_spec(points, query, indptr, indices, radius, weights)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
        # the same fits, summed in another order and solved another way: sin^2 = 1 - cos^2
        # carries cos's rounding (1e-16) as an absolute error, times the gap factor (up to
        # ~100 in the sparse balls)
        np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    assert np.isnan(got).sum() < len(got) // 10 and np.isfinite(got).any()


def test_split_halves_of_a_plane_agree_and_noise_separates_them():
    rng = np.random.default_rng(6)
    xy = rng.uniform(-1.0, 1.0, (4000, 2))
    flat = np.column_stack([xy, np.zeros(4000)])
    noisy = np.column_stack([xy, rng.normal(scale=0.02, size=4000)])
    radius = 0.2
    out = []
    for points in (flat, noisy):
        indptr, indices = ball_neighbors(ball_grid(points, radius), None, points, radius)
        out.append(split_disagreement(points, points, indptr, indices, radius))
    assert np.nanmax(out[0]) < 1e-20
    # each half's tilt: noise 0.02 over ~60 points spread over a ball of radius 0.2, sin^2 of
    # about 2 x 2 x 8 sigma^2 / (N R^2) (two halves, two tangent components) ~ 0.01
    assert 0.002 < np.nanmean(out[1]) < 0.05


def test_split_halves_of_a_clean_sphere_agree_where_plane_fits_of_them_tilt():
    # every other entry of a regular sampling is an uneven half of the ball; on a curved
    # surface a plane fit of it tilts with the curvature (noise it does not have), the
    # halves' fits with the ball's quadric part taken off do not
    from meshcurv.surfaces import sphere

    points = sphere(1.0, 5).vertices
    radius = 0.3
    indptr, indices = ball_neighbors(ball_grid(points, radius), None, points, radius)
    split = split_disagreement(points, points, indptr, indices, radius)
    counts = np.diff(indptr)
    owner = np.repeat(np.arange(len(points)), counts)
    even = (np.arange(len(indices)) - np.repeat(indptr[:-1], counts)) % 2 == 0
    planes = []
    for part in (even, ~even):
        ptr = np.concatenate([[0], np.cumsum(np.bincount(owner[part], minlength=len(points)))])
        planes.append(pca_normals(points, points, ptr, indices[part], radius))
    cos = np.einsum("ij,ij->i", *planes)
    # measured: 1e-8 (in the plane fit's frame, tilted from the surface's own axis, the
    # sphere's height is not quite a quadric), plane fits of the halves 2.2e-4
    assert np.nanmean(split) < 1e-7
    assert np.nanmean(1.0 - cos * cos) > 1e-4


def agreement_spec(points, query, normals, indptr, indices, radius, flatness, weights=None):
    """plane_agreement in numpy: the weighted covariance of the ball (the query point with
    weight 1) about its centroid, its eigenvalues l1 <= l2 <= l3 and the smallest one's
    eigenvector e; |normal . e| where l1 <= flatness l2 and l2 > 1e-6 l3, else NaN."""
    owner, _, _, used, cov = _ball_covariance(points, query, indptr, indices, radius, weights)
    lam, vec = np.linalg.eigh(cov)
    cos = np.abs(np.einsum("ij,ij->i", normals, vec[:, :, 0]))
    patch = (lam[:, 0] <= flatness * lam[:, 1]) & (lam[:, 1] > 1e-6 * lam[:, 2])
    enough = np.bincount(owner, used, minlength=len(query)) + 1 >= 3
    return np.where(patch & enough, cos, np.nan)


@pytest.mark.parametrize("weighted", [False, True])
def test_plane_agreement_equals_its_numpy_specification(weighted):
    from meshcurv.normals.pca import plane_agreement

    rng = np.random.default_rng(4)
    # a bumpy sheet, a noise blob and a line of points: patches, no patch, no plane
    sheet = rng.uniform(-1, 1, (1500, 3)) * [1, 1, 0]
    sheet[:, 2] = 0.2 * np.sin(2 * sheet[:, 0]) + 0.01 * rng.normal(size=1500)
    blob = rng.normal(size=(200, 3)) * 0.05 + [3.0, 0.0, 0.0]
    line = np.column_stack([np.linspace(5, 6, 50), np.zeros(50), np.zeros(50)])
    points = np.vstack([sheet, blob, line])
    normals = rng.normal(size=points.shape)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[::97] = np.nan
    radius = 0.2
    grid = ball_grid(points, radius)
    query = np.arange(len(points))
    indptr, indices = ball_neighbors(grid, query, points, radius)
    weights = rng.uniform(0, 1, len(points)) * (rng.uniform(size=len(points)) > 0.1) \
        if weighted else None
    got = plane_agreement(points, points, normals, indptr, indices, radius, 1 / 6, weights)
    want = agreement_spec(points, points, normals, indptr, indices, radius, 1 / 6, weights)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert np.isfinite(got[:1500]).mean() > 0.9          # the sheet: planes
    assert np.isnan(got[1500:]).all()                    # blob and line: none


def spread_spec(points, query, indptr, indices, radius, weights=None):
    """ball_spread in numpy: the eigenvalues, ascending, of the plane fit's covariance
    (:func:`_ball_covariance`, units of the radius squared); NaN rows with fewer than 3
    points."""
    owner, _, _, used, cov = _ball_covariance(points, query, indptr, indices, radius, weights)
    enough = np.bincount(owner, used, minlength=len(query)) + 1 >= 3
    return np.where(enough[:, None], np.linalg.eigvalsh(cov), np.nan)


@pytest.mark.parametrize("weighted", [False, True])
def test_ball_spread_equals_its_numpy_specification(weighted):
    from meshcurv.normals.pca import ball_spread

    rng = np.random.default_rng(5)
    sheet = rng.uniform(-1, 1, (1500, 3)) * [1, 1, 0]
    sheet[:, 2] = 0.2 * np.sin(2 * sheet[:, 0])
    blob = rng.normal(size=(200, 3)) * 0.05 + [3.0, 0.0, 0.0]
    line = np.column_stack([np.linspace(5, 6, 50), np.zeros(50), np.zeros(50)])
    lone = np.array([[9.0, 9.0, 9.0]])
    points = np.vstack([sheet, blob, line, lone])
    indptr, indices = ball_neighbors(ball_grid(points, 0.2), np.arange(len(points)), points,
                                     0.2)
    weights = rng.uniform(0, 1, len(points)) if weighted else None
    got = ball_spread(points, points, indptr, indices, 0.2, weights)
    want = spread_spec(points, points, indptr, indices, 0.2, weights)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    with np.errstate(invalid="ignore"):                      # the lone point's NaN row
        flat = got[:, 0] / got[:, 1]
    assert np.nanmax(flat[:1500]) < 0.05 and np.nanmin(flat[1500:1700]) > 0.3
    assert np.isnan(got[-1]).all()                           # a lone point: no plane


@pytest.mark.parametrize("reach, expected", [(90, 0.25), (120, 0.5)])
def test_flatness_of_a_spherical_cap(reach, expected):
    """A unit sphere evenly sampled (200k random points) in the ball about a point whose rim
    lies ``reach`` degrees around: smallest over middle eigenvalue (1 - cos T) / (2 (2 +
    cos T)), within the sampling's scatter (a few thousand points in the ball: ~2 %)."""
    from meshcurv.normals.pca import ball_spread

    p = np.random.default_rng(6).normal(size=(200_000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    radius = 2.0 * np.sin(np.radians(reach) / 2.0)
    x = np.array([[0.0, 0.0, 1.0]])
    inside = np.flatnonzero(np.linalg.norm(p - x, axis=1) <= radius)
    got = ball_spread(p, x, np.array([0, len(inside)]), inside, radius)
    assert got[0, 0] / got[0, 1] == pytest.approx(expected, rel=0.03)
