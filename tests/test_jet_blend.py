"""Ring jets (meshcurv.fit.ring_jet against its numpy specification, the hop rings of
meshcurv.neighbors.kring) and their blend into the circle fits (meshcurv.jet_blend)."""

import numpy as np
import pytest
import scipy.sparse as sp

import meshcurv
from meshcurv import jet_blend, surfaces
from meshcurv.fit import ring_jet, ring_jet_spec
from meshcurv.neighbors import kring, power_of_two_scale
from meshcurv.result import Status


def hop_lists(faces, n, query, depth, limit=jet_blend.MAX_RING):
    """The kernel's hop rings of ``query`` to ``depth`` hops, and each row's inner count."""
    adjacency = kring.edge_adjacency(faces, n)
    work = kring.KringWork(n)
    return kring.hop_rings(adjacency[0], adjacency[1], np.asarray(query, np.int64), depth,
                           work.stamp, work.queue, 0, limit)


def test_hop_rings_are_the_vertices_within_that_many_edges():
    """Against powers of the adjacency matrix: every row holds the vertices 1 .. depth hops
    away, those within depth - 1 first (``inner`` of them), on a mesh with a border."""
    s = surfaces.paraboloid(spacing=0.5, extent=3.0)
    n = len(s.vertices)
    e = np.concatenate([s.faces[:, [0, 1]], s.faces[:, [1, 2]], s.faces[:, [2, 0]]])
    a = sp.coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    a = ((a + a.T + sp.identity(n)) > 0).astype(np.int64)
    reach = [sp.identity(n, dtype=np.int64, format="csr")]
    for _ in range(4):
        reach.append(((reach[-1] @ a) > 0).astype(np.int64).tocsr())
    query = np.arange(0, n, 5)
    indptr, indices, inner = hop_lists(s.faces, n, query, 4)
    for i, q in enumerate(query):
        row = indices[indptr[i]:indptr[i + 1]]
        within = [set(reach[k][q].indices) - {q} for k in (3, 4)]
        assert len(row) == len(set(row)) and set(row) == within[1]
        assert set(row[:inner[i]]) == within[0]
    # rings of more than ``limit`` vertices are left empty
    sizes = np.diff(indptr)
    limit = int(np.median(sizes))
    indptr, indices, inner = hop_lists(s.faces, n, query, 4, limit)
    assert np.array_equal(np.diff(indptr), np.where(sizes > limit, 0, sizes))
    assert np.all(inner[sizes > limit] == 0)


def test_the_hub_of_a_large_fan_gets_no_jet_and_costs_no_memory():
    """A disc of 200000 triangles around one hub vertex (a cap triangulated from its centre):
    every vertex's 4-ring is the whole fan; the rows get no jet (NaN, jet_share 0) instead of
    lists of 200000^2 entries, and the circle fits stand."""
    k = 200000
    t = np.linspace(0.0, 2 * np.pi, k, endpoint=False)
    v = np.vstack([[0.0, 0.0, 0.0], np.column_stack([np.cos(t), np.sin(t), np.zeros(k)])])
    ring = np.arange(1, k + 1)
    f = np.column_stack([np.zeros(k, np.int64), ring, np.roll(ring, -1)])
    small, large, error, _, _ = jet_blend.ring_jets(v, f, np.arange(0, k + 1, 1000),
                                                 np.tile([0.0, 0.0, 1.0], (k // 1000 + 1, 1)))
    assert np.isnan(small).all() and np.isnan(error).all()


@pytest.mark.parametrize("surface", [
    surfaces.ellipsoid((3.0, 1.0, 0.5), 4),
    surfaces.torus(2.0, 0.5, 60, 20),
    surfaces.saddle("random", n=3000),
])
def test_ring_jet_matches_its_numpy_specification(surface):
    """Shape operators of both supports, the misfit bound, the small fit's rows and the
    frame at every 7th vertex. Tolerances: the kernel's Cholesky and the specification's
    LAPACK solve of the same normal equations (condition up to ~1e9 at the scaled quartic's
    terms on the random sampling) agree to 1e-7 of the entries (measured 1.1e-8 on the
    saddle, 5e-13 on the others); the misfit bound, whose residuals are what the two
    solutions leave, to 1e-6 of itself (measured 7e-9 on the saddle, where the quartic leaves
    almost nothing)."""
    query = np.arange(0, len(surface.vertices), 7)
    indptr, indices, inner = hop_lists(surface.faces, len(surface.vertices), query, 4)
    m = len(query)
    small, large, error, frame_u, rows = (np.empty((m, 3)), np.empty((m, 3)), np.empty(m),
                                          np.empty((m, 3)), np.empty(m, dtype=np.int64))
    ring_jet.ring_jet(surface.vertices, query, surface.normals[query], indptr, indices, inner,
                      small, large, error, frame_u, rows)
    for i, q in enumerate(query):
        a, b, e, tu, count = ring_jet_spec.ring_jet(
            surface.vertices[q], surface.normals[q],
            surface.vertices[indices[indptr[i]:indptr[i + 1]]], inner[i])
        scale = np.abs(a).max()
        np.testing.assert_allclose(small[i], a, rtol=0, atol=1e-7 * scale)
        np.testing.assert_allclose(large[i], b, rtol=0, atol=1e-7 * scale)
        assert error[i] == pytest.approx(e, rel=1e-6, abs=0.0)
        np.testing.assert_allclose(frame_u[i], tu, atol=1e-15)
        assert rows[i] == count


def test_ring_jet_is_exact_on_a_quartic_height_field_and_says_so():
    """Heights along a fixed axis z of the graph z = f(x, y), f a quartic, are a quartic in
    any frame about that axis: with the normal e_z given at every vertex of a random
    sampling, both supports give the graph's exact principal curvatures (from its gradient
    and Hessian, the tilt of the frame included) at every interior vertex to round-off (1e-9
    of k: measured 1e-12), with a misfit bound of round-off size: the residuals summed one
    by one, each at least the coordinates' rounding, bound k's error by 1.9e-12 of the
    largest |k| (measured), below 1e-9."""
    rng = np.random.default_rng(3)
    xy = rng.uniform(-1.5, 1.5, size=(3000, 2))
    x, y = xy.T
    c = np.array([0.3, -0.2, 0.25, 0.1, -0.05, 0.04, 0.03, -0.02, 0.02, 0.01, -0.015])
    z = (c[0] * x * x + c[1] * x * y + c[2] * y * y + c[3] * x + c[4] * y + c[5] * x ** 3
         + c[6] * x * y * y + c[7] * y ** 3 + c[8] * x ** 4 + c[9] * x * x * y * y
         + c[10] * y ** 4)
    fx = 2 * c[0] * x + c[1] * y + c[3] + 3 * c[5] * x * x + c[6] * y * y + 4 * c[8] * x ** 3 \
        + 2 * c[9] * x * y * y
    fy = c[1] * x + 2 * c[2] * y + c[4] + 2 * c[6] * x * y + 3 * c[7] * y * y \
        + 2 * c[9] * x * x * y + 4 * c[10] * y ** 3
    fxx = 2 * c[0] + 6 * c[5] * x + 12 * c[8] * x * x + 2 * c[9] * y * y
    fxy = c[1] + 2 * c[6] * y + 4 * c[9] * x * y
    fyy = 2 * c[2] + 2 * c[6] * x + 6 * c[7] * y + 2 * c[9] * x * x + 12 * c[10] * y * y
    # the graph's principal curvatures along +z, convex positive (heights falling away)
    w = np.sqrt(1 + fx * fx + fy * fy)
    first = np.stack([np.stack([1 + fx * fx, fx * fy], -1),
                      np.stack([fx * fy, 1 + fy * fy], -1)], -2)
    second = -np.stack([np.stack([fxx, fxy], -1), np.stack([fxy, fyy], -1)], -2) / w[:, None, None]
    exact = np.sort(np.linalg.eigvals(np.linalg.solve(first, second)).real, axis=1)[:, ::-1]
    from scipy.spatial import Delaunay
    faces = Delaunay(xy).simplices.astype(np.int64)
    v = np.column_stack([x, y, z])
    query = np.flatnonzero(np.abs(xy).max(axis=1) < 1.0)
    indptr, indices, inner = hop_lists(faces, len(v), query, 4)
    m = len(query)
    small, large, error, frame_u, rows = (np.empty((m, 3)), np.empty((m, 3)), np.empty(m),
                                          np.empty((m, 3)), np.empty(m, dtype=np.int64))
    up = np.tile([0.0, 0.0, 1.0], (m, 1))
    ring_jet.ring_jet(v, query, up, indptr, indices, inner, small, large, error, frame_u, rows)
    scale = np.abs(exact[query]).max()
    for fit in (small, large):
        k1, k2, _, _ = jet_blend._eigen(fit)
        np.testing.assert_allclose(k1, exact[query, 0], atol=1e-9 * scale)
        np.testing.assert_allclose(k2, exact[query, 1], atol=1e-9 * scale)
    assert np.nanmax(error) < 1e-9 * scale


def test_ring_jet_gives_no_fit_where_it_cannot():
    """NaN shape operators where the support holds fewer than MIN_ROWS points (an
    icosahedron's 3-ring is its 11 other vertices), where the vertex or its normal is not
    finite; neighbours with NaN coordinates are passed over."""
    ico = surfaces.sphere(1.0, 0)
    v = ico.vertices.copy()
    indptr, indices, inner = hop_lists(ico.faces, len(v), np.arange(len(v)), 4)
    m = len(v)
    out = (np.empty((m, 3)), np.empty((m, 3)), np.empty(m), np.empty((m, 3)),
           np.empty(m, dtype=np.int64))
    ring_jet.ring_jet(v, np.arange(m, dtype=np.int64), ico.normals, indptr, indices, inner, *out)
    assert np.isnan(out[0]).all() and np.isnan(out[2]).all() and (out[4] == 0).all()

    s = surfaces.ellipsoid((2.0, 1.5, 1.0), 3)
    v = s.vertices.copy()
    query = np.arange(len(v), dtype=np.int64)
    normals = s.normals.copy()
    normals[0] = np.nan
    v[1] = np.nan
    indptr, indices, inner = hop_lists(s.faces, len(v), query, 4)
    m = len(v)
    out = (np.empty((m, 3)), np.empty((m, 3)), np.empty(m), np.empty((m, 3)),
           np.empty(m, dtype=np.int64))
    ring_jet.ring_jet(v, query, normals, indptr, indices, inner, *out)
    assert np.isnan(out[0][:2]).all() and np.isnan(out[3][:2]).all()
    assert np.isfinite(out[0][2:]).all()
    # a neighbour of vertex 1 skips it and still fits
    near = indices[indptr[2]:indptr[3]]
    assert 1 in near or np.isfinite(out[0][2]).all()


def test_blend_takes_the_jet_on_a_clean_ellipsoid_and_nothing_under_noise():
    """A clean ellipsoid 3 / 1 / 0.5 (10242 vertices), whose curvature (up to 12) varies across
    the default balls: mean |dk| falls to less than 0.45 of the circle fits' (measured 0.0156
    -> 0.0048, 0.31x; 0.45x under the bound of the clouds' rule); a torus with 0.1 % noise
    along the normal and an ellipsoid with 0.003 % keep every row's bits (the jet over 37
    points is the noisier estimate there: three of its standard errors clear its difference
    from the circle fits); the blend's weights are in [0, 1]."""
    s = surfaces.ellipsoid((3.0, 1.0, 0.5), 5)
    plain = meshcurv.principal_curvatures(s.vertices, s.faces, ring_jet=False)
    blended = jet_blend.blend(plain, s.vertices, s.faces, np.arange(len(s.vertices)))
    w = blended.jet_share
    dk = lambda r: np.mean((np.abs(r.k1 - s.k1) + np.abs(r.k2 - s.k2)) / 2)
    assert dk(blended) < 0.45 * dk(plain)
    assert w.min() >= 0.0 and w.max() <= 1.0 and (w > 0.5).mean() > 0.6      # measured 0.81
    kept = w == 0.0
    assert np.array_equal(blended.k1[kept], plain.k1[kept])
    assert np.array_equal(blended.d1[kept], plain.d1[kept])
    # directions stay an orthonormal frame with the normal (d2 = n x d1)
    np.testing.assert_allclose(np.cross(blended.normals, blended.d1), blended.d2, atol=1e-12)
    assert np.all(blended.k1 >= blended.k2)

    for t in (surfaces.add_normal_noise(surfaces.torus(2.0, 0.5, 120, 30), 0.001, seed=1),
              surfaces.add_normal_noise(surfaces.ellipsoid((2.0, 1.5, 1.0), 4), 3e-5, seed=1)):
        noisy = meshcurv.principal_curvatures(t.vertices, t.faces, ring_jet=False)
        again = jet_blend.blend(noisy, t.vertices, t.faces, np.arange(len(t.vertices)))
        assert not again.jet_share.any()
        for name in ("k1", "k2", "d1", "d2", "normals"):
            assert getattr(again, name) is getattr(noisy, name)


@pytest.mark.parametrize("faces", [True, False])
def test_blend_weights_follow_the_rule_of_each_support(faces):
    """jet_share against the module docstring's rule, recomputed in numpy from the jets:
    w = clip(1 - s^2 (e^2 + |S_small - S_large|^2) / |S_small - S_circles|^2, 0, 1), |S|^2 the
    mean squared eigenvalue; on a mesh's rings s = 3 and e the standard error (the misfit
    bound over sqrt(rows - 15)), on a cloud's nearest points s = 2 and e the bound. To 1e-9
    (the same operations in another order)."""
    s = surfaces.ellipsoid((2.0, 1.5, 1.0), 3)
    f = s.faces if faces else None
    plain = meshcurv.principal_curvatures(s.vertices, f, ring_jet=False)
    blended = jet_blend.blend(plain, s.vertices, f, np.arange(len(s.vertices)))
    ok = plain.status == Status.OK
    unit = power_of_two_scale(plain.radius)
    small, large, error, tu, rows = jet_blend.ring_jets(
        s.vertices, f, np.flatnonzero(ok), plain.normals[ok], unit)
    tv = np.cross(plain.normals[ok], tu)
    c, si = np.einsum("ij,ij->i", plain.d1[ok], tu), np.einsum("ij,ij->i", plain.d1[ok], tv)
    k1, k2 = plain.k1[ok] / unit, plain.k2[ok] / unit
    circles = np.column_stack([k1 * c * c + k2 * si * si, (k1 - k2) * c * si,
                               k1 * si * si + k2 * c * c])
    norm2 = lambda a: 0.5 * (a[:, 0] ** 2 + 2 * a[:, 1] ** 2 + a[:, 2] ** 2)
    e2 = error ** 2 / (rows - 15) if faces else error ** 2
    sigmas = 3.0 if faces else 2.0
    w = np.clip(1 - sigmas ** 2 * (e2 + norm2(small - large)) / norm2(small - circles), 0, 1)
    assert 0.05 < (w > 0).mean() < 0.95         # both kinds of rows are there
    np.testing.assert_allclose(blended.jet_share[ok], np.nan_to_num(w), rtol=0, atol=1e-9)
    assert not blended.jet_share[~ok].any()


def test_the_default_radius_takes_the_jets_a_given_radius_does_not():
    """``ring_jet`` is on at the default radius and with "auto" (the default equals the
    blend applied to ``ring_jet=False``), off for a given radius (the same bits with the
    switch on and off); clouds take their points' nearest neighbours."""
    s = surfaces.ellipsoid((2.0, 1.5, 1.0), 3)
    v, f = s.vertices, s.faces
    on = meshcurv.principal_curvatures(v, f)
    off = meshcurv.principal_curvatures(v, f, ring_jet=False)
    expected = jet_blend.blend(off, v, f, np.arange(len(v)))
    assert expected.jet_share.any() and off.jet_share is None
    for name in ("k1", "k2", "d1", "d2", "normals", "jet_share"):
        assert np.array_equal(getattr(on, name), getattr(expected, name))
    given = [meshcurv.principal_curvatures(v, f, radius=0.5, ring_jet=flag)
             for flag in (True, False)]
    assert np.array_equal(given[0].k1, given[1].k1) and given[0].jet_share is None
    cloud = meshcurv.principal_curvatures(v)
    plain = meshcurv.principal_curvatures(v, ring_jet=False)
    dk = lambda r: np.mean((np.abs(r.k1 - s.k1) + np.abs(r.k2 - s.k2)) / 2)
    assert dk(cloud) < 0.95 * dk(plain)      # measured 0.034 -> 0.030


def test_cloud_lists_skip_points_that_are_not_finite_and_small_clouds():
    """The nearest-neighbour lists of a cloud with a NaN point (no list for it, never a
    neighbour) and of a cloud smaller than the larger support."""
    rng = np.random.default_rng(0)
    p = rng.normal(size=(2000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    p[3] = np.nan
    rows = np.arange(len(p))
    small, large, error, tu, _ = jet_blend.ring_jets(p, None, rows, p)
    assert np.isnan(small[3]).all() and np.isfinite(small[rows != 3]).all()
    # a unit sphere's caps of 37 points (about 16 degrees): k = 1 to the quartic's error
    k1, k2, _, _ = jet_blend._eigen(small[rows != 3])
    np.testing.assert_allclose(np.concatenate([k1, k2]), 1.0, atol=0.01)
    few = p[:40][np.isfinite(p[:40]).all(axis=1)]
    small, large, _, _, _ = jet_blend.ring_jets(few, None, np.arange(len(few)), few)
    assert np.isfinite(small).all() and np.isfinite(large).all()


@pytest.mark.parametrize("faces", [True, False])
def test_rows_of_a_query_and_of_a_scaled_input_equal_the_whole_runs(faces):
    """The jets are row-local: the rows of a ``query`` equal the whole run's; on coordinates
    scaled by 2^-700 and 2^600 (squares of the supports' sizes under- and overflow) the
    rows are the unit-scale run's scaled, bit for bit."""
    s = surfaces.ellipsoid((2.0, 1.5, 1.0), 3)
    f = s.faces if faces else None
    whole = meshcurv.principal_curvatures(s.vertices, f)
    assert (whole.jet_share > 0).mean() > 0.05       # measured 0.13 (mesh), 0.07 (points)
    rows = np.arange(3, len(s.vertices), 11)
    part = meshcurv.principal_curvatures(s.vertices, f, query=rows)
    for name in ("k1", "k2", "d1", "d2", "jet_share"):
        assert np.array_equal(getattr(part, name), getattr(whole, name)[rows])
    for unit in (2.0 ** -700, 2.0 ** 600):
        scaled = meshcurv.principal_curvatures(s.vertices * unit, f)
        assert np.array_equal(scaled.k1 * unit, whole.k1)
        assert np.array_equal(scaled.d1, whole.d1)
        assert np.array_equal(scaled.jet_share, whole.jet_share)
