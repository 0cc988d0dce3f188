"""Faces wound against their neighbours are turned before the face normals orient anything
(meshcurv.normals.winding)."""

import numpy as np

import meshcurv
from meshcurv import surfaces
from meshcurv.neighbors import edge_adjacency
from meshcurv.normals.winding import coherent_faces, directed_edge_counts


def _torus():
    return surfaces.torus(2.0, 0.5, n_major=60, n_minor=15)


def _flipped(f, share, seed=0):
    out = f.copy()
    turn = np.random.default_rng(seed).uniform(size=len(f)) < share
    out[turn] = out[turn][:, ::-1]
    return out, int(turn.sum())


def _counts_spec(f, indptr, indices):
    """Plain numpy: for each adjacency entry (row a, entry b), the faces running a -> b."""
    a, b = f.ravel(), f[:, [1, 2, 0]].ravel()
    proper = a != b
    n = len(indptr) - 1
    runs = np.bincount(a[proper] * n + b[proper], minlength=n * n)
    rows = np.repeat(np.arange(n), np.diff(indptr))
    return runs[rows * n + indices]


def test_directed_edge_counts_against_numpy():
    s = _torus()
    for share in (0.0, 0.1, 0.5):
        f, _ = _flipped(s.faces, share, seed=3)
        f[:5, 1] = f[:5, 0]                           # degenerate faces too
        f = f[10:]                                    # and a border
        indptr, indices = edge_adjacency(f, len(s.vertices))
        counts = directed_edge_counts(f, indptr, indices)
        assert np.array_equal(counts, _counts_spec(f, indptr, indices))
        assert (counts > 1).any() == (share > 0)


def test_closed_mesh_turned_back_outward():
    s = _torus()
    for share in (0.05, 0.3, 0.7):
        f, n_turned = _flipped(s.faces, share)
        out, turned, repeated = coherent_faces(s.vertices, f)
        assert np.array_equal(out, s.faces)
        assert turned == n_turned


def test_coherent_meshes_untouched_closed_inward_ones_turned():
    s = _torus()
    out, turned, repeated = coherent_faces(s.vertices, s.faces)
    assert out is s.faces and turned == 0
    # wound inward throughout (closed): turned outward
    out, turned, repeated = coherent_faces(s.vertices, s.faces[:, ::-1])
    assert np.array_equal(out, s.faces) and turned == len(s.faces)
    # a mirror image keeps the faces, which then wind inward
    mirrored = s.vertices * [-1.0, 1.0, 1.0]
    out, turned, repeated = coherent_faces(mirrored, s.faces)
    assert np.array_equal(out, s.faces[:, ::-1]) and turned == len(s.faces)
    # open and coherent, either way round: as given
    half = s.faces[(s.vertices[s.faces][:, :, 0] > 0).all(axis=1)]
    for f in (half, half[:, ::-1]):
        out, turned, repeated = coherent_faces(s.vertices, f)
        assert out is f and turned == 0


def test_open_pieces_keep_the_winding_of_most_of_their_area():
    s = _torus()
    v = s.vertices
    half = s.faces[(v[s.faces][:, :, 0] > 0).all(axis=1)]
    f, n_turned = _flipped(half, 0.3)
    out, turned, repeated = coherent_faces(v, f)
    assert np.array_equal(out, half) and turned == n_turned
    # most of it turned: the piece follows the majority
    f, n_turned = _flipped(half, 0.7, seed=1)
    out, turned, repeated = coherent_faces(v, f)
    assert np.array_equal(out, half[:, ::-1]) and turned == len(half) - n_turned


def test_pieces_oriented_one_by_one():
    # two tori side by side, the second one partly turned: each comes back outward
    s = _torus()
    v = np.concatenate([s.vertices, s.vertices + [10.0, 0, 0]])
    second, _ = _flipped(s.faces + len(s.vertices), 0.4, seed=5)
    f = np.concatenate([s.faces, second])
    out, turned, repeated = coherent_faces(v, f)
    assert np.array_equal(out, np.concatenate([s.faces, s.faces + len(s.vertices)]))


def test_curvature_of_a_badly_wound_mesh_equals_the_coherent_one():
    # 30 % of the faces turned: 14 % of the vertices had the sign of their mean curvature
    # wrong before (face normals cancelling and flipping); now the result is the coherent
    # mesh's, and the orientation note says what was done
    s = _torus()
    f, n_turned = _flipped(s.faces, 0.3)
    res = meshcurv.principal_curvatures(s.vertices, f)
    plain = meshcurv.principal_curvatures(s.vertices, s.faces)
    for name in ("k1", "k2", "d1", "d2", "normals", "status"):
        assert np.array_equal(getattr(res, name), getattr(plain, name), equal_nan=True), name
    assert plain.orientation == "oriented like the faces"
    assert res.orientation == (f"oriented like the faces ({n_turned} of {len(f)} faces turned "
                               f"to wind like their neighbours, outward where closed)")
    # a mirrored torus: the faces wind inward; the curvature stays convex-positive outward,
    # as accurate as on the torus itself (a reflection turns the sampling planes: not bit for
    # bit)
    t = surfaces.torus(2.0, 0.5, n_major=120, n_minor=30)
    plain = meshcurv.principal_curvatures(t.vertices, t.faces)
    res = meshcurv.principal_curvatures(t.vertices * [-1.0, 1.0, 1.0], t.faces)
    assert "faces turned" in res.orientation
    for name in ("k1", "k2"):
        err, err_plain = (np.nanmean(np.abs(getattr(r, name) - getattr(t, name)))
                          for r in (res, plain))
        assert err < 1.2 * err_plain + 1e-3, (name, err, err_plain)


def test_repeated_faces_count_once():
    # a double-sided export (every triangle also wound the other way), a mesh merged with part
    # of itself, copies listed with their corners rotated: each triangle counts once, as first
    # listed. Before, the copies cut each face out of the winding's pieces (their edges had
    # 3-4 faces), a one-face piece "closed" by those edges was turned by the sign of its own
    # volume about the centroid, and its vertices' face normals cancelled: on a 120 x 30
    # torus mean |dk| 0.00093 -> 0.55 (double-sided), max 6.2 where 100 faces were repeated,
    # all marked valid
    s = _torus()
    f = s.faces
    # (faces, how many of the kept ones are turned): the inward copy listed first is kept,
    # then turned outward with its closed piece
    for faces, n_turned in ((np.concatenate([f, f[:, ::-1]]), 0),
                            (np.stack([f, f[:, ::-1]], axis=1).reshape(-1, 3), 0),
                            (np.concatenate([f, f[:100][:, [1, 2, 0]]]), 0),
                            (np.concatenate([f[:, ::-1], f]), len(f))):
        out, turned, repeated = coherent_faces(s.vertices, faces)
        assert repeated == len(faces) - len(f)
        assert np.array_equal(out, f)
        assert turned == n_turned
    # meshes without repeats report none
    for faces in (f, _flipped(f, 0.3)[0]):
        assert coherent_faces(s.vertices, faces)[2] == 0
    # the curvature of every such mesh is the single-sided one's, bit for bit
    plain = meshcurv.principal_curvatures(s.vertices, f)
    faces = np.concatenate([f, f[:, ::-1]])
    res = meshcurv.principal_curvatures(s.vertices, faces)
    for name in ("k1", "k2", "d1", "d2", "normals", "status"):
        assert np.array_equal(getattr(res, name), getattr(plain, name), equal_nan=True), name
    assert res.orientation == (f"oriented like the faces ({len(f)} of {len(faces)} faces "
                               f"repeating another left out)")


def test_command_line_says_how_many_faces_were_turned(tmp_path, capsys):
    # the orientation line of `meshcurv annotate` names the turned faces and does not offer
    # --viewpoint, which meshes do not use
    import trimesh

    from meshcurv import cli
    s = _torus()
    f, n_turned = _flipped(s.faces, 0.3)
    trimesh.Trimesh(s.vertices, f, process=False).export(str(tmp_path / "wound.ply"))
    assert cli.main(["annotate", str(tmp_path / "wound.ply"), "-o", str(tmp_path / "o.ply")]) == 0
    out = capsys.readouterr().out
    assert (f"meshcurv: normals oriented like the faces ({n_turned} of {len(f)} faces turned "
            f"to wind like their neighbours, outward where closed)\n") in out
    assert "--viewpoint" not in out
