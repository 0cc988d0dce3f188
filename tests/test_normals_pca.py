"""Plane-fit normals (meshcurv.normals.pca): the split-half disagreement kernel against its
numpy specification, plane fits of each half of the lists."""

import numpy as np
import pytest

from meshcurv.neighbors import ball_grid, ball_neighbors
from meshcurv.normals.pca import pca_normals, split_plane_disagreement


def split_spec(points, query, indptr, indices, radius, weights=None):
    """sin^2 between :func:`pca_normals` of the entries at even and at odd list positions."""
    counts = np.diff(indptr)
    owner = np.repeat(np.arange(len(query)), counts)
    even = (np.arange(len(indices)) - np.repeat(indptr[:-1], counts)) % 2 == 0
    halves = []
    for part in (even, ~even):
        ptr = np.concatenate([[0], np.cumsum(np.bincount(owner[part], minlength=len(query)))])
        halves.append(pca_normals(points, query, ptr.astype(indptr.dtype), indices[part],
                                  radius, weights))
    cos = np.einsum("ij,ij->i", *halves)
    return np.maximum(0.0, 1.0 - cos * cos)


@pytest.mark.parametrize("weighted", [False, True])
def test_split_plane_disagreement_equals_its_numpy_specification(weighted):
    rng = np.random.default_rng(5)
    xy = rng.uniform(-1.0, 1.0, (3000, 2))
    points = np.column_stack([xy, 0.3 * xy[:, 0] ** 2 + rng.normal(scale=0.01, size=3000)])
    weights = rng.uniform(0.0, 1.0, 3000) if weighted else None
    query = points[::7]
    # sparse balls too: some halves have fewer than 3 points (NaN)
    for radius in (0.03, 0.2):
        indptr, indices = ball_neighbors(ball_grid(points, radius), None, query, radius)
        got = split_plane_disagreement(points, query, indptr, indices, radius, weights)
        want = split_spec(points, query, indptr, indices, radius, weights)
        np.testing.assert_array_equal(np.isnan(got), np.isnan(want))
        # the same normals bit for bit; sin^2 = 1 - cos^2 carries cos's rounding (1e-16,
        # summed in another order) as an absolute error
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-15)
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
        out.append(split_plane_disagreement(points, points, indptr, indices, radius))
    assert np.nanmax(out[0]) < 1e-20
    # each half's tilt: noise 0.02 over ~60 points spread over a ball of radius 0.2, sin^2 of
    # about 2 x 2 x 8 sigma^2 / (N R^2) (two halves, two tangent components) ~ 0.01
    assert 0.002 < np.nanmean(out[1]) < 0.05
