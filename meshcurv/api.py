"""The estimator, top to bottom: neighbourhoods -> normals and frames -> directional circle fits
-> Euler (sine) fit -> outputs.
"""


import numpy as np
from scipy.spatial import cKDTree
from tqdm.auto import tqdm

from . import normals as nrm
from .fit import fused, jet
from .normals import orient
from .options import check_options
from .result import CurvatureResult
from .neighbors import (BallGrid, KringWork, ball_counts, ball_grid, ball_neighbors,
                        default_radius, edge_adjacency, kring_counts, kring_neighbors,
                            power_of_two_scale, spatial_order)

__all__ = ["principal_curvatures", "estimate_normals", "no_estimate_reason"]

# Query points per call into the kernels: bounds the memory of the neighbour lists (about
# 0.8 kB per query point at 100 neighbours) at no measurable cost in speed.
_BLOCK = 16384
# Neighbour list entries per block (int64): blocks shrink where the balls hold more than
# 1024 points (a radius much larger than the sampling), so their lists stay within ~128 MB.
_BLOCK_ENTRIES = 2 ** 24
# Most neighbour pairs (query points x neighbours) a call takes on: hours of work beyond.
MAX_PAIRS = 1e11

# Noise level (RMS height residual of the local cubic fit, as a fraction of the radius) at
# which weighting="auto" mixes equal and distance weights half and half. Measured: clean
# samples of the test surfaces stay below 0.09 % of the radius (Table 2 paraboloid 0.02 %,
# torus 0.08 %), normal noise of 0.03 % of the bounding-box diagonal already gives 0.6-0.9 %,
# and from there on equal weights are the more accurate.
NOISE_SCALE = 2e-3


def _mix_normals(start, refined, beta):
    """``start + beta (refined - start)``, normalised, row by row.

    With beta from the measured noise: the quadric's normal on clean data (no tilt from
    irregular sampling), the starting one (usually the plane fit's, which averages the most
    points) under noise.
    """
    mixed = start + beta[:, None] * (refined - start)
    with np.errstate(invalid="ignore", divide="ignore"):
        return mixed / np.linalg.norm(mixed, axis=1, keepdims=True)


def weight_blend(noise, radius, weighting="auto"):
    """Per-vertex mix of the circle fits' weight functions, in [0, 1] (1 = distance weights).

    "auto": ``1 / (1 + (noise / (NOISE_SCALE * radius))^4)``, i.e. distance weights where the
    local cubic fit explains the points (clean data: less bias), equal weights where it leaves
    noise (less variance); NaN noise (too few points for the fit) gives equal weights.
    """
    noise = np.asarray(noise, dtype=np.float64)
    if weighting == "distance":
        return np.ones_like(noise)
    if weighting == "none":
        return np.zeros_like(noise)
    with np.errstate(invalid="ignore"):
        beta = 1.0 / (1.0 + (noise / (NOISE_SCALE * radius)) ** 4)
    return np.where(np.isfinite(beta), beta, 0.0)

# Neighbours per point in the graph of the spanning-tree orientation.
_TREE_NEIGHBOURS = 10


def _as_arrays(vertices, faces, normals):
    """Validate and convert inputs; a trimesh.Trimesh supplies vertices and faces."""
    if hasattr(vertices, "vertices") and hasattr(vertices, "faces"):
        if faces is None:
            faces = vertices.faces
        vertices = vertices.vertices
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be an (n, 3) array, got shape {v.shape}")
    v = np.ascontiguousarray(v)
    f = None
    if faces is not None:
        f = np.asarray(faces)
        if f.size == 0:
            f = np.zeros((0, 3), dtype=np.int64)
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"faces must be an (m, 3) integer array, got shape {f.shape}")
        if not np.issubdtype(f.dtype, np.integer):
            if not np.all(np.mod(f, 1) == 0):
                raise ValueError("faces must hold integer vertex indices")
        f = f.astype(np.int64, copy=False)
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(
                f"faces index vertices 0..{len(v) - 1}, found indices {f.min()}..{f.max()}")
    nv = None
    if normals is not None:
        nv = np.asarray(normals, dtype=np.float64)
        if nv.shape != v.shape:
            raise ValueError(f"normals must have the shape of vertices {v.shape}, got {nv.shape}")
    return v, f, nv


def _blocks(order, progress, desc, size=_BLOCK):
    """Blocks of ``size`` positions, with a progress bar when asked.

    ``order`` is an index array (blocks are its pieces) or a count m (blocks are slices of
    ``range(m)``, which index without copies).
    """
    m = order if isinstance(order, (int, np.integer)) else len(order)
    bar = tqdm(total=m, desc=desc, unit="pt", disable=not progress, leave=False)
    for s in range(0, m, size):
        e = min(s + size, m)
        yield slice(s, e) if isinstance(order, (int, np.integer)) else order[s:e]
        bar.update(e - s)
    bar.close()


def _block_size(counts, n_queries, radius, what):
    """Queries per block for neighbour lists of about ``mean(counts)`` entries, raising
    ValueError where ``n_queries`` such lists are more work than :data:`MAX_PAIRS`."""
    per = max(float(np.mean(counts)) if len(counts) else 0.0, 1.0)
    if per * n_queries > MAX_PAIRS:
        raise ValueError(
            f"radius {radius:.6g} is too large for these {what}: each neighbourhood would hold "
            f"about {per:.3g} points ({per * n_queries:.3g} neighbour pairs in all, far too "
            f"many to compute); use a smaller radius")
    return int(min(_BLOCK, max(1, _BLOCK_ENTRIES // per)))


def _sample_queries(m, size=64):
    """Up to ``size`` positions spread over ``range(m)``."""
    return np.unique(np.linspace(0, m - 1, min(m, size)).astype(np.int64)) if m else \
        np.zeros(0, dtype=np.int64)


def _ball_search(v, finite, radius):
    """Ball queries over the finite rows of ``v``: ``(neighbours, counts, kernel_points, rank)``.

    ``neighbours(idx)`` gives the CSR lists of the points ``v[idx]``, unsorted (the kernels do
    not depend on the order within a list); ``counts(idx)`` their lengths, nothing stored. With a uniform grid (when one fits; the same lists
    as a k-d tree, several times faster) the lists hold rows of ``kernel_points``, the grid's
    copy of the points in grid order, where a neighbourhood lies together in memory however
    the input is ordered; ``rank`` gives their vertex indices. With the k-d tree fallback
    ``kernel_points`` is ``v`` and ``rank`` None.
    """
    tree = ball_grid(v, radius) if len(finite) else None
    if tree is None and len(finite):
        tree = cKDTree(v[finite])
    in_grid = isinstance(tree, BallGrid)

    def neighbours(idx):
        if tree is None:
            return np.zeros(len(idx) + 1, dtype=np.int64), np.zeros(0, dtype=np.int64)
        return ball_neighbors(tree, finite, v[idx], radius, ascending=False, positions=in_grid)

    def counts(idx):
        if tree is None:
            return np.zeros(len(idx), dtype=np.int64)
        return ball_counts(tree, v[idx], radius)

    return (neighbours, counts, (tree.sorted_points if in_grid else v),
            (tree.order if in_grid else None))


def _mst_normals(v, radius, neighbours, kernel_points, rank, progress, block=_BLOCK):
    """PCA normals of every point, oriented along a spanning tree whose graph joins each point
    to its nearest neighbours, taken from the ball lists at hand (see :func:`_ball_search`)."""
    n = len(v)
    nv = np.full((n, 3), np.nan)
    graph = np.full((n, _TREE_NEIGHBOURS), -1, dtype=np.int32)
    # the grid's own cell order (``rank``) when there is one, else one made for the purpose
    order = rank if rank is not None else spatial_order(v, radius)
    for pos in _blocks(order, progress, "normals", block):
        indptr, indices = neighbours(pos)
        nv[pos] = nrm.pca_normals(kernel_points, v[pos], indptr, indices, radius)
        near = orient.nearest_in_lists(kernel_points, v[pos], indptr, indices, _TREE_NEIGHBOURS)
        graph[pos] = near if rank is None else np.where(near >= 0, rank[near], -1)
    return nrm.orient_mst(v, nv, neighbors=graph)


def estimate_normals(points, radius, progress=False):
    """Unit normals of a point cloud, consistently oriented: what :func:`principal_curvatures`
    uses when it gets neither normals nor faces.

    A PCA plane fit over the ball of ``radius`` around each point, then signs propagated along
    a minimum spanning tree (Hoppe et al. 1992) and each connected piece turned outward (see
    :func:`meshcurv.normals.orient_mst`). For a subset whose balls lie inside ``points`` (a
    tile and its halo), the normals of the subset equal those of the whole cloud up to sign.

    Parameters
    ----------
    points : (n, 3) float, model units (NaN rows get NaN normals and are nobody's neighbour)
    radius : float, model units
    progress : bool, show a progress bar

    Returns
    -------
    (n, 3) float64 unit normals; NaN where the ball holds fewer than 3 points.

    Example
    -------
    >>> import numpy as np, meshcurv
    >>> s = meshcurv.surfaces.sphere(subdivisions=3)
    >>> nv = meshcurv.estimate_normals(s.vertices, radius=0.3)
    >>> bool(np.all(np.einsum("ij,ij->i", nv, s.normals) > 0.99))
    True
    """
    v = np.ascontiguousarray(points, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"points must have shape (n, 3), got {v.shape}")
    radius = float(radius)
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive finite number of model units, got {radius}")
    s = power_of_two_scale(radius)
    if s != 1.0:
        # lengths whose squares overflow (underflow) in float64: on exactly rescaled points
        with np.errstate(over="ignore"):
            return estimate_normals(v * s, radius * s, progress)
    finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    neighbours, counts, kernel_points, rank = _ball_search(v, finite, radius)
    block = _block_size(counts(finite[_sample_queries(len(finite))]), len(finite), radius,
                        "points")
    return _mst_normals(v, radius, neighbours, kernel_points, rank, progress, block)


def _no_default_radius(points):
    """Why no default radius can be derived from the finite ``points`` (2 or more)."""
    if np.all(points == points[0]):
        return (f"all {len(points)} points coincide: there is no surface and no radius can be "
                "derived from their spacing; pass a radius to get all-invalid rows")
    with np.errstate(over="ignore", invalid="ignore"):
        spread = np.ptp(points, axis=0)
    why = ("their distances are too large to square in float64"
           if not np.all(np.isfinite(spread)) or spread.max() > 1e150 else
           "most of them coincide")
    return (f"no radius can be derived from the spacing of these {len(points)} points ({why}; "
            f"extent {np.array2string(spread, precision=3)}); pass a radius in model units")


def no_estimate_reason(result, n_points, option="radius"):
    """Why a :class:`CurvatureResult` with no valid row got none, and what to try: one line.

    ``n_points`` is the number of finite input points; ``option`` names the radius as the
    caller's user knows it (e.g. "--radius"). Balls holding nearly every point mean a radius
    far too large (fits see a whole object, no surface patch); balls with few neighbours one
    too small.
    """
    nn = np.asarray(result.n_neighbors)
    med = float(np.median(nn)) if len(nn) else 0.0
    if n_points > 2 and med >= 0.5 * (n_points - 1):
        return (f"the radius {result.radius:.6g} is far too large: each ball holds nearly every "
                f"point (median {med:.0f} of {n_points}); try a much smaller {option}")
    if med < 12:
        return (f"the radius {result.radius:.6g} is too small: its balls hold a median of "
                f"{med:.0f} neighbours; try a larger {option}")
    return (f"no neighbourhood of radius {result.radius:.6g} (median {med:.0f} neighbours) spans "
            f"a surface patch in enough directions (points along lines or curves, one-sided "
            f"or coincident); try another {option}")


def principal_curvatures(vertices, faces=None, normals=None, radius=None, n_directions=8,
                         neighborhood="auto", *, slab=0.25, min_points=3, min_spread=0.25,
                         weighting="auto", circle_normalization="tangent",
                         section_blend=True, robust=True,
                         half_frequency=False, normal_estimation="auto", refine_normals=None,
                         orientation="mst",
                         query=None, progress=False):
    """Principal curvatures by CGA circle fits in normal sections (Seibert et al.).

    At every vertex x: the neighbours within ``radius`` are split by ``n_directions`` planes
    through the normal into ``2 * n_directions`` half-sets; a circle centred on the normal line
    is fitted to each (a 3x3 eigenproblem in conformal geometric algebra); the Euler model
    ``kappa(theta) = A + B cos 2theta + C sin 2theta`` fitted to those curvatures gives k1, k2
    and their directions.

    Parameters
    ----------
    vertices : (n, 3) float or trimesh.Trimesh
        Points, model units. Never reordered; NaN/inf rows give NaN results.
    faces : (m, 3) int, optional
        Triangles, counter-clockwise seen from outside. Enables the k-ring neighbourhood and
        face-based normal orientation.
    normals : (n, 3) float, optional
        Outward normals, used as given (normalised). Default: estimated, see
        ``normal_estimation``.
    radius : float or "auto", optional
        Neighbourhood radius, model units. Default: the radius whose ball holds about 100
        points (:func:`meshcurv.neighbors.default_radius`; ~5 mean edge lengths).
        "auto": one radius per mesh that balances the noise measured on the data against the
        circle model's bias (:func:`meshcurv.autoradius.auto_radius`; a few pilot runs on a
        sample of vertices). The radius used is ``result.radius``.
    n_directions : int, default 8
        Planes through the normal, i.e. ``2 * n_directions`` circle fits per vertex.
    neighborhood : {"auto", "kring", "ball"}
        "kring": vertices reachable over mesh edges without leaving the ball (needs faces;
        never leaks across thin sheets). "ball": all points within ``radius``. "auto": kring
        when faces are given, else ball.
    slab : float, default 0.25
        Half-width of each plane's slab, as a fraction of ``radius``. Wider slabs use more
        points (less noise) at the price of a blend of directions, which ``section_blend``
        models.
    min_points : int, default 3
        Fewest neighbours (besides x) a half-set needs to be fitted.
    min_spread : float, default 0.25
        Fewest fraction of ``radius`` the farthest point of a half-set must reach along its
        direction; rejects one-sided stubs near borders and holes.
    weighting : {"auto", "distance", "none"}
        Weights of the points in each circle fit. "distance": ``(1 - r^2 / radius^2)^4``,
        which favours near points: where the curvature varies inside the ball it halves the
        error of equal weights (Table 2 paraboloid, radius 2: mean |dk1| 0.0015 vs 0.0030).
        "none": equal weights, about a third of the noise-induced error. "auto" (default): per
        vertex, distance weights where the local cubic fit leaves no noise and equal weights
        where it does, mixed smoothly (:func:`weight_blend`).
    circle_normalization : {"tangent", "unit"}
        Normalisation of the CGA sphere vector t in each circle fit. "unit": |t| = 1, the
        smallest eigenvector of the 3x3 matrix (the paper). "tangent" (default): t1 = 1, the
        same eigenproblem with normalisation matrix diag(1, 0, 0); identical on exact data, but
        it cannot drift to spheres centred at x, whose curvature is unbounded - with noise of
        15 % of the radius the unit form has a 6x wider spread and 1000x outliers.
    section_blend : bool, default True
        Fit the Euler model to the direction mix each half-set really measured (from its own
        points) instead of the plane's nominal angle. Removes the slab's blurring of k1 - k2.
    robust : bool, default True
        Drop circle fits further than 3 robust sigmas from the Euler model and refit.
    half_frequency : bool, default False
        Add ``cos theta, sin theta`` terms (the paper's half-frequency fit, linear form) to
        absorb differences between opposite directions.
    normal_estimation : {"auto", "faces", "pca"}
        Used when ``normals`` is None. "faces": area-weighted face normals. "pca": normal of
        the least-squares plane through the same neighbourhood, oriented by the faces if there
        are any, else by ``orientation``. "auto" (default): "pca" - on noisy meshes face normals
        are the worst choice (0.3 % noise, random sphere: mean |dk1| + |dk2| 0.60 with face
        normals, 0.38 with PCA ones; max |dk1| 13 vs 0.9), on clean ones the refinement below
        makes the two equal.
    refine_normals : bool or None, default None
        Refine the normals by a local quadric fit over the same neighbourhood before the
        circle fits (:func:`meshcurv.jet.local_jet`), mixed with the starting normal by
        the measured noise (the mix of ``weighting="auto"``, :func:`weight_blend`, whatever
        ``weighting`` is): face and PCA normals
        tilt with irregular sampling (0.7 degrees on a random sphere, up to 3 % in
        curvature), the quadric's normal does not but is noisier. None: refine estimated
        normals, use given ones as they are; True: refine given normals too; False: never.
    orientation : "mst" or (3,) array-like
        Global orientation of estimated point-cloud normals: "mst" propagates along a minimum
        spanning tree and then turns each connected piece away from its own centroid; a (3,)
        point orients every normal towards it (a scanner position).
    query : (q,) int, optional
        Estimate only at these vertex indices (neighbours still come from all vertices); the
        result then has q rows in this order.
    progress : bool, default False
        Show a progress bar.

    Returns
    -------
    CurvatureResult
        ``k1, k2, d1, d2, normals, valid, mean, gaussian, shape_index, curvedness``, the
        diagnostics ``n_neighbors, n_samples, residual, noise`` (one row per vertex, or per
        query) and the ``radius`` used.

    Raises
    ------
    ValueError
        Wrong shapes, face indices out of range, unknown option values.

    Examples
    --------
    >>> import meshcurv, numpy as np, trimesh
    >>> sphere = trimesh.creation.icosphere(subdivisions=4, radius=2.0)
    >>> res = meshcurv.principal_curvatures(sphere, radius=0.4)
    >>> bool(abs(np.nanmedian(res.k1) - 0.5) < 1e-3)
    True
    """
    v, f, given_normals = _as_arrays(vertices, faces, normals)
    n = len(v)
    orientation = check_options(neighborhood=neighborhood, normal_estimation=normal_estimation,
                                orientation=orientation, weighting=weighting,
                                circle_normalization=circle_normalization,
                                n_directions=n_directions)
    if neighborhood == "kring" and f is None:
        raise ValueError("neighborhood='kring' needs faces")
    use_kring = f is not None and neighborhood != "ball"
    if query is None:
        query = np.arange(n, dtype=np.int64)
    else:
        query = np.asarray(query, dtype=np.int64).ravel()
        if query.size and (query.min() < 0 or query.max() >= n):
            raise ValueError(f"query indices must lie in 0..{n - 1}")
    finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    derived = radius is None or isinstance(radius, str)
    if radius is None:
        radius = default_radius(v)
    elif isinstance(radius, str):
        if radius != "auto":
            raise ValueError(f"radius must be a number of model units, None or 'auto', got {radius!r}")
        from .autoradius import auto_radius     # it calls this function for its pilot runs

        # pilot runs with this call's own options (a viewpoint, too: no spanning tree then)
        radius = auto_radius(v, f, normals=given_normals, weighting=weighting, slab=slab,
                             n_directions=n_directions, neighborhood=neighborhood,
                             normal_estimation=normal_estimation, refine_normals=refine_normals,
                             orientation=orientation, min_spread=min_spread,
                             circle_normalization=circle_normalization,
                             section_blend=section_blend, robust=robust,
                             half_frequency=half_frequency)
    radius = float(radius)
    if derived and len(finite) > 1 and not (np.isfinite(radius) and radius > 0):
        raise ValueError(_no_default_radius(v[finite]))
    if len(finite) > 1 and not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive finite number of model units, got {radius}")
    scale = power_of_two_scale(radius)
    if scale != 1.0:
        # squares of lengths this large (small) overflow (underflow) in float64; the estimator
        # is scale-equivariant, and scaling by a power of two is exact
        with np.errstate(over="ignore"):
            res = principal_curvatures(
                v * scale, f, given_normals, radius * scale, n_directions, neighborhood,
                slab=slab, min_points=min_points, min_spread=min_spread, weighting=weighting,
                circle_normalization=circle_normalization, section_blend=section_blend,
                robust=robust, half_frequency=half_frequency,
                normal_estimation=normal_estimation, refine_normals=refine_normals,
                orientation=orientation if isinstance(orientation, str) else orientation * scale,
                query=query, progress=progress)
        with np.errstate(over="ignore"):
            for name in ("k1", "k2", "residual"):
                setattr(res, name, getattr(res, name) * scale)
            res.noise = res.noise / scale
        # curvatures of a subnormal-sized cloud may exceed float64: no estimate there
        lost = res.valid & ~(np.isfinite(res.k1) & np.isfinite(res.k2))
        for name in ("k1", "k2", "d1", "d2", "residual"):
            getattr(res, name)[lost] = np.nan
        res.valid &= ~lost
        res.radius = radius
        return res

    # 1. neighbourhoods: connected k-ring limited to the ball, or a ball query
    if use_kring:
        adjacency = edge_adjacency(f, n)
        work = KringWork(n)

        def neighbours(idx):
            return kring_neighbors(v, adjacency, radius, idx, work)

        def counts(idx):
            return kring_counts(v, adjacency, radius, idx, work)
        kernel_points, rank = v, None
    else:
        neighbours, counts, kernel_points, rank = _ball_search(v, finite, radius)
    # work per query from a sample: smaller blocks for large balls, an error for infeasible ones
    block = _block_size(counts(query[_sample_queries(len(query))]), len(query), radius,
                        "vertices" if f is not None else "points")

    # 2. normals: given, from the faces, or a PCA plane fit over each block's neighbourhood
    # (oriented by the faces or towards the viewpoint block by block; along a spanning tree in
    # a first pass of its own, as the tree needs every normal)
    method = normal_estimation
    if method == "auto":
        method = "pca"
    if method == "faces" and given_normals is None and f is None:
        raise ValueError("normal_estimation='faces' needs faces")
    viewpoint = None if isinstance(orientation, str) else orientation
    tree_orient = given_normals is None and method == "pca" and f is None and viewpoint is None
    # PCA normals block by block, where the orientation needs no other block
    estimate = given_normals is None and method == "pca" and not tree_orient
    face_normals = None
    if given_normals is not None:
        nv = given_normals
    elif f is not None:
        with np.errstate(invalid="ignore"):       # NaN vertices give NaN normals
            face_normals = nrm.face_vertex_normals(v, f)
        nv = face_normals
    refine = given_normals is None if refine_normals is None else bool(refine_normals)

    if tree_orient:
        block_all = _block_size(counts(finite[_sample_queries(len(finite))]), len(finite),
                                radius, "points")
        nv = _mst_normals(v, radius, neighbours, kernel_points, rank, progress, block_all)

    # 3-5. directional circle fits and the Euler fit, in the compiled kernel, block by block
    # in a spatially coherent order of the queries
    m = len(query)
    k1 = np.full(m, np.nan)
    k2 = np.full(m, np.nan)
    d1 = np.full((m, 3), np.nan)
    d2 = np.full((m, 3), np.nan)
    qn = np.full((m, 3), np.nan)
    n_samples = np.zeros(m, dtype=np.int32)
    residual = np.full(m, np.nan)
    n_neighbors = np.zeros(m, dtype=np.int32)
    noise = np.full(m, np.nan)
    size = min(m, block)
    b_k1, b_k2, b_res, b_noise = (np.empty(size) for _ in range(4))
    b_d1, b_d2 = np.empty((size, 3)), np.empty((size, 3))
    b_samples, b_neighbours = np.empty(size), np.empty(size)
    # queries by grid cell for ball queries (the points a block touches then stay in cache);
    # as given for k-rings, whose memory accesses follow the mesh's own numbering
    order = len(query) if use_kring else spatial_order(v[query], radius)
    for pos in _blocks(order, progress, "curvature", block):
        idx = query[pos]
        xb = v[idx]
        b = len(idx)
        indptr, indices = neighbours(idx)
        if estimate:
            qb = nrm.pca_normals(kernel_points, xb, indptr, indices, radius)
            if face_normals is not None:
                nrm.orient_like(qb, face_normals[idx])
            else:
                nrm.orient_towards(qb, xb, viewpoint)
        else:
            qb = nv[idx]
        with np.errstate(invalid="ignore", divide="ignore"):
            qb = qb / np.linalg.norm(qb, axis=1, keepdims=True)
        start = qb.copy() if refine else None
        jet.local_jet(kernel_points, xb, qb, indptr, indices, radius, refine, b_noise[:b])
        beta = weight_blend(b_noise[:b], radius, "auto")
        if refine:
            qb = _mix_normals(start, qb, beta)
        fused.curvature_cga(
            kernel_points, xb, qb, indptr, indices, radius, int(n_directions),
            float(slab), float(min_points), float(min_spread),
            beta if weighting == "auto" else weight_blend(b_noise[:b], radius, weighting),
            circle_normalization == "unit", bool(section_blend), bool(half_frequency), bool(robust),
            b_k1[:b], b_k2[:b], b_d1[:b], b_d2[:b], b_samples[:b], b_res[:b], b_neighbours[:b],
            rank)
        k1[pos], k2[pos], d1[pos], d2[pos] = b_k1[:b], b_k2[:b], b_d1[:b], b_d2[:b]
        qn[pos], n_samples[pos], residual[pos] = qb, b_samples[:b], b_res[:b]
        n_neighbors[pos], noise[pos] = b_neighbours[:b], b_noise[:b]
        del indptr, indices

    # 6. outputs
    valid = np.isfinite(k1)
    return CurvatureResult(k1=k1, k2=k2, d1=d1, d2=d2, normals=qn, valid=valid,
                           n_neighbors=n_neighbors, n_samples=n_samples, residual=residual,
                           noise=noise, radius=radius)
