"""What the estimator takes besides arrays: trimesh's mesh, point cloud and scene."""

import numpy as np
import pytest
import trimesh

import meshcurv


def test_trimesh_point_cloud_is_its_points():
    # trimesh.load of a PLY without faces gives a PointCloud
    rng = np.random.default_rng(0)
    p = rng.normal(size=(3000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    res = meshcurv.principal_curvatures(trimesh.PointCloud(p))
    plain = meshcurv.principal_curvatures(p)
    assert np.array_equal(res.k1, plain.k1, equal_nan=True)
    assert abs(np.nanmedian(res.k1) - 1.0) < 1e-3


def test_trimesh_scene_refused_in_one_line():
    scene = trimesh.Scene([trimesh.creation.icosphere(2), trimesh.creation.box()])
    with pytest.raises(ValueError, match=r"is no one surface \(it holds 2 geometries\).*"
                                         r"to_geometry") as e:
        meshcurv.principal_curvatures(scene)
    assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match=r"\(it holds 1 geometry\)"):
        meshcurv.principal_curvatures(trimesh.Scene([trimesh.creation.icosphere(2)]))


def test_no_faces_is_a_point_cloud():
    # an empty face list (trimesh.Trimesh(vertices=points)) made every row NO_NORMAL: the
    # mesh path found no face normals; the points are a cloud
    rng = np.random.default_rng(1)
    p = rng.normal(size=(3000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    plain = meshcurv.principal_curvatures(p)
    for res in (meshcurv.principal_curvatures(p, np.zeros((0, 3), dtype=np.int64)),
                meshcurv.principal_curvatures(trimesh.Trimesh(vertices=p))):
        assert np.array_equal(res.k1, plain.k1, equal_nan=True)
        assert res.valid.all()



def test_complex_coordinates_are_refused_in_one_line():
    # numpy's float64 conversion would drop the imaginary parts with a ComplexWarning
    p = trimesh.creation.icosphere(2).vertices
    with pytest.raises(ValueError, match="vertices must be real numbers, got complex128"):
        meshcurv.principal_curvatures(p.astype(complex))
    with pytest.raises(ValueError, match="normals must be real numbers"):
        meshcurv.principal_curvatures(p, normals=(p + 0j))
