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


def test_quads_are_split_as_trimesh_splits_them():
    # a grid torus of quads (an OBJ's faces as a numpy user holds them): the same result as
    # the triangles trimesh.Trimesh makes of them, and the torus's curvature
    from meshcurv import surfaces
    nu, nv = 60, 20
    u, w = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    corner = lambda a, b: ((a % nu) * nv + (b % nv)).ravel()        # noqa: E731
    quads = np.stack([corner(u, w), corner(u + 1, w), corner(u + 1, w + 1), corner(u, w + 1)],
                     axis=1)
    t = 2 * np.pi * np.arange(nu)[:, None] / nu
    p = 2 * np.pi * np.arange(nv)[None, :] / nv
    ring = 2.0 + 0.5 * np.cos(p)
    v = np.stack([ring * np.cos(t), ring * np.sin(t), 0.5 * np.sin(p) + 0 * t], axis=-1)
    v = v.reshape(-1, 3)
    res = meshcurv.principal_curvatures(v, quads)
    split = meshcurv.principal_curvatures(trimesh.Trimesh(v, quads, process=False))
    for name in ("k1", "k2", "d1", "d2", "normals", "status"):
        assert np.array_equal(getattr(res, name), getattr(split, name), equal_nan=True), name
    truth = surfaces.torus_at(v, 2.0, 0.5)
    # outward (convex positive), k1 = 1 / 0.5 around the tube: mean |dk1|, |dk2| measured
    # 0.0008, 0.0020 (0.04 %, 0.1 % of k1)
    assert res.valid.all()
    assert np.mean(np.abs(res.k1 - truth.k1)) < 0.005
    assert np.mean(np.abs(res.k2 - truth.k2)) < 0.005


def test_faces_refused_in_one_line_with_what_was_wrong():
    v = trimesh.creation.icosphere(1).vertices
    f = trimesh.creation.icosphere(1).faces
    for faces, says in ((f[:, :2], r"\(m, 3\) integer array of triangles .* shape \(80, 2\)"),
                        (f.ravel(), r"got shape \(240,\)"),
                        (f + 0.5, "integer vertex indices"),
                        (f.astype(bool), "integer vertex indices, got bool"),
                        (f - 1, r"found indices -1\.\.40$"),
                        (f + 1, r"found indices 1\.\.42 \(numbered from 1, as in OBJ files\? "
                                r"pass faces - 1\)")):
        with pytest.raises(ValueError, match=says) as e:
            meshcurv.principal_curvatures(v, faces)
        assert "\n" not in str(e.value)
