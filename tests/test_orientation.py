"""The global sign of estimated normals: closed clouds outward, open one-sided views towards the
viewer above (+z), LAS/LAZ input towards +z, a viewpoint where one is given - checked against
the exact normals and mean curvatures of analytic surfaces, with no normals given."""

import os

import numpy as np
import pytest

import meshcurv
from meshcurv import cli, io, surfaces
from meshcurv.normals.orient import PIECE_RULES, piece_signs
from meshcurv.result import Status

CNC = "/work/shared/bench/cnc"
# The notes CurvatureResult.orientation gives for the two rules of a spanning-tree run.
CLOSED, OPEN = (f"oriented {r}" for r in PIECE_RULES[:2])


def torus_patch(n, keep, major=3.0, minor=1.0, seed=0):
    """``n`` points uniform by area on the part of a torus about z where ``keep(u, v)`` (u
    around the z axis, v around the tube, 0 on the outer equator); exact outward normals and
    mean curvature ``(1/minor + cos v / (major + minor cos v)) / 2``, random order."""
    rng = np.random.default_rng(seed)
    uv = np.empty((0, 2))
    while len(uv) < n:
        u, v, w = rng.uniform(0.0, 2.0 * np.pi, (3, 4 * n))
        # rejection: the area element is proportional to major + minor cos v
        take = (w / (2.0 * np.pi) < (major + minor * np.cos(v)) / (major + minor)) & keep(u, v)
        uv = np.vstack([uv, np.column_stack([u[take], v[take]])])
    u, v = uv[:n].T
    rho = major + minor * np.cos(v)
    points = np.column_stack([rho * np.cos(u), rho * np.sin(u), minor * np.sin(v)])
    normals = np.column_stack([np.cos(v) * np.cos(u), np.cos(v) * np.sin(u), np.sin(v)])
    return points, normals, 0.5 * (1.0 / minor + np.cos(v) / rho)


def sphere_part(n, keep=None, inside=False, seed=0):
    """``n`` uniform points on the unit sphere where ``keep(points)``; normals outward (or, with
    ``inside``, inward: the side a viewer inside a bowl sees), mean curvature +1 (-1)."""
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(8 * n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    p = p[keep(p)][:n] if keep is not None else p[:n]
    s = -1.0 if inside else 1.0
    return p, s * p, np.full(len(p), s)


def valley_terrain(n, seed=0):
    """A terrain-like height field, a sum of three sines over the square [-5, 5]^2 whose broad
    shape is a valley (so "away from the centroid" would point down); ``n`` uniform points,
    upward normals, mean curvature convex positive under them."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform(-5.0, 5.0, (2, n))
    amp, kx, ky = np.array([0.6, 0.6, 0.1]), np.array([0.3, 0.0, 2.0]), np.array([0.0, 0.3, 1.0])
    t = np.outer(x, kx) + np.outer(y, ky) + [-np.pi / 2, -np.pi / 2, 0.0]     # (n, 3) phases
    z = np.sin(t) @ amp
    fx, fy = np.cos(t) @ (amp * kx), np.cos(t) @ (amp * ky)
    fxx, fxy, fyy = (-np.sin(t) @ (amp * a * b) for a, b in ((kx, kx), (kx, ky), (ky, ky)))
    g = np.sqrt(1.0 + fx * fx + fy * fy)
    normals = np.column_stack([-fx, -fy, np.ones(n)]) / g[:, None]
    mean = -((1 + fy * fy) * fxx - 2 * fx * fy * fxy + (1 + fx * fx) * fyy) / (2 * g ** 3)
    return np.column_stack([x, y, z]), normals, mean


def goursat_cloud():
    """The benchmark's 10k-point Goursat surface 0.03 (x^4+y^4+z^4) - 2 (x^2+y^2+z^2) - 8 = 0
    with exact outward normals; mean curvature div(grad F / |grad F|) / 2 (convex positive)."""
    d = np.loadtxt(os.path.join(CNC, "goursat_010000.pts"), comments="#")
    p, normals = d[:, :3], d[:, 3:6]
    grad = 0.12 * p ** 3 - 4.0 * p
    hess = 0.36 * p ** 2 - 4.0                     # diagonal of the Hessian
    g = np.linalg.norm(grad, axis=1)
    mean = (g ** 2 * hess.sum(axis=1) - (grad ** 2 * hess).sum(axis=1)) / (2 * g ** 3)
    return p, normals, mean


def cnc_torus():
    """The benchmark's 10k-point torus (R = 6, r = 2) with exact outward normals."""
    d = np.loadtxt(os.path.join(CNC, "torus_010000.pts"), comments="#")
    p = d[:, :3]
    cos_v = (np.hypot(p[:, 0], p[:, 1]) - 6.0) / 2.0
    return p, d[:, 3:6], 0.5 * (0.5 + cos_v / (6.0 + 2.0 * cos_v))


OPEN_VIEWS = {
    # a LiDAR-like view of a torus from above: the part facing up (n_z > 0)
    "torus_top": lambda: torus_patch(5000, lambda u, v: np.sin(v) > 0),
    # the inner, saddle-shaped half of it: its centroid lies on its convex side
    "torus_inner_top": lambda: torus_patch(5000, lambda u, v: (v > np.pi / 2) & (v < np.pi)),
    "terrain": lambda: valley_terrain(5000),
    "dome": lambda: sphere_part(4000, lambda p: p[:, 2] > 0),
    "bowl_seen_from_above": lambda: sphere_part(4000, lambda p: p[:, 2] < 0, inside=True),
}
CLOSED_CLOUDS = {
    "sphere": lambda: sphere_part(5000),
    "torus": lambda: torus_patch(8000, lambda u, v: np.ones_like(u, dtype=bool)),
    "cnc_torus": cnc_torus,
    "goursat": goursat_cloud,
}


def assert_signs_right(res, normals, mean):
    """Every valid normal on the side of the exact one, and the mean curvature's sign right
    wherever it is clearly non-zero (a third of its 90th percentile: the estimate's own error
    at the default radius is a few percent of that) and the ball is not cut by a border (at
    least 3/4 of the median neighbor count: one-sided balls have about half), but for at most
    1 in 1000 of those points: where the ball spans half a wavelength of the terrain's finest
    sine, its smoothing comes near the threshold (valley terrain of the tiled test, radius
    0.7: mean error 0.0053, 99th percentile 0.018, the worst 0.079 at a point of H 0.130,
    none of 4083 wrong; an earlier estimator put one point of H 0.091 at -0.003). A wrongly
    oriented patch flips hundreds."""
    ok = res.valid
    assert ok.mean() > 0.95
    assert (np.einsum("ij,ij->i", res.normals[ok], normals[ok]) > 0).all()
    full_ball = res.n_neighbors >= 0.75 * np.median(res.n_neighbors)
    clear = ok & full_ball & (np.abs(mean) > np.percentile(np.abs(mean), 90) / 3)
    assert clear.sum() > 0.3 * ok.sum()
    assert np.mean(np.sign(res.mean[clear]) != np.sign(mean[clear])) <= 1e-3


@pytest.mark.parametrize("name", sorted(OPEN_VIEWS))
def test_one_sided_views_face_the_viewer_above_at_the_defaults(name):
    points, normals, mean = OPEN_VIEWS[name]()
    res = meshcurv.principal_curvatures(points)
    assert res.orientation == OPEN
    assert_signs_right(res, normals, mean)


@pytest.mark.parametrize("name", sorted(CLOSED_CLOUDS))
def test_closed_clouds_point_outward_at_the_defaults(name):
    points, normals, mean = CLOSED_CLOUDS[name]()
    res = meshcurv.principal_curvatures(points)
    assert res.orientation == CLOSED
    assert_signs_right(res, normals, mean)


@pytest.mark.parametrize("name", ["terrain", "dome"])
@pytest.mark.parametrize("unit", [1e-3, 1e3])
def test_one_sided_views_face_up_in_any_unit(name, unit):
    """The same views in other units (a 10 m terrain in kilometres, a dome in millimetres): the
    pieces' areas were once compared with 1.0, so views smaller than a unit square of area
    were taken as closed and the terrain pointed down."""
    points, normals, mean = OPEN_VIEWS[name]()
    res = meshcurv.principal_curvatures(points * unit)
    assert res.orientation == OPEN
    assert_signs_right(res, normals, mean)


def test_each_connected_piece_takes_its_own_rule():
    """A closed sphere and, far from it, an open terrain in one cloud: one sign each."""
    sp, sn, sm = sphere_part(3000)
    tp, tn, tm = valley_terrain(5000)
    tp = tp + [30.0, 0.0, 0.0]
    res = meshcurv.principal_curvatures(np.vstack([sp, tp]), radius=0.6)
    assert res.orientation.startswith("oriented by piece: outward (closed surface) on 1 piece")
    assert "towards +z (open surface) on 1 piece of 5000 points" in res.orientation
    assert_signs_right(res, np.vstack([sn, tn]), np.concatenate([sm, tm]))


def test_piece_signs_rules():
    """Closed: sign of the centroid score; open facing up or down: up; open sideways: the
    centroid score; a mean normal of length 0.25 is open, just below it closed."""
    count = [1000, 1000, 1000, 1000, 1000]
    normal_sum = [[0, 0, -10], [0, 0, -600], [300, 0, 20], [0, 0, 250], [0, 0, 249]]
    score = [4.0, 9.0, -3.0, -1.0, -1.0]
    sign, rule = piece_signs(count, normal_sum, score)
    assert sign.tolist() == [1, -1, -1, 1, -1]
    assert rule.tolist() == [0, 1, 2, 1, 0]
    # areas in any unit (the sums of a tiled run are in model units squared): the same rules
    for unit in (1e-12, 1e12):
        sign, rule = piece_signs(np.multiply(count, unit), np.multiply(normal_sum, unit), score)
        assert sign.tolist() == [1, -1, -1, 1, -1] and rule.tolist() == [0, 1, 2, 1, 0]
    # a piece without area (isolated points) is left as it is
    assert piece_signs([0.0], [[0.0, 0.0, 0.0]], [0.0])[0].tolist() == [1.0]


def test_plus_z_orients_every_normal_up_on_its_own():
    points, normals, mean = valley_terrain(4000)
    res = meshcurv.principal_curvatures(points, orientation="+z")
    assert res.orientation == "oriented towards +z"
    assert_signs_right(res, normals, mean)


def test_a_viewpoint_decides_every_normal():
    """A scanner inside the bowl's sphere below it sees the bowl from its convex side."""
    points, normals, mean = sphere_part(4000, lambda p: p[:, 2] < 0)
    res = meshcurv.principal_curvatures(points, orientation=(0.0, 0.0, -50.0))
    assert res.orientation == "oriented towards the viewpoint"
    assert_signs_right(res, normals, mean)


def test_the_orientation_rule_decides_signs_only():
    """+z, a viewpoint above and the spanning tree orient a noisy terrain alike, and they give
    the same curvature: every rule's estimated normals get the same normal field for the
    normal-aware fits (plane fits over the radius and over twice it, mixed point by point,
    :func:`meshcurv.pipeline.field_mix`). When +z and viewpoints kept the plane fits over the
    radius alone: valley terrain of 60000 points, noise 0.03, mean |dH| 0.0620 against 0.0252
    with the field (measured)."""
    points, normals, mean = valley_terrain(60000, seed=3)
    noisy = points + np.random.default_rng(4).normal(scale=0.03, size=points.shape)
    inner = (np.abs(points[:, :2]) < 4.0).all(axis=1)
    errors = []
    for rule in ("+z", (0.0, 0.0, 1000.0), "mst"):
        res = meshcurv.principal_curvatures(noisy, orientation=rule)
        assert res.valid[inner].all()
        errors.append(np.mean(np.abs(res.mean - mean)[inner]))
    # the rules' start normals differ only where outlier weights fall below 1 (+z and the
    # viewpoint fit them with the weights, the spanning tree without): 1e-4 of the error
    assert max(errors) <= 1.01 * min(errors)
    assert max(errors) < 0.030


def write_las(path, points):
    """``points`` as a LAS 1.2 file (point format 3, no normals, 1e-5 scale)."""
    laspy = pytest.importorskip("laspy")
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.scales = [1e-5, 1e-5, 1e-5]
    header.offsets = [0.0, 0.0, 0.0]
    las = laspy.LasData(header)
    las.x, las.y, las.z = points.T
    las.write(str(path))


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def test_las_input_is_oriented_towards_plus_z_and_says_so(tmp_path, capsys):
    """The inner top of a torus as a LAS file: the spanning tree's "away from the centroid"
    would flip it; LAS input is seen from above."""
    points, normals, mean = torus_patch(4000, lambda u, v: (v > np.pi / 2) & (v < np.pi))
    write_las(tmp_path / "scan.las", points)
    code, out, err = run(capsys, "annotate", tmp_path / "scan.las", "-o", tmp_path / "a.ply")
    assert code == 0, err
    assert "meshcurv: normals oriented towards +z (LAS input; --viewpoint to change)" in out
    data = io.read(str(tmp_path / "a.ply"))
    valid = data.fields["valid"] > 0
    assert valid.mean() > 0.95
    assert (np.einsum("ij,ij->i", data.normals[valid], normals[valid]) > 0).all()
    clear = valid & (np.abs(mean) > np.percentile(np.abs(mean), 90) / 3)
    assert (np.sign(data.fields["mean"][clear]) == np.sign(mean[clear])).all()
    # a scanner position given by the user turns them
    code, out, err = run(capsys, "annotate", tmp_path / "scan.las", "-o", tmp_path / "b.ply",
                         "--viewpoint", "0", "0", "-100")
    assert code == 0, err
    assert "meshcurv: normals oriented towards the viewpoint" in out
    flipped = io.read(str(tmp_path / "b.ply"))
    assert (np.einsum("ij,ij->i", flipped.normals[valid], normals[valid]) < 0).all()


def test_other_clouds_say_which_rule_the_spanning_tree_took(tmp_path, capsys):
    points, _, _ = sphere_part(3000)
    np.savetxt(tmp_path / "sphere.xyz", points)
    code, out, err = run(capsys, "annotate", tmp_path / "sphere.xyz", "-o", tmp_path / "s.ply")
    assert code == 0, err
    assert "meshcurv: normals oriented outward (closed surface) (--viewpoint to change)" in out


@pytest.fixture(scope="module")
def client():
    """An in-process Dask cluster, one worker thread."""
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as c:
        yield c


def test_tiled_runs_orient_as_the_untiled_one(client):
    """"+z" is decided point by point: bit-identical to the untiled run. "mst": the groups of
    tiles take the rule a whole cloud's piece takes (here towards +z, where the old
    "away from the centroid" pointed the valley down)."""
    from meshcurv.tiled import principal_curvatures_tiled

    points, normals, mean = valley_terrain(6000, seed=3)
    radius = 0.7                       # about 90 neighbors
    for orientation in ("+z", "mst"):
        tiled = principal_curvatures_tiled(points, radius, 5.0, orientation=orientation,
                                           scheduler=client, threads_per_task=1)
        untiled = meshcurv.principal_curvatures(points, radius=radius, orientation=orientation)
        assert tiled.orientation == untiled.orientation
        assert_signs_right(tiled, normals, mean)
        if orientation == "+z":
            for name in ("k1", "k2", "normals", "valid", "status"):
                assert np.array_equal(getattr(tiled, name), getattr(untiled, name),
                                      equal_nan=name in ("k1", "k2", "normals")), name
        else:
            np.testing.assert_allclose(tiled.normals, untiled.normals, atol=1e-12)


def test_tiles_whose_overlaps_disagree_are_flipped_to_agree():
    """The vote between tiles still fixes a tile whose own propagation took the other side:
    three tiles in a row, the middle one disagreeing with both neighbors."""
    from scipy.sparse import csr_matrix

    from meshcurv.tiled.orient import _agreeing_flips

    votes = csr_matrix(np.array([[0.0, -40.0, 0.0], [-40.0, 0.0, -25.0], [0.0, -25.0, 0.0]]))
    flips, n_groups, labels = _agreeing_flips(votes)
    assert flips.tolist() == [1.0, -1.0, 1.0]
    assert n_groups == 1 and labels.tolist() == [0, 0, 0]


def test_a_closed_cloud_sampled_densely_on_one_side_still_points_outward():
    # a sphere whose lower half is sampled 10x more densely: its mean unit normal per point is
    # ~0.41 (it would read as an open view), per area ~0 (Gauss)
    rng = np.random.default_rng(5)
    p = rng.normal(size=(60000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    keep = (p[:, 2] < 0) | (rng.uniform(size=len(p)) < 0.1)
    p = p[keep][:12000]
    assert np.linalg.norm(p.mean(axis=0)) > 0.3
    res = meshcurv.principal_curvatures(p)
    assert res.orientation == CLOSED
    assert_signs_right(res, p, np.ones(len(p)))


def test_tile_area_weights_are_those_of_the_spanning_tree_graph():
    from meshcurv.normals.orient import nearest_areas, nearest_in_lists, sample_areas
    from meshcurv.pipeline import TREE_NEIGHBORS, ball_search

    rng = np.random.default_rng(6)
    p = rng.uniform(size=(3000, 3)) * [1.0, 1.0, 0.05]
    p[10] = p[11]                                    # coincident points are nobody's neighbor
    radius = 0.06
    search = ball_search(p, np.arange(len(p)), radius)
    indptr, indices = search.neighbors(np.arange(len(p)))
    near = nearest_in_lists(search.points, p, indptr, indices, TREE_NEIGHBORS)
    graph = np.where(near >= 0, search.rank[near], -1)
    np.testing.assert_allclose(nearest_areas(p, p, radius, TREE_NEIGHBORS),
                               sample_areas(p, graph), rtol=1e-12)


def _fibonacci_sphere(n):
    i = np.arange(n) + 0.5
    polar, turn = np.arccos(1 - 2 * i / n), np.pi * (1 + 5 ** 0.5) * i
    return np.column_stack([np.cos(turn) * np.sin(polar), np.sin(turn) * np.sin(polar),
                            np.cos(polar)])


def test_stacked_points_and_scan_rings_are_oriented_as_one_surface():
    # the nearest neighbours split these clouds into many pieces, each signed alone: 10
    # copies of every point of a sphere left 46 % of the signs wrong (the note said "by
    # piece"), 11 copies jittered by 1e-7 49 % (the note said "outward"), rings 0.1 apart of
    # 1000 points each 20 %
    p = _fibonacci_sphere(1500)
    rng = np.random.default_rng(0)
    rings = np.concatenate([
        np.column_stack([np.sin(t) * np.cos(a), np.sin(t) * np.sin(a), np.full_like(a, np.cos(t))])
        for t in np.linspace(0.1, np.pi - 0.1, 30)
        for a in [np.linspace(0, 2 * np.pi, 600, endpoint=False)]])
    clouds = {"copies": (np.repeat(p, 10, axis=0), None),
              "jittered": (np.repeat(p, 11, axis=0) + 1e-7 * rng.normal(size=(16500, 3)), None),
              "rings": (rings, 0.3)}
    for name, (v, radius) in clouds.items():
        res = meshcurv.principal_curvatures(v, radius=radius)
        assert res.orientation == CLOSED, name
        assert np.einsum("ij,ij->i", res.normals, v).min() > 0.9, name
        assert (res.k1[res.valid] > 0.9).all() and res.valid.mean() > 0.99, name
    # separate objects stay apart: two spheres 10 radii apart, each closed
    two = np.concatenate([p, 0.5 * p + [10.0, 0.0, 0.0]])
    res = meshcurv.principal_curvatures(two, radius=0.3)
    assert res.orientation == CLOSED
    assert (np.einsum("ij,ij->i", res.normals, two - np.where(
        np.arange(len(two))[:, None] < 1500, 0.0, [10.0, 0.0, 0.0])) > 0).all()


def test_balls_holding_one_line_of_points_do_not_decide_the_signs():
    # trimesh's 32 x 32 torus as a cloud, radius 0.37 and 0.45 below the spacing around the
    # axis (0.49 outside): the outer balls hold one ring of the tube, whose plane fits lie in
    # the ring's plane, 90 degrees off (59 % and 28 % of them), and the tree propagated its
    # signs through them: at 0.37 every normal faced inward under an "outward" note (mean
    # |dk1| 1.98). The rows are oriented again along the fitted normals, and the note says so
    import trimesh

    from meshcurv import pipeline

    v = np.asarray(trimesh.creation.torus(2.0, 0.5).vertices)
    exact = surfaces.torus_at(v, 2.0, 0.5)
    for radius in (0.37, 0.45):
        res = meshcurv.principal_curvatures(v, radius=radius)
        assert res.valid.all()
        assert np.einsum("ij,ij->i", res.normals, exact.normals).min() > 0.9, radius
        assert np.abs(res.k1 - exact.k1).mean() < 0.05, radius
        assert res.orientation.startswith(CLOSED + ", along the fitted normals"), radius
    # the default radius' plane fits agree with the fits: one tree, the note as it was
    res = meshcurv.principal_curvatures(v)
    assert res.orientation == CLOSED
    # the same object where few rows turned: a quarter of one percent of the rows
    start = res.normals.copy()
    turn = np.arange(0, len(v), 400)
    start[turn] = np.cross(start[turn], res.d1[turn])
    query = np.arange(len(v))
    search = pipeline.ball_search(v, query, res.radius)
    assert pipeline.reoriented_by_fits(res, v, start, query, search) is res
    # and a tree over the fitted normals where many did, even from signs all wrong
    start[::10] = np.cross(start[::10], res.d1[::10])
    turned = pipeline.reoriented_by_fits(res, v, -start, query, search)
    assert turned.orientation.startswith(CLOSED + ", along the fitted normals (10% ")
    np.testing.assert_array_equal(turned.normals, res.normals)
    np.testing.assert_array_equal(turned.k1, res.k1)
    assert res.orientation == CLOSED


def test_bridging_kernels_agree_with_scipy_and_numpy():
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import connected_components

    from meshcurv.normals.orient import BRIDGE_TILT, graph_pieces, nearest_in_other_piece
    rng = np.random.default_rng(3)
    n, k = 500, 3
    graph = rng.integers(-1, n, (n, k)).astype(np.int32)
    graph[rng.uniform(size=(n, k)) < 0.7] = -1                  # many pieces
    labels = graph_pieces(graph)
    rows, cols = np.nonzero(graph >= 0)
    adj = csr_matrix((np.ones(len(rows)), (rows, graph[rows, cols])), shape=(n, n))
    count, scipy_labels = connected_components(adj, directed=False)
    assert len(np.unique(labels)) == count > 10
    for piece in range(count):                       # the same partition, labelled by its
        members = np.flatnonzero(scipy_labels == piece)   # lowest index
        assert (labels[members] == members.min()).all()
    points = rng.uniform(size=(n, 3))
    points[7] = points[8]
    vertex = rng.permutation(n)                      # list entries are rows, mapped to points
    indptr = np.concatenate([[0], np.cumsum(rng.integers(0, 30, 40))]).astype(np.int64)
    indices = rng.integers(0, n, indptr[-1]).astype(np.int64)
    query = rng.uniform(size=(40, 3))
    query[0] = points[7]
    own = rng.choice(labels, 40)
    # normals by vertex (list entries map to vertices through ``vertex``), some NaN
    normals = rng.normal(size=(n, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    normals[::17] = np.nan
    query_normals = rng.normal(size=(40, 3))
    query_normals /= np.linalg.norm(query_normals, axis=1, keepdims=True)
    got = nearest_in_other_piece(points, query, indptr, indices, vertex, labels, own, normals,
                                 query_normals)
    refused = 0
    for q in range(40):
        entries = indices[indptr[q]:indptr[q + 1]]
        d = points[entries] - query[q]
        d2 = (d ** 2).sum(axis=1)
        ok = (labels[vertex[entries]] != own[q]) & (d2 > 0)
        expected = -1
        if ok.any():
            e = np.flatnonzero(ok)[np.argmin(d2[ok])]
            j = vertex[entries[e]]
            tilt = [np.abs(d[e] @ nrm) / np.sqrt(d2[e]) for nrm in (query_normals[q], normals[j])]
            # within BRIDGE_TILT of both tangent planes (a NaN normal refuses nothing)
            across = any(t > np.sin(BRIDGE_TILT) for t in tilt)
            expected = -1 if across else j
            refused += across
        assert got[q] == expected, q
    assert 3 < refused < 30                            # both outcomes are exercised


def test_unoriented_given_normals_are_named_in_the_orientation_note():
    # given normals whose signs fell at random (a plane fit left unoriented): the curvature's
    # signs follow them, and the note says so; oriented ones, even noisy, are "as given"
    rng = np.random.default_rng(2)
    p = rng.normal(size=(4000, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    noisy = p + rng.normal(scale=0.2, size=p.shape)
    assert "face away" not in meshcurv.principal_curvatures(p, normals=noisy).orientation
    signs = np.where(rng.uniform(size=len(p)) < 0.5, -1.0, 1.0)
    note = meshcurv.principal_curvatures(p, normals=p * signs[:, None]).orientation
    share = int(note.split("as given; ")[1].split(" %")[0])
    assert 25 <= share <= 45, note      # more than 3 of 6 neighbours by coin flips: 34 %
    # a mesh, with its k-rings
    s = surfaces.torus(2.0, 0.5, n_major=60, n_minor=15)
    assert meshcurv.principal_curvatures(s.vertices, s.faces,
                                         normals=s.normals).orientation == "as given"
    flipped = s.normals * np.where(np.arange(len(s.normals)) % 2, -1.0, 1.0)[:, None]
    assert "face away" in meshcurv.principal_curvatures(s.vertices, s.faces,
                                                        normals=flipped).orientation
    # coarse shapes' consistent normals turn by more than 90 degrees across a ball: only the
    # nearest neighbours whose normals lie near a point's line say anything about its side
    # (cube corners, a 32-section cylinder, an annulus read as 100 %, 100 %, 50 % facing away)
    import trimesh
    for mesh in (trimesh.creation.box(), trimesh.creation.cylinder(1, 3, sections=32),
                 trimesh.creation.annulus(0.5, 1, 2)):
        assert meshcurv.principal_curvatures(
            mesh.vertices, mesh.faces, normals=mesh.vertex_normals).orientation == "as given"


def test_given_normals_far_off_the_surface_get_no_estimate(tmp_path, capsys):
    # a given normal more than 60 degrees off the plane of its neighborhood describes no
    # surface there: its row gets no estimate (NO_NORMAL) and the note counts them; normals
    # tilted less keep their rows, and the other rows are as with good normals
    rng = np.random.default_rng(5)
    s = surfaces.sphere(1.0, subdivisions=4)

    def tilted(normals, degrees):
        side = np.cross(normals, rng.normal(size=normals.shape))
        side /= np.linalg.norm(side, axis=1, keepdims=True)
        a = np.radians(degrees)
        return np.cos(a) * normals + np.sin(a) * side

    bad = np.zeros(len(s.vertices), dtype=bool)
    bad[rng.choice(len(bad), len(bad) // 10, replace=False)] = True
    for faces in (s.faces, None):
        given = s.normals.copy()
        given[bad] = tilted(s.normals[bad], 75.0)
        res = meshcurv.principal_curvatures(s.vertices, faces, normals=given)
        assert (res.status[bad] == Status.NO_NORMAL).all()
        assert np.isnan(res.k1[bad]).all() and np.isnan(res.normals[bad]).all()
        assert res.valid[~bad].all()
        np.testing.assert_allclose(res.k1[~bad], 1.0, atol=1e-6)
        np.testing.assert_allclose(res.k2[~bad], 1.0, atol=1e-6)
        assert f"; {bad.sum()} given normals are more than 60 degrees off" in res.orientation
        # 40 degrees off: an estimate about that normal, as given
        res = meshcurv.principal_curvatures(s.vertices, faces,
                                            normals=tilted(s.normals, 40.0))
        assert res.valid.all() and res.orientation == "as given"
    # every normal off: the command line says why nothing was estimated, and what to do
    side = tilted(s.normals, 90.0)
    io.write_ply(str(tmp_path / "off.ply"), s.vertices, None,     # a cloud: its own normals
                 {"nx": side[:, 0], "ny": side[:, 1], "nz": side[:, 2]})
    code = cli.main(["annotate", str(tmp_path / "off.ply"), "-o", str(tmp_path / "out.ply")])
    err = capsys.readouterr().err
    assert code != 0 and "given normals are unusable" in err and "--normals estimate" in err, err
    assert not (tmp_path / "out.ply").exists()


def test_a_sphere_above_a_floor_takes_its_own_sign():
    """A unit sphere of 8000 random points 0.1 above a floor of 40k (the default radius,
    0.22, reaches across the gap): the bridge between the two pieces of the spanning tree's
    graph ran from the sphere's bottom straight down, across the gap, and the sphere took the
    floor's side, inward (k = -1 on 97 % of its points, all valid). Now the sphere is a piece
    of its own, closed, outward; the floor faces +z; every point farther than the radius from
    the other surface is exact. The 1052 points nearer (balls holding both surfaces, their
    plane-fit normals tilted) are not: 381 WRAPS_AROUND, 669 of the others more than 0.1 off."""
    from scipy.spatial import cKDTree
    rng = np.random.default_rng(0)
    sphere = meshcurv.surfaces.sphere(1.0, sampling="random", n=8000, seed=1).vertices
    sphere = sphere + [0.0, 0.0, 1.1]
    floor = np.column_stack([rng.uniform(-4, 4, (40_000, 2)), np.zeros(40_000)])
    res = meshcurv.principal_curvatures(np.vstack([sphere, floor]))
    assert "outward (closed surface) on 1 piece of 8000 points" in res.orientation
    apart = np.r_[cKDTree(floor).query(sphere)[0], cKDTree(sphere).query(floor)[0]] > res.radius
    k = np.r_[np.ones(len(sphere)), np.zeros(len(floor))]
    assert res.valid[apart].all()
    assert np.abs(res.k1 - k)[apart].max() < 1e-9 and np.abs(res.k2 - k)[apart].max() < 1e-9
    assert np.all(res.normals[len(sphere):][apart[len(sphere):], 2] > 0.99)
