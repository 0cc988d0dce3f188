"""CurvatureResult.status says why a row has no estimate: each reason where it arises."""

import numpy as np
import pytest

import meshcurv
from meshcurv import surfaces
from meshcurv.result import Status

SPHERE = surfaces.sphere(subdivisions=3)
UP = np.array([0.0, 0.0, 1.0])


def status_of(points, normals, **kw):
    res = meshcurv.principal_curvatures(points, normals=normals, refine_normals=False, **kw)
    assert np.array_equal(res.status == Status.OK, res.valid)
    return res.status


def test_estimated_rows_are_ok():
    res = meshcurv.principal_curvatures(SPHERE.vertices, SPHERE.faces, radius=0.6)
    assert res.status.dtype == np.int8 and np.all(res.status == Status.OK)


def test_a_radius_below_the_spacing_leaves_too_few_half_sets():
    # at that radius alone (by default such vertices are retried at larger radii)
    res = meshcurv.principal_curvatures(SPHERE.vertices, SPHERE.faces, radius=0.3,
                                        sparse_retry=False)
    assert np.all(res.status == Status.TOO_FEW_HALF_SETS)


def test_a_mesh_radius_below_its_edges_leaves_too_few_neighbors_with_the_faces_normals():
    # no point within the ball: the plane fit has none, and the rows were NO_NORMAL with NaN
    # normals although the faces give one
    res = meshcurv.principal_curvatures(SPHERE.vertices, SPHERE.faces, radius=1e-4)
    assert np.all(res.status == Status.TOO_FEW_NEIGHBORS)
    assert np.einsum("ij,ij->i", res.normals, SPHERE.normals).min() > 0.99


def test_no_position_no_normal_and_an_isolated_point():
    v = np.vstack([SPHERE.vertices, [[np.nan] * 3, [5.0, 5, 5], [0.0, 0, 1.02]]])
    nv = np.vstack([SPHERE.normals, [UP, UP, [0.0, 0, 0]]])
    status = status_of(v, nv, radius=0.6)
    assert list(status[-3:]) == [Status.NO_POSITION, Status.TOO_FEW_NEIGHBORS, Status.NO_NORMAL]


def test_neighbors_on_one_side_give_too_few_half_sets():
    wedge = np.array([[0, 0, 0], [0.2, 0, 0], [0.4, 0, 0], [0.6, 0, 0], [0.8, 0, 0],
                      [0.5, 0.01, 0]], dtype=float)
    status = status_of(wedge, np.tile(UP, (6, 1)), radius=1.0, query=[0])
    assert status[0] == Status.TOO_FEW_HALF_SETS


def test_too_few_circle_fits_for_the_half_frequency_model_are_ill_posed():
    """Five or six circle fits: enough for 3 Euler parameters, not for 5."""
    rng = np.random.default_rng(0)
    found = 0
    for _ in range(40):
        k = rng.integers(6, 14)
        p = np.vstack([[0, 0, 0], np.column_stack([rng.uniform(-0.7, 0.7, (k, 2)),
                                                   rng.normal(scale=0.05, size=k)])])
        nv = np.tile(UP, (len(p), 1))
        # positions only, and robust_points=False: the outlier pass re-weights points of these
        # tiny noisy clouds, and the robust Euler refit may then drop fits (ill-posed with
        # more than 6 samples)
        res = meshcurv.principal_curvatures(p, normals=nv, radius=1.0, refine_normals=False,
                                            half_frequency=True, query=[0],
                                            normal_constraints="off", robust_points=False)
        if res.status[0] == Status.ILL_POSED_FIT:
            assert res.n_samples[0] in (5, 6)
            found += 1
    assert found > 0


def test_a_fan_rim_has_degenerate_directions():
    t = np.linspace(0, np.pi, 40)
    v = np.vstack([[0.0, 0, 0], np.column_stack([np.cos(t), np.sin(t), np.full_like(t, 0.5)])])
    f = np.array([[0, i, i + 1] for i in range(1, 40)])
    res = meshcurv.principal_curvatures(v, f, radius=0.6)
    assert np.sum(res.status == Status.DEGENERATE_DIRECTIONS) >= 30


def test_curvatures_beyond_float64_are_out_of_range():
    scale = 2.0 ** -1060                     # a subnormal-sized sphere: curvature 2**1060
    res = meshcurv.principal_curvatures(SPHERE.vertices * scale, SPHERE.faces,
                                        radius=0.6 * scale)
    assert np.all(res.status == Status.OUT_OF_RANGE)


@pytest.mark.parametrize("member", list(Status))
def test_every_status_is_documented(member):
    assert member.name in Status.__doc__ and member.value == int(member)
