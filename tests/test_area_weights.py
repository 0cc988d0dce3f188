"""Area weights of a mesh's vertices (meshcurv.area_weights) and what they do to the estimate."""

import numpy as np
import pytest

import meshcurv
from meshcurv import surfaces
from meshcurv.area_weights import CLOUD_RING_POINTS, cloud_area_weights, vertex_area_weights


def test_weights_are_each_vertex_third_of_its_faces_area_over_the_largest():
    # two right triangles sharing the edge 0-2 (legs 1, 1 and 1, 2: areas 0.5 and 1), a vertex 4
    # in no face and a degenerate face of three collinear vertices 5, 6, 7
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-2, 0, 0], [9, 9, 9],
                  [0, 0, 1], [1, 0, 1], [2, 0, 1]], dtype=float)
    f = np.array([[0, 1, 2], [0, 2, 3], [5, 6, 7]])
    w = vertex_area_weights(v, f)
    third = np.array([1.5, 0.5, 1.5, 1.0]) / 3      # a third of each vertex's faces' areas
    np.testing.assert_allclose(w[:4], third / third.max(), rtol=1e-15)
    np.testing.assert_array_equal(w[5:], 0.0)       # no area to stand for
    # no face: the median of the referenced vertices' (0 for the degenerate ones included)
    assert w[4] == pytest.approx(np.median(np.r_[w[:4], w[5:]]))


def test_weights_are_the_same_bits_however_the_faces_are_wound_repeated_or_scaled():
    s = surfaces.torus(2.0, 0.5, 24, 12)
    w = vertex_area_weights(s.vertices, s.faces)
    rotated = s.faces[:, [1, 2, 0]]
    for v, f in ((s.vertices, s.faces[::-1, ::-1]),                    # wound the other way
                 (s.vertices, np.vstack([rotated, s.faces])),          # each face twice
                 (s.vertices * 2.0 ** -700, s.faces),                  # squares underflow
                 (s.vertices * 2.0 ** 600, rotated)):                  # squares overflow
        np.testing.assert_array_equal(vertex_area_weights(v, f), w)



def test_weights_match_plain_numpy_areas():
    # the compiled kernels against np.cross and np.add.at over the distinct triangles
    rng = np.random.default_rng(5)
    s = surfaces.torus(2.0, 0.5, 30, 12)
    v = s.vertices + rng.normal(scale=0.05, size=s.vertices.shape)
    f = np.vstack([s.faces, s.faces[rng.choice(len(s.faces), 40)][:, ::-1]])
    distinct = np.unique(np.sort(f, axis=1), axis=0)
    twice = np.linalg.norm(np.cross(v[distinct[:, 1]] - v[distinct[:, 0]],
                                    v[distinct[:, 2]] - v[distinct[:, 0]]), axis=1)
    area = np.zeros(len(v))
    np.add.at(area, distinct.ravel(), np.repeat(twice, 3))
    np.testing.assert_allclose(vertex_area_weights(v, f), area / area.max(), rtol=1e-13)

def test_weights_without_any_area_are_one():
    v = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], dtype=float)
    np.testing.assert_array_equal(vertex_area_weights(v, np.array([[0, 1, 2]])), 1.0)


def test_cloud_weights_are_the_squared_distance_to_the_sixth_nearest_distinct_point():
    # a 5 x 5 grid of spacing 1 with one point repeated and one far point: interior points'
    # 6th nearest lies at sqrt 2, a corner's at sqrt 5; the repeat is no neighbour
    g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2)
    p = np.column_stack([g, np.zeros(len(g))])
    p = np.vstack([p, p[12], [[100.0, 0.0, 0.0]], [[np.nan, 0.0, 0.0]]])
    w = cloud_area_weights(p)
    finite = p[:-1]
    d = np.linalg.norm(finite[:, None] - finite[None], axis=2)
    d = np.sort(np.where(d > 0, d, np.inf), axis=1)[:, CLOUD_RING_POINTS - 1] ** 2
    np.testing.assert_allclose(w[:-1], d / d.max(), rtol=1e-15)
    assert w[12] == w[25] == pytest.approx(2.0 / d.max())
    assert w[-1] == pytest.approx(np.median(w[:-1]))       # no position: the median
    for scale in (2.0 ** -700, 2.0 ** 600):
        np.testing.assert_array_equal(cloud_area_weights(p * scale), w)



@pytest.mark.parametrize("size", [2.0 ** 24, 1e300])
def test_cloud_weights_of_points_closer_than_their_coordinates_resolve_stay_finite(size):
    # found by the fuzz test: two points 5e-324 apart at y = 2^24 have a spread of 5e-324,
    # whose power-of-two scale (2^1000) took the coordinates to inf and the k-d tree raised
    points = np.array([[0.0, size, 0.0], [0.0, size, 5e-324], [1e-300, size, 0.0]])
    assert np.isfinite(cloud_area_weights(points)).all()
    res = meshcurv.principal_curvatures(points, radius=0.3)
    assert not res.valid.any()


def test_weights_of_some_rows_are_the_whole_weights_up_to_a_common_factor():
    # the probe of the MLS blend reads the weights of a few rows' lists alone
    rng = np.random.default_rng(3)
    s = surfaces.torus(2.0, 0.5, 24, 12)
    v = s.vertices + rng.normal(scale=0.02, size=s.vertices.shape)
    rows = rng.choice(len(v), 40, replace=False)
    for whole, part in ((vertex_area_weights(v, s.faces), vertex_area_weights(v, s.faces, rows)),
                        (cloud_area_weights(v), cloud_area_weights(v, rows))):
        assert np.isnan(np.delete(part, rows)).all()
        factor = whole[rows].max() / part[rows].max()
        assert 0.0 < factor <= 1.0      # the rows hold the largest or not
        np.testing.assert_allclose(part[rows] * factor, whole[rows], rtol=1e-14)

def _decimated_ellipsoid(keep=0.1):
    """The ellipsoid 2 / 1.5 / 1 (icosphere of 40962 vertices) decimated by MeshLab's quadric
    edge collapse to ``keep`` of its faces: denser where it bends more; the truth at each
    vertex's projection onto the surface."""
    pymeshlab = pytest.importorskip("pymeshlab")
    s = surfaces.ellipsoid((2.0, 1.5, 1.0), 6)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(s.vertices, s.faces))
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=int(keep * len(s.faces)),
                                                preservenormal=True)
    v = np.asarray(ms.current_mesh().vertex_matrix(), dtype=np.float64)
    f = np.asarray(ms.current_mesh().face_matrix(), dtype=np.int64)
    return v, f, surfaces.ellipsoid_at(v)


def _mean_dk(res, truth):
    ok = np.isfinite(res.k1) & np.isfinite(res.k2)
    assert ok.mean() == 1.0
    return float(np.mean(np.abs(res.k1 - truth.k1) + np.abs(res.k2 - truth.k2)) / 2)


def test_area_weights_take_a_decimated_mesh_to_apss_accuracy():
    # measured: 0.0105 unweighted (the circle fits: the probe keeps the MLS blend out),
    # 0.0029 weighted (the probe takes it; MeshLab's APSS at the same radius 0.0028); its
    # points alone 0.0103 -> 0.0036. The bounds leave room for other platforms' decimation
    v, f, truth = _decimated_ellipsoid()
    for faces, bound in ((f, 0.0045), (None, 0.0055)):
        weighted = meshcurv.principal_curvatures(v, faces)
        alike = meshcurv.principal_curvatures(v, faces, area_weights=False)
        assert weighted.mls_share is not None and alike.mls_share is None
        assert _mean_dk(weighted, truth) < bound
        assert _mean_dk(weighted, truth) < 0.6 * _mean_dk(alike, truth)


def test_area_weights_leave_the_circle_fits_alone():
    # an even torus whose circle fits the probe finds limited by the sampling: the blend
    # takes the weights (its vertex areas vary 1.5 / 2.5 from the inner to the outer
    # equator), the circle fits do not (measured, blended: 0.00046 weighted, 0.00049 not)
    s = surfaces.torus(2.0, 0.5, 120, 30)
    for coarse_fit in ("circles", "mls"):
        a = meshcurv.principal_curvatures(s.vertices, s.faces, radius=0.5, coarse_fit=coarse_fit)
        b = meshcurv.principal_curvatures(s.vertices, s.faces, radius=0.5,
                                          coarse_fit=coarse_fit, area_weights=False)
        if coarse_fit == "circles":
            np.testing.assert_array_equal(a.k1, b.k1)
        else:
            assert _mean_dk(a, s) < 1.3 * _mean_dk(b, s) + 1e-4


def test_inputs_the_probe_leaves_to_the_circle_fits_keep_their_bits():
    # an icosphere ellipsoid, mesh and cloud, at its default radius given (the default takes
    # smaller balls at the ends, whose calls probe again): neither MLS surface finds the
    # circle fits limited, and nothing else takes the weights
    s = surfaces.ellipsoid((2.0, 1.5, 1.0), 3)
    for faces in (s.faces, None):
        r = meshcurv.default_radius(s.vertices, faces=faces)
        a = meshcurv.principal_curvatures(s.vertices, faces, radius=r)
        b = meshcurv.principal_curvatures(s.vertices, faces, radius=r, area_weights=False)
        assert a.mls_share is None
        np.testing.assert_array_equal(a.k1, b.k1)
        np.testing.assert_array_equal(a.k2, b.k2)
