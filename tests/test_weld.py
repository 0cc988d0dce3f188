"""Coincident vertices joined for the neighbourhoods (meshcurv.weld): triangle soups and meshes
split along seams get the estimate of the mesh their copies make together."""

import numpy as np
import pytest

import meshcurv
from meshcurv import surfaces, weld


def _torus(n_major=60, n_minor=15):
    return surfaces.torus(2.0, 0.5, n_major=n_major, n_minor=n_minor)


def _soup_after_vertices(v, f):
    """The mesh's vertices, then one copy per triangle corner, the faces on the copies."""
    n = len(v)
    return np.concatenate([v, v[f].reshape(-1, 3)]), n + np.arange(3 * len(f)).reshape(-1, 3)


def _rows_equal(a, b, rows_a=slice(None), rows_b=slice(None)):
    """Every per-row field of two results equal bit for bit (NaN equal to NaN)."""
    for name in ("k1", "k2", "d1", "d2", "normals", "valid", "n_neighbors", "n_samples",
                 "residual", "noise", "status", "outlier_score", "radius_used"):
        x, y = getattr(a, name)[rows_a], getattr(b, name)[rows_b]
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), name


def test_no_coincident_rows_no_welding():
    # grids symmetric about the coordinate planes: mirror images differ in sign bits only
    s = _torus()
    assert weld.coincident_vertices(s.vertices) is None
    g = np.stack(np.meshgrid(*[np.linspace(-1, 1, 11)] * 3, indexing="ij"), -1).reshape(-1, 3)
    assert weld.coincident_vertices(g) is None
    assert weld.coincident_vertices(np.zeros((1, 3))) is None


def test_groups_exact_positions_first_vertex_leads():
    v = np.array([[1.0, 2.0, 3.0],
                  [0.0, 0.0, 1.0],
                  [1.0, 2.0, 3.0],
                  [np.nan, 0.0, 0.0],
                  [-0.0, 0.0, 1.0],          # equal to row 1
                  [np.nan, 0.0, 0.0],        # NaN rows stay their own
                  [1.0, 2.0, 3.0 + 1e-15]])
    w = weld.coincident_vertices(v)
    assert w.keep.tolist() == [0, 1, 3, 5, 6]
    assert w.index.tolist() == [0, 1, 0, 2, 1, 3, 4]


def test_hash_collisions_fall_back_to_sorting(monkeypatch):
    # every row gets the same hash: the groups must come out the same
    v = np.array([[1.0, 2.0, 3.0], [3.0, 2.0, 1.0], [1.0, 2.0, 3.0], [3.0, 2.0, 1.0],
                  [5.0, 5.0, 5.0]])
    expected = weld.coincident_vertices(v)
    monkeypatch.setattr(weld, "_mix", lambda x: np.zeros_like(x))
    w = weld.coincident_vertices(v)
    assert w.keep.tolist() == expected.keep.tolist() == [0, 1, 4]
    assert w.index.tolist() == expected.index.tolist() == [0, 1, 0, 1, 2]
    assert weld.coincident_vertices(v[[0, 1, 4]]) is None


def test_soup_after_its_vertices_equals_the_mesh_bit_for_bit():
    # the mesh's vertices, then one copy per triangle corner: joined, the welded mesh is the
    # mesh itself, so every row is the mesh's and every copy its vertex's
    s = _torus()
    v, f = s.vertices, s.faces
    n = len(v)
    soup_v, soup_f = _soup_after_vertices(v, f)
    plain = meshcurv.principal_curvatures(v, f)
    res = meshcurv.principal_curvatures(soup_v, soup_f)
    assert len(res) == len(soup_v)
    _rows_equal(res, plain, slice(0, n))
    _rows_equal(res, plain, slice(n, None), f.ravel())


def test_triangle_soup_is_estimated_like_the_mesh():
    # a soup alone (every corner its own vertex): before welding no row had an estimate
    # (each k-ring was one triangle); now every row has, as accurate as on the mesh (the
    # welded vertices come in another order, which turns the tangent frames: not bit for bit)
    s = _torus(120, 30)
    soup_v, soup_f = s.vertices[s.faces].reshape(-1, 3), np.arange(3 * len(s.faces)).reshape(-1, 3)
    res = meshcurv.principal_curvatures(soup_v, soup_f)
    plain = meshcurv.principal_curvatures(s.vertices, s.faces)
    assert res.valid.all()
    err_soup = np.abs(res.k1 - s.k1[s.faces.ravel()]).mean()
    err_mesh = np.abs(plain.k1 - s.k1).mean()
    assert err_soup < 1.5 * err_mesh + 1e-4, (err_soup, err_mesh)
    # copies of one vertex share its row
    copies = np.flatnonzero(s.faces.ravel() == s.faces[0, 0])
    assert len(copies) == 6
    assert np.all(res.k1[copies] == res.k1[copies[0]])


def test_seam_split_mesh_equals_the_welded_mesh():
    # one seam of the torus split as texture seams are: the vertices of one meridian copied,
    # the triangles on one side moved to the copies. Measured before welding: mean |dk| of
    # the vertices near the seam 0.0028 against 0.0006 on the intact torus
    s = _torus(240, 60)
    v, f = s.vertices, s.faces
    n = len(v)
    seam = np.arange(60)                       # the meridian u = 0
    last = np.arange(n - 60, n)                # the meridian before it
    side = np.isin(f, last).any(axis=1) & np.isin(f, seam).any(axis=1)
    split_f = f.copy()
    split_f[side] = np.where(np.isin(f[side], seam), n + f[side], f[side])
    split_v = np.concatenate([v, v[seam]])
    plain = meshcurv.principal_curvatures(v, f, radius=0.3)
    res = meshcurv.principal_curvatures(split_v, split_f, radius=0.3)
    _rows_equal(res, plain, slice(0, n))
    _rows_equal(res, plain, slice(n, None), seam)


def test_soup_normals_given_per_face_average_to_the_vertex_normal():
    # each copy carries its triangle's normal (an STL's facet normals): the welded vertex
    # takes their mean, within a few degrees of the surface normal on this mesh
    s = _torus(120, 30)
    tri = s.vertices[s.faces]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    soup_v, soup_f = tri.reshape(-1, 3), np.arange(3 * len(s.faces)).reshape(-1, 3)
    soup_n = np.repeat(fn, 3, axis=0)
    res = meshcurv.principal_curvatures(soup_v, soup_f, normals=soup_n)
    exact = s.normals[s.faces.ravel()]
    cos = np.einsum("ij,ij->i", res.normals, exact)
    assert cos.min() > np.cos(np.radians(3.0))
    assert res.valid.all()
    err = np.abs(res.k1 - s.k1[s.faces.ravel()]).mean()
    assert err < 0.02, err


def test_welded_mesh_normals():
    v = np.array([[0.0, 0, 0], [0, 0, 0], [1, 0, 0], [1, 0, 0], [2, 0, 0], [2, 0, 0]])
    f = np.array([[0, 2, 4], [1, 3, 5]])
    nv = np.array([[0.0, 0, 2], [0, 1, 0], [0, 0, 1], [0, 0, -1], [np.nan, 0, 0], [0, 0, 3]])
    w = weld.coincident_vertices(v)
    vw, fw, nw = weld.welded_mesh(v, f, nv, w)
    assert fw.tolist() == [[0, 1, 2], [0, 1, 2]]
    h = np.sqrt(0.5)
    # the copies' unit normals averaged; cancelling ones keep the first copy's (as given);
    # NaN copies are left out
    assert np.allclose(nw, [[0, h, h], [0, 0, 1], [0, 0, 1]])
    assert weld.welded_mesh(v, f, None, w)[2] is None


def test_query_and_radius_list_on_a_soup():
    s = _torus()
    v, f = s.vertices, s.faces
    n = len(v)
    soup_v, soup_f = _soup_after_vertices(v, f)
    copy = n + int(np.flatnonzero(f.ravel() == 7)[0])
    query = [copy, 7, 3, 7]
    res = meshcurv.principal_curvatures(soup_v, soup_f, query=query)
    plain = meshcurv.principal_curvatures(v, f, query=[7, 7, 3, 7])
    _rows_equal(res, plain)
    both = meshcurv.principal_curvatures(soup_v, soup_f, radius=[0.4, 0.6], query=query)
    plain_both = meshcurv.principal_curvatures(v, f, radius=[0.4, 0.6], query=[7, 7, 3, 7])
    assert len(both) == 2
    for a, b in zip(both, plain_both):
        _rows_equal(a, b)


@pytest.mark.parametrize("neighborhood", ["ball", "kring"])
def test_vertices_listed_twice_are_estimated_once(neighborhood):
    # every vertex listed twice, the faces on the first copies: with k-rings or balls each
    # copy gets the mesh's own row (balls would otherwise hold every point twice, and the
    # second copies no k-ring)
    s = _torus()
    v, f = s.vertices, s.faces
    res = meshcurv.principal_curvatures(np.concatenate([v, v]), f, neighborhood=neighborhood)
    plain = meshcurv.principal_curvatures(v, f, neighborhood=neighborhood)
    _rows_equal(res, plain, slice(0, len(v)))
    _rows_equal(res, plain, slice(len(v), None))
