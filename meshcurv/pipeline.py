"""The block loop of the estimator: neighborhoods -> normals -> local jet (noise, refined
normal) -> fused circle and Euler fits -> :class:`~meshcurv.result.CurvatureResult`.

:func:`run` takes validated arrays, a numeric radius and a :class:`~meshcurv.options.Plan`
(input checks, radius policy and options are :mod:`meshcurv.api`'s). Query points go through
the compiled kernels in blocks, which bounds the memory of the neighbor lists.
"""

import dataclasses
from typing import Callable, NamedTuple

import numpy as np
from scipy.spatial import cKDTree
from scipy.stats import chi2
from tqdm.auto import tqdm

from .fit import fused, jet, outliers, wrap
from .fit.constants import NOISE_SCALE, TUKEY_C
from .fit.extrapolate import BIAS_RATIO, extrapolate_to_zero
from .neighbors import (MAX_BALL_FRACTION, BallGrid, KringWork, ball_counts, ball_grid,
                        ball_neighbors, crowd_thinning, edge_adjacency, kring_counts,
                        kring_neighbors, spatial_order)
from .neighbors.csr import ball_mean, count_within, csr_rows
from .neighbors.radius import PATCH_FLATNESS
from .normals import face_normal_error, face_vertex_normals, orient, orient_along, \
    orient_like, orient_mst, orient_towards, pca_normals, sphere_normals
from .normals.pca import plane_agreement, split_disagreement
from .normals.winding import coherent_faces
from .result import CurvatureResult, Status, oriented_like

__all__ = ["run", "run_radii", "estimate_normals", "weight_blend", "clean_fraction",
           "given_normal_noise", "mix_given_normals", "Search", "ball_search", "kring_search",
           "block_size", "blocks", "mst_normals", "outlier_scores", "retry_sparse",
           "side_normals_estimated", "BLOCK",
           "BLOCK_ENTRIES", "MAX_PAIRS", "NOISE_SCALE", "BIAS_NOISE_SCALE", "BIAS_TILT_SCALE",
           "GIVEN_SAMPLE",
           "SPARSE_FACTORS", "MAX_BALL_FRACTION", "FIELD_RATIO", "FIELD_NOISE_RATIO",
           "field_mix"]

# Query points per call into the kernels: bounds the memory of the neighbor lists (about
# 0.8 kB per query point at 100 neighbors) at no measurable cost in speed.
BLOCK = 16384
# Neighbor list entries per block (int64, and 1.5x as many int32 in the searches' scratch):
# blocks shrink where the balls hold more than 128 points (the wide normal field's balls of
# twice the radius hold ~400), so their lists stay within ~16 MB and the scratch ~12 MB.
BLOCK_ENTRIES = 2 ** 21
# Most neighbor pairs (query points x neighbors) a call takes on: hours of work beyond.
MAX_PAIRS = 1e11

# The direction of ``orientation="+z"``.
_UP = np.array([0.0, 0.0, 1.0])
# A row's ball reaches around the surface (status WRAPS_AROUND, no estimate) where the weight
# of folding in it (:func:`meshcurv.fit.wrap.folding_weight`: neighbors on the far side and on
# the bend to it) is at least two points, so that one stray point does not take its estimate.
WRAP_POINTS = 2.0
# Where that weight comes from normals estimated over the balls themselves (a cloud's plane
# fits), a ball holding a tube's whole section gives them anything, and the test nothing
# (torus 3 / 0.4 cloud at 2.4 times the tube's radius: 71 % of the rows kept, 0.88 k1 off; a
# pole of radius 0.1 in a scan at radius 0.44: 95 %, k1 0.3 for 10): there the ball's own
# shape tells (:func:`meshcurv.fit.wrap.beyond_a_cap`).

# Noise level (as a fraction of the radius) at which the bias correction is applied half.
# The correction adds the smaller fit's noise, amplified: about 6 sigma / radius^2 in
# curvature (measured: the two fits' difference on noisy spheres, where there is no bias, has
# variance ~130 sigma^2 / (r^4 N) for N points within the smaller radius r), against a bias of
# 0.001-0.005 / radius at the test surfaces' usual radii - even at about 2-3e-4 of the radius.
# The jet measures clean samples at 0.5e-5 .. 0.9e-4 of the radius (sphere, paraboloid,
# torus), noise of 0.01 % of the diagonal at 1e-3 and more.
BIAS_NOISE_SCALE = 2.5e-4
# Least share of the bias correction for which the second, smaller fit is run: below it (noise
# above ~5.6 BIAS_NOISE_SCALE) the correction would move the estimate by less than 1/500 of
# the two fits' difference, itself mostly the smaller fit's noise there.
BIAS_MIN_GAIN = 1e-3
# Share of the bias correction from which a row counts as corrected: half on, the measured
# noise at BIAS_NOISE_SCALE of the radius (rows below it are checked for a shape's residual,
# :func:`bias_noise`; rows above it keep the default radius under ``radius="auto"``).
BIAS_HALF_GAIN = 0.5
# Telling the shape's higher orders from noise in the quartic's residual (:func:`bias_noise`):
# the residual of the shape falls like radius^SHAPE_RESIDUAL_ORDER (the quartic's first
# omitted terms), to 2^-2.5 = 0.18 of itself in a ball sqrt 2 smaller, while noise stays; a
# row whose residual falls below SHAPE_RESIDUAL_DROP of itself there is taken for the shape's,
# and below less where the smaller ball has so few points that noise alone would fall that
# far with a chance above SHAPE_FALSE_DROP (the residual's square has a chi-square spread
# with the fit's degrees of freedom: ~50 points, 35 of them, halve it with a chance of
# ~2e-6). Coarse meshes at their default radius: torus 120 x 30, residual 7.9e-4 of the
# radius at R 0.45 that read as noise and kept the correction off.
SHAPE_RESIDUAL_ORDER = 5
SHAPE_RESIDUAL_DROP = 0.5
SHAPE_FALSE_DROP = 1e-3
# Tilt (radians) of given normals from the local quadric's at which the bias correction is
# applied half: exact normals of clean samples tilt from the quadric's by its own error (a few
# 1e-3 where the curvature varies inside the ball: Table 2 paraboloid at radius 2), normals
# with noise sigma_xi = 0.1 (the benchmark's) by ~0.14.
BIAS_TILT_SCALE = 0.03

# Given normals whose |cos| with the plane fit of their own neighborhood is below this (60
# degrees off it) describe no surface there: the curvature about them is wildly wrong
# (measured once: a sphere whose every normal is tilted by 45 / 60 / 75 degrees gave median
# |dk| 0.53 / 0.85 / 9.1 on k = 1), so those rows get none (NO_NORMAL). A plane fit across a right-angled edge is 45
# degrees from either face's normal, within it (:func:`_off_surface`).
GIVEN_OFF_COS = 0.5

# Vertices sampled to estimate the noise of given normals (:func:`given_normal_noise`): its
# standard error is then about 2 % of the estimate.
GIVEN_SAMPLE = 4096

# Share of sampled points whose given normal faces away from most of their neighbors' above
# which the result's orientation note says so (:func:`facing_away`): 0 on consistently
# oriented normals, about a third for unoriented ones (more than 3 of 6 coin flips: 22 / 64);
# 1 % of the normals flipped at random gives about 1 % (the flipped points).
GIVEN_AWAY_SHARE = 0.05
# The neighbors :func:`facing_away` compares a normal with: its nearest few, and only those
# whose normals are within 60 degrees of its own or of its opposite (|cos| > 1/2), whose
# sides therefore say something. Over a whole ball, a coarse shape's normals turn by more
# than 90 degrees: the corners of a cube, a 32-section cylinder and an annulus read as 100 %,
# 100 % and 50 % facing away with consistent outward normals.
AWAY_NEIGHBORS = 6

# Radii, as multiples of the call's, at which :func:`retry_sparse` re-estimates the vertices
# whose ball held too few points, each at the smallest that serves (the larger the ball, the
# more the curvature varies inside it): up to 16 times the area, so a patch sampled 16 times
# more sparsely than the default radius' target still gets its ~100 points.
SPARSE_FACTORS = (1.5, 2.0, 3.0, 4.0)
# Fewest neighbors of a half-set in the last resort of :func:`retry_sparse`.
SPARSE_MIN_POINTS = 1
# Statuses of fits that failed for lack of points.
SPARSE_STATUSES = (Status.TOO_FEW_NEIGHBORS, Status.TOO_FEW_HALF_SETS, Status.ILL_POSED_FIT,
                   Status.DEGENERATE_DIRECTIONS)

# Tilt (radians) taken as the plane fits' error where ``normal_estimation="auto"`` mixes them
# with a mesh's face normals, by inverse variance against the face normals' expected tilt
# (:func:`meshcurv.normals.face_normal_error`). Measured on clean meshes at the default
# radius: plane fits tilt by 1e-3 .. 2.4e-2 (median; torus, paraboloid, ellipsoid, cylinder;
# up to 0.18 at the borders, which also tilts the fits of every vertex within a radius of
# them), face normals by 0 .. 4e-4; noise of 0.1 % of the diagonal tilts face normals by 0.09.
FACE_MIX_TILT = 1e-2

# Neighbors per point in the graph of the spanning-tree orientation.
TREE_NEIGHBORS = 10
# Most rounds of joining the pieces of that graph (:func:`bridged_graph`).
BRIDGE_ROUNDS = 4
# The spanning tree orients a cloud's plane-fit normals before the fits. Where more than
# REORIENT_SHARE of the rows' fitted normals (the refined ones the estimates use) lie more
# than 60 degrees (|cos| below REORIENT_COS) from their plane-fit normal, the tree
# propagated its signs through wrong normals, and the rows are oriented again by a tree over
# the fitted ones (:func:`reoriented_by_fits`). Plane fits over balls that hold one curve of
# points (one ring of a coarse tube, one scan line) lie in the curve's plane: trimesh's 32 x 32
# torus as a cloud at radius 0.37 had 59 % of them off by 90 degrees and every sign wrong.
# Measured share elsewhere: 0 on the six benchmark clouds at every position noise, scan
# terrain, a 100k random torus cloud, the same torus cloud at its default radius. The tree
# routes round a few wrong normals (its weights 1 - |n_i . n_j|), so a few rows (spikes,
# creases) do not trigger the second tree.
REORIENT_COS = 0.5
REORIENT_SHARE = 0.01

# Radius, as a multiple of the call's, of the plane fits that give a point cloud's estimated
# normals to the normal-aware circle fits (a neighbor's normal row). Those rows count where
# the positions are noisy (their weight is 1 - the noise blend), and there a plane fit's
# normal tilts by the noise over ~sqrt(points), a sixteenth of the variance in a ball of twice
# the radius, while its bias (the curvature's variation across the ball) is a second-order
# effect for a plane fit centred on its point. Each point mixes the wide fit with the narrow
# one (over the radius) by what separates them (:func:`field_mix`), which keeps the narrow
# one where the surface bends within the ball. Measured on clouds without normals at their
# default radius, mean |dk| / median |k|, the previous release (sqrt 2 radii, halves of a
# ball compared by plane fits) -> now (random samplings of 20000 points unless named, noise
# 0.1 / 0.3 / 1 % of the diagonal along the normal): sphere 0.026 / 0.048 / 0.103 -> 0.022 /
# 0.031 / 0.051, monkey saddle 0.047 / 0.102 / 0.191 -> 0.034 / 0.060 / 0.092, ellipsoid
# 0.028 / 0.045 / 0.081 -> 0.029 / 0.042 / 0.068, torus 120 x 30 vertices as a cloud 0.013 /
# 0.014 / 0.023 -> 0.009 / 0.011 / 0.024; the CNC benchmark clouds (mean |dH| over six,
# sigma_eps 0.1 / 0.2) 0.0117 / 0.0157 -> 0.0103 / 0.0136. Losses: torus 240 x 60 at 0.1 %
# 0.0050 -> 0.0052, icosphere-scaled ellipsoid at 1 % 0.069 -> 0.072, CNC torus_010000 0.0071
# -> 0.0077, a valley terrain of 24000 points with noise 0.03 (mean |dH|) 0.0281 -> 0.0333
# (narrow fits alone 0.0321: the mix misjudges it). Clean clouds are unchanged: the field's
# rows have no weight there.
FIELD_RATIO = 2.0
# The mean squared disagreement (sin^2) of plane fits over the radius and over FIELD_RATIO
# times it, per unit of the split measure of the two halves of a ball, where noise alone
# separates them (:func:`field_mix`, :func:`meshcurv.normals.pca.split_disagreement`):
# measured on noisy planes (40000 points, noise 0.2-26 % of the radius): 0.39-0.42 random,
# 0.45-0.46 hexagonal and 0.47-0.52 square grids.
FIELD_NOISE_RATIO = 0.45
# A mesh's estimated normals get the same wide field, over k-rings of FIELD_RATIO times the
# radius, where its normal rows weigh something: where the rows' gain ``1 - beta`` (beta the
# noise blend of the weights) reaches WIDE_FIELD_GAIN at 1 % of a sample of WIDE_FIELD_SAMPLE
# vertices (a measured noise of 0.06 % of the radius). Clean meshes (noise ~0.01 % of the
# radius, gain ~1e-5) skip it: it would change no estimate beyond rounding, at 1.7x the time
# (torus mesh 300k vertices, 4.4 -> 7.7 s). Measured, mean |dk1| at the default radius
# before -> with it, noise 0.1 / 0.3 % of the diagonal along random directions: sphere
# (icosphere 5) 0.0175 / 0.0430 -> 0.0086 / 0.0128, torus 240 x 60 0.0141 / 0.0373 -> 0.0130
# / 0.0217, ellipsoid 0.0452 / 0.0564 -> 0.0446 / 0.0536, random ellipsoid 20k 0.0352 /
# 0.0598 -> 0.0345 / 0.0546, monkey saddle 0.0661 / 0.1719 -> 0.0369 / 0.0571, paraboloid
# 0.0081 / 0.0425 -> 0.0045 / 0.0332: the mesh now measures as the same points do as a cloud.
WIDE_FIELD_GAIN = 0.01
WIDE_FIELD_SAMPLE = 2048


class Search(NamedTuple):
    """Neighborhoods of one radius: ``neighbors(idx)`` the CSR lists of the points ``v[idx]``
    (unsorted: the kernels depend on the order within a list only for rounding, but for the
    field mix's two halves of each list, :func:`_mixed_field`), ``counts(idx)`` their
    lengths (nothing stored), ``points`` the coordinates the lists index (the grid's copy in
    grid order, or ``v``) and ``rank`` their vertex indices (None when ``points`` is ``v``);
    ``adjacency`` the mesh's edge graph of k-ring searches (None for balls); ``radius`` the
    radius it was made for (model units); ``work`` the k-ring searches' work arrays
    (:class:`meshcurv.neighbors.KringWork`, None for balls), which the searches of other radii
    over the same mesh share (:func:`_search_like`: they run one at a time)."""

    neighbors: Callable
    counts: Callable
    points: np.ndarray
    rank: object
    adjacency: object = None
    radius: float = None
    work: object = None


def _mix_normals(start, refined, beta):
    """``start + beta (refined - start)``, normalised, row by row.

    With beta from the measured noise: the jet's normal on clean data (no tilt from
    irregular sampling), the starting one (usually the plane fit's, which averages the most
    points) under noise.
    """
    mixed = start + beta[:, None] * (refined - start)
    with np.errstate(invalid="ignore", divide="ignore"):
        return mixed / np.linalg.norm(mixed, axis=1, keepdims=True)


def clean_fraction(noise, scale):
    """``1 / (1 + (noise / scale)^4)`` per vertex, in [0, 1]: 1 where the measured noise (model
    units) is well below ``scale``, 0 well above it and where it is NaN (too few points)."""
    noise = np.asarray(noise, dtype=np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        gain = 1.0 / (1.0 + (noise / scale) ** 4)
    return np.where(np.isfinite(gain), gain, 0.0)

def sphericity(noise, residual):
    """Per-vertex weight in [0, 1] of the sphere fit's normal against the quadric's: the
    fraction ``min(1, noise^2 / residual^2)`` of the sphere fit's residual (both RMS, in units
    of the radius) that the local cubic fit's residual ``noise`` also leaves, i.e. that is
    noise and not the shape's departure from a sphere or plane. 1 on spheres and planes
    (where the sphere fit is exact and the quadric's normal tilts with the sampling), towards 0
    on anisotropic shapes (paraboloid, torus), 0 where either is NaN."""
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.minimum(1.0, noise * noise / (residual * residual))
    return np.where(np.isfinite(w), w, np.where(residual == 0.0, 1.0, 0.0))


def _oriented_like(fitted, start):
    """``fitted`` (b, 3) unit normals turned to ``start``'s side; ``start`` where NaN."""
    flip = np.einsum("ij,ij->i", fitted, start) < 0
    fitted = np.where(flip[:, None], -fitted, fitted)
    return np.where(np.isfinite(fitted).all(axis=1)[:, None], fitted, start)


def _partners(v, sample, radius, search):
    """``(sample, partner)``: for each vertex of ``sample`` (k,) the neighbor in its list
    whose distance is nearest to half the radius (vertex indices), those without one dropped."""
    indptr, indices = search.neighbors(sample)
    row = np.repeat(np.arange(len(sample)), np.diff(indptr))
    d = search.points[indices] - v[sample][row]
    dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    off = np.where(dist > 0, np.abs(dist - 0.5 * radius), np.inf)
    has = np.diff(indptr) > 0
    best = np.full(len(sample), np.inf)
    best[has] = np.minimum.reduceat(off, indptr[:-1][has])
    hit = np.flatnonzero((off == best[row]) & np.isfinite(off))
    rows, first = np.unique(row[hit], return_index=True)    # the first such entry per row
    partner = indices[hit[first]]
    if search.rank is not None:
        partner = search.rank[partner]
    return sample[rows], partner


def _without_pair(search, rows, others):
    """The search's CSR lists of the vertices ``rows`` (k,) without the vertices ``others``
    (k,): each row's list less its partner (the query itself is left out by the fits)."""
    indptr, indices = search.neighbors(rows)
    owner = np.repeat(np.arange(len(rows)), np.diff(indptr))
    vertex = indices if search.rank is None else search.rank[indices]
    keep = vertex != others[owner]
    counts = np.bincount(owner[keep], minlength=len(rows))
    return np.concatenate([[0], np.cumsum(counts)]).astype(indptr.dtype), indices[keep]


def given_normal_noise(v, given, radius, search, query, size=GIVEN_SAMPLE):
    """Variance per tangent component (radians^2) of the independent noise on the given
    normals (n, 3), estimated from up to ``size`` of the vertices ``query``; 0.0 where none
    shows.

    For a vertex i, a neighbor j at about half the radius (:func:`_partners`: far enough
    that the points' noise tilts the chord little, near enough for the chord's second-order
    term to stay small) and the unit chord ``c = (x_j - x_i) / |x_j - x_i|``, the chord is at
    right angles to the mean of the two exact normals up to second order in the distance
    (the symmetry of a circle), so with given normals ``g = t + xi`` ``e_g = (g_i + g_j) . c``
    is ``(xi_i + xi_j) . c`` (variance ``2 a2``) plus what the points' own noise puts in
    ``c``; ``e_f`` of the normals fitted to the points
    (:func:`meshcurv.normals.sphere.sphere_normals`, smooth) holds the same position term
    and twice their bias along c instead, provided they are fitted without x_i and x_j
    (else they follow the two points' noise and make the chord look right). The estimate is
    the mean of ``(e_g^2 - e_f^2) / 2`` over the sample, kept only where it exceeds three
    standard errors:
    exact given normals get 0 (their ``e_g`` is the smaller), and with it the given normals
    stay as they are bit for bit; the fits' bias and noise only lower the estimate.
    """
    sample = query[_sample_queries(len(query), size)]
    sample = sample[np.isfinite(given[sample]).all(axis=1) & np.isfinite(v[sample]).all(axis=1)]
    if len(sample) < 8:
        return 0.0
    sample, near = _partners(v, sample, radius, search)
    both = np.concatenate([sample, near])
    indptr, indices = _without_pair(search, both, np.concatenate([near, sample]))
    fitted, _, _ = sphere_normals(search.points, v[both], indptr, indices, radius,
                                  with_query=False)
    fitted = _oriented_like(fitted, given[both])   # NaN given normals leave NaN
    with np.errstate(invalid="ignore", divide="ignore"):
        unit = given[both] / np.linalg.norm(given[both], axis=1, keepdims=True)
        chord = v[near] - v[sample]
        chord /= np.linalg.norm(chord, axis=1, keepdims=True)
        k = len(sample)
        e_given = np.einsum("ij,ij->i", unit[:k] + unit[k:], chord)
        e_fitted = np.einsum("ij,ij->i", fitted[:k] + fitted[k:], chord)
        excess = 0.5 * (e_given ** 2 - e_fitted ** 2)
    excess = excess[np.isfinite(excess)]
    if len(excess) < 8:
        return 0.0
    a2 = float(np.mean(excess))
    return a2 if a2 > 3.0 * float(np.std(excess)) / np.sqrt(len(excess)) else 0.0


def mix_given_normals(given, fitted, tilt_gain, noise, radius, a2):
    """Given unit normals (b, 3) mixed with fitted ones (b, 3, on the given side) by inverse
    variances: ``given + lambda (fitted - given)``, normalised, with
    ``lambda = a2 / (a2 + c2)``, ``a2`` the given normals' noise variance per tangent
    component (:func:`given_normal_noise`) and ``c2 = (tilt_gain noise / radius)^2`` the fitted
    normal's (``tilt_gain`` from :func:`meshcurv.normals.sphere.sphere_normals`, ``noise`` the
    local jet's RMS height residual, model units). ``a2 = 0``, or a NaN fit or noise, keeps the
    given normal bit for bit.
    """
    with np.errstate(invalid="ignore", divide="ignore"):
        c2 = (tilt_gain * noise / radius) ** 2
        lam = a2 / (a2 + c2) if a2 > 0 else np.zeros(len(given))
        lam = np.where(np.isfinite(lam) & np.isfinite(fitted).all(axis=1), lam, 0.0)
        mixed = given + lam[:, None] * (fitted - given)
        mixed /= np.linalg.norm(mixed, axis=1, keepdims=True)
    return np.where((lam > 0)[:, None], mixed, given)


def weight_blend(noise, radius, weighting="auto"):
    """Per-vertex mix of the circle fits' weight functions, in [0, 1] (1 = distance weights).

    "auto": ``clean_fraction(noise, NOISE_SCALE * radius)``, i.e. distance weights where the
    local jet explains the points (clean data: less bias), equal weights where it leaves
    noise (less variance); NaN noise (too few points for the fit) gives equal weights.
    """
    noise = np.asarray(noise, dtype=np.float64)
    if weighting == "distance":
        return np.ones_like(noise)
    if weighting == "none":
        return np.zeros_like(noise)
    return clean_fraction(noise, NOISE_SCALE * radius)


def blocks(order, progress, desc, size=BLOCK):
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


def _sample_queries(m, size=64):
    """Up to ``size`` positions spread over ``range(m)``."""
    return np.unique(np.linspace(0, m - 1, min(m, size)).astype(np.int64)) if m else \
        np.zeros(0, dtype=np.int64)


def block_size(search, queries, radius, what):
    """Queries per block for the neighbor lists of ``queries`` (their mean length from a
    sample), raising ValueError where they are more work than :data:`MAX_PAIRS`."""
    counts = search.counts(queries[_sample_queries(len(queries))])
    per = max(float(np.mean(counts)) if len(counts) else 0.0, 1.0)
    if per * len(queries) > MAX_PAIRS:
        raise ValueError(
            f"radius {radius:.6g} is too large for these {what}: each neighborhood would hold "
            f"about {per:.3g} points ({per * len(queries):.3g} neighbor pairs in all, far too "
            f"many to compute); use a smaller radius")
    return int(min(BLOCK, max(1, BLOCK_ENTRIES // per)))


def ball_search(v, finite, radius):
    """:class:`Search` by ball queries over the finite rows ``finite`` of ``v``.

    With a uniform grid (when one fits; the same lists as a k-d tree, several times faster)
    the lists hold rows of the grid's copy of the points, where a neighborhood lies together
    in memory however the input is ordered; else a k-d tree over ``v[finite]``.
    """
    tree = ball_grid(v, radius) if len(finite) else None
    if tree is None and len(finite):
        tree = cKDTree(v[finite])
    in_grid = isinstance(tree, BallGrid)
    # crowded parts (a scanner's near field) serve thinned: see crowd_thinning
    serving = crowd_thinning(tree) if in_grid else None

    def neighbors(idx):
        if tree is None:
            return np.zeros(len(idx) + 1, dtype=np.int64), np.zeros(0, dtype=np.int64)
        return ball_neighbors(tree, finite, v[idx], radius, ascending=False, positions=in_grid,
                              serving=serving)

    def counts(idx):
        if tree is None:
            return np.zeros(len(idx), dtype=np.int64)
        return ball_counts(tree, v[idx], radius, serving)

    return Search(neighbors, counts, tree.sorted_points if in_grid else v,
                  tree.order if in_grid else None, None, radius)


def kring_search(v, f, radius, adjacency=None, work=None):
    """:class:`Search` by connected k-rings over the mesh edges of faces ``f``, limited to the
    ball of ``radius``; ``adjacency``: their :func:`edge_adjacency`, if already made;
    ``work``: the :class:`KringWork` of another search over the same mesh, to share (its
    stamps, 8 bytes per vertex and thread; each query takes fresh tags, so the lists are the
    same)."""
    if adjacency is None:
        adjacency = edge_adjacency(f, len(v))
    if work is None:
        work = KringWork(len(v))

    def neighbors(idx):
        return kring_neighbors(v, adjacency, radius, idx, work)

    def counts(idx):
        return kring_counts(v, adjacency, radius, idx, work)
    return Search(neighbors, counts, v, None, adjacency, radius, work)


def _search_like(search, v, f, finite, radius):
    """:class:`Search` of the same kind as ``search`` (k-rings over the faces ``f``, with its
    edge adjacency and work arrays, or balls about the ``finite`` rows of ``v``) at another
    ``radius``."""
    if search.adjacency is not None:
        return kring_search(v, f, radius, search.adjacency, search.work)
    return ball_search(v, finite, radius)


def outlier_scores(v, radius, search, rows, progress, block=BLOCK):
    """Outlier scores (n,) of the points ``v[rows]`` (NaN elsewhere): each one's residual from
    a robust height fit of its neighborhood over its robust scale, as a Gaussian deviate
    (:func:`meshcurv.fit.outliers.point_residuals`, :func:`~meshcurv.fit.outliers.outlier_score`)."""
    score = np.full(len(v), np.nan)
    for pos in blocks(rows, progress, "outliers", block):
        indptr, indices = search.neighbors(pos)
        _score_block(score, v, radius, search, pos, indptr, indices)
    return score


def _score_block(score, v, radius, search, pos, indptr, indices):
    """:func:`outlier_scores` of the points ``v[pos]`` from their lists, into ``score[pos]``."""
    residual, scale, dof = (np.empty(len(pos)) for _ in range(3))
    outliers.point_residuals(search.points, v[pos], indptr, indices, radius, residual, scale, dof)
    score[pos] = outliers.outlier_score(residual, scale, dof)


def _outlier_pass(v, f, radius, search, rows, plan, progress, block, face_normals,
                  face_weight=None, split=False):
    """The outlier scores of :func:`outlier_scores` and, from the same neighbor lists (one
    search for all), what else needs every point's neighborhood before the blocks and does
    not depend on the scores (when ``rows`` are all the finite points): the spanning tree's
    normals (``plan.normals == "mst"``), the plane-fit field of :func:`_pca_field` without
    the outlier weights (normal-aware fits with ``plan.normals == "pca"``) and, with
    ``split``, the field mix's split-half disagreement without them
    (:func:`_mixed_field`); those two are then fitted again only where a neighborhood holds a
    down-weighted point.

    Returns ``(score (n,), tree, plain, halves)``: ``tree`` the ``(normals, note)`` of
    :func:`mst_normals` or None, ``plain`` the (n, 3) unweighted field or None, ``halves``
    the (n,) unweighted split disagreement or None.
    """
    n = len(v)
    whole = len(rows) == np.count_nonzero(np.isfinite(v).all(axis=1))
    tree = plan.normals == "mst" and f is None and whole
    field = plan.normal_constraints and plan.normals == "pca" and whole
    split = split and whole
    if not (tree or field or split):
        return outlier_scores(v, radius, search, rows, progress, block), None, None, None
    score = np.full(n, np.nan)
    nv = graph = plain = halves = None
    if tree:
        nv, graph = _tree_arrays(n)
    if field:
        plain = np.full((n, 3), np.nan)
    if split:
        halves = np.full(n, np.nan)
    if search.rank is not None:
        rows = search.rank          # the grid's cell order (the finite points): cache-friendly
    elif tree:
        rows = rows[spatial_order(v[rows], radius)]
    block = min(block, block_size(search, rows, radius, "points"))
    for pos in blocks(rows, progress, "outliers and normals", block):
        indptr, indices = search.neighbors(pos)
        _score_block(score, v, radius, search, pos, indptr, indices)
        if tree:
            _tree_block(nv, graph, v, radius, search, pos, indptr, indices)
        if field:
            plain[pos] = _block_normals(None, face_normals, pos, v[pos], indptr, indices,
                                        radius, search, plan, face_weight=face_weight)
        if split:
            halves[pos] = split_disagreement(search.points, v[pos], indptr, indices, radius)
        del indptr, indices
    tree = _oriented_tree(v, nv, graph, search, block) if tree else None
    return score, tree, plain, halves


def _scored_rows(v, search, query, finite, block, plan):
    """The vertices whose outlier scores the estimates at ``query`` use: every finite one, or,
    for a few queries without normal-aware fits, those and their neighbors (the neighbors'
    normals of normal-aware fits come from their own neighborhoods, scored too)."""
    if finite is None:
        finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    if len(query) >= len(finite) // 4 or plan.normal_constraints:
        return finite
    parts = [query]
    for s in range(0, len(query), block):
        rows = np.unique(search.neighbors(query[s:s + block])[1])
        parts.append(rows if search.rank is None else search.rank[rows])
    rows = np.unique(np.concatenate(parts))
    return rows[np.isfinite(v[rows]).all(axis=1)]


def mst_normals(v, radius, search, progress, block=BLOCK, point_weights=None):
    """PCA normals of every point, oriented along a spanning tree whose graph joins each point
    to its nearest neighbors, taken from the search's lists (see :func:`ball_search`);
    ``point_weights`` (per row of ``search.points``) weight the plane fits. Returns
    ``(normals (n, 3), note)``: the note says how the pieces were oriented
    (:func:`meshcurv.normals.orient.orientation_note`)."""
    nv, graph = _tree_arrays(len(v))
    # the grid's own cell order (``rank``) when there is one, else one made for the purpose
    order = search.rank if search.rank is not None else spatial_order(v, radius)
    for pos in blocks(order, progress, "normals", block):
        indptr, indices = search.neighbors(pos)
        _tree_block(nv, graph, v, radius, search, pos, indptr, indices, point_weights)
    return _oriented_tree(v, nv, graph, search, block)


def _oriented_tree(v, nv, graph, search, block):
    """:func:`meshcurv.normals.orient_mst` of the normals ``nv`` over the graph of nearest
    neighbors ``graph`` (n, TREE_NEIGHBORS), whose pieces are first joined wherever a point's
    ball holds a point of another piece (:func:`bridged_graph`): ``(normals, note)``."""
    return orient_mst(v, nv, neighbors=bridged_graph(v, nv, graph, search, block), note=True)


def bridged_graph(v, nv, graph, search, block=BLOCK):
    """The spanning tree's graph ``graph`` ((n, k) int32 vertex indices, -1 for none) with a
    column more per round where its pieces (:func:`meshcurv.normals.orient.graph_pieces`) are
    joined: each point outside the largest piece gets an edge to the nearest point of another
    piece in its list of ``search`` that lies along the surface, not across a gap from it
    (within ``BRIDGE_TILT`` of the tangent planes of the unoriented normals ``nv`` (n, 3) at
    both ends; -1 where there is none), for up to ``BRIDGE_ROUNDS`` rounds while that joins
    any. A graph of one piece comes back as it is (the same object).

    The nearest neighbors alone split a cloud whose points come in stacks (each point's
    nearest are copies of one other position: 10 copies of every point of a sphere left 46 %
    of the signs wrong) or in scan lines far denser along than across (the nearest all lie on
    the point's own line: rings 0.1 apart with 1000 points each on a unit sphere, 20 % wrong);
    each piece then took its sign alone. Pieces farther apart than the radius (separate
    objects) stay apart, and so do pieces stacked across a gap narrower than it: a unit
    sphere 0.1 above a floor of random points was joined to it and took the floor's side,
    inward (k = -1 on 97 % of its points, all valid); now it is a piece of its own, closed,
    outward. Where it touches the floor, or comes nearer than the spacing of the points
    (0.02 of a spacing of 0.04 there), the nearest neighbours join the two still, and it
    comes out inward."""
    labels = orient.graph_pieces(graph)
    columns = [graph]
    vertex = search.rank if search.rank is not None else np.arange(len(v))
    finite = None
    for _ in range(BRIDGE_ROUNDS):
        sizes = np.bincount(labels, minlength=len(v))
        if np.count_nonzero(sizes) <= 1:
            break
        if finite is None:
            finite = np.isfinite(v).all(axis=1)
        rows = np.flatnonzero((labels != np.argmax(sizes)) & finite)
        near = np.full(len(v), -1, dtype=np.int32)
        for pos in blocks(rows, False, "", block):
            indptr, indices = search.neighbors(pos)
            near[pos] = orient.nearest_in_other_piece(search.points, v[pos], indptr, indices,
                                                      vertex, labels, labels[pos], nv, nv[pos])
        if not (near >= 0).any():
            break
        columns.append(near[:, None])
        labels = orient.graph_pieces(np.ascontiguousarray(np.hstack(columns)))
    return graph if len(columns) == 1 else np.ascontiguousarray(np.hstack(columns))


def _tree_arrays(n):
    """Unoriented normals (n, 3) NaN and spanning-tree graph (n, TREE_NEIGHBORS) int32 -1 of
    :func:`mst_normals`, before the blocks fill them."""
    return np.full((n, 3), np.nan), np.full((n, TREE_NEIGHBORS), -1, dtype=np.int32)


def _tree_block(nv, graph, v, radius, search, pos, indptr, indices, point_weights=None):
    """The plane-fit normals and the tree graph's nearest neighbors (vertex indices) of the
    points ``v[pos]`` from their lists, into ``nv[pos]`` and ``graph[pos]``."""
    nv[pos] = pca_normals(search.points, v[pos], indptr, indices, radius, point_weights)
    graph[pos] = _graph_rows(v[pos], search, indptr, indices)


def _graph_rows(xb, search, indptr, indices, k=TREE_NEIGHBORS):
    """The spanning tree graph's rows (b, k) of the points ``xb`` (b, 3): the vertex indices
    of their ``k`` nearest neighbors in their lists, nearest first, -1 for none."""
    near = orient.nearest_in_lists(search.points, xb, indptr, indices, k)
    return near if search.rank is None else np.where(near >= 0, search.rank[near], -1)


def reoriented_by_fits(res, v, start, query, search, block=BLOCK):
    """``res`` (rows ``query`` of ``v``) with its normals' signs taken from a spanning tree
    over its own fitted normals, where the spanning-tree ``start`` normals ((n, 3), oriented
    plane fits) misled the first tree (see :data:`REORIENT_SHARE`); ``res`` itself
    otherwise. Rows turned round get k1, k2 = -k2, -k1 and d1, d2 swapped
    (:func:`meshcurv.result.oriented_like`). The tree's graph is built as the first one's
    (nearest neighbors in ``search``'s lists); vertices not queried keep their plane fits."""
    with np.errstate(invalid="ignore"):
        cos = np.abs(np.einsum("ij,ij->i", start[query], res.normals))
    fitted = np.isfinite(cos)
    off = np.count_nonzero(cos[fitted] < REORIENT_COS)
    if off <= REORIENT_SHARE * np.count_nonzero(fitted):
        return res
    field = start.copy()
    field[query[fitted]] = res.normals[fitted]
    graph = np.full((len(v), TREE_NEIGHBORS), -1, dtype=np.int32)
    rows = np.flatnonzero(np.isfinite(v).all(axis=1))
    for pos in blocks(rows, False, "", block):
        indptr, indices = search.neighbors(pos)
        graph[pos] = _graph_rows(v[pos], search, indptr, indices)
        del indptr, indices
    field, note = _oriented_tree(v, field, graph, search, block)
    share = off / np.count_nonzero(fitted)
    return dataclasses.replace(
        oriented_like(res, field[query]),
        orientation=f"{note}, along the fitted normals ({share:.0%} of the plane fits were "
                    f"more than 60 degrees off them: a radius below the sampling's spacing in "
                    f"some direction?)")


def estimate_normals(v, radius, progress=False):
    """Oriented PCA normals (n, 3) of the cloud ``v`` ((n, 3) float64, contiguous; radius in
    model units, squaring safely): the "mst" normals of :func:`run`."""
    finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    return _spanning_tree_normals(v, radius, ball_search(v, finite, radius), finite,
                                  progress)[0]


def _spanning_tree_normals(v, radius, search, finite, progress, point_weights=None):
    """:func:`mst_normals` of the ``finite`` (k,) rows of ``v`` over the ball ``search``, in
    blocks sized for their neighbor lists."""
    return mst_normals(v, radius, search, progress, block_size(search, finite, radius, "points"),
                       point_weights)


def _start_normals(v, f, given, radius, search, finite, plan, progress, point_weights=None,
                   repair=""):
    """``(normals, face_normals, note, face_weight)`` before the blocks: the given ones, the
    faces', or the spanning tree's (which needs every normal first); None where blocks
    estimate their own. ``finite``: the finite rows of ``v`` (ball searches only); ``note``:
    how the normals get their sign (``CurvatureResult.orientation``); ``face_weight``: the
    per-vertex weight of the face normals in the blocks' plane-fit normals
    (:func:`face_weights`), or None. ``f`` wound coherently and outward already
    (:func:`meshcurv.normals.winding.coherent_faces`); ``repair``: what that changed, for the
    note (:func:`_repair_note`)."""
    if plan.normals == "given":
        return given, None, _given_note(given, v, search, finite), None
    if plan.normals == "mst":
        normals, note = _spanning_tree_normals(v, radius, search, finite, progress,
                                               point_weights)
        return normals, None, note, None
    face_normals = None
    if f is not None:
        with np.errstate(invalid="ignore"):       # NaN vertices give NaN normals
            face_normals = face_vertex_normals(v, f)
    note = ("oriented like the faces" if face_normals is not None else
            "oriented towards +z" if plan.viewpoint is None else "oriented towards the viewpoint")
    note += repair
    weight = (face_weights(v, f, face_normals, search.adjacency)
              if plan.face_mix and face_normals is not None else None)
    return (face_normals if plan.normals == "faces" else None), face_normals, note, weight


def facing_away(given, v, search, rows, size=GIVEN_SAMPLE):
    """Share of up to ``size`` of the vertices ``rows`` of ``v`` whose given normal (``given``
    (n, 3)) faces away (dot product below -1/2) from the normals of more than half of those
    of its :data:`AWAY_NEIGHBORS` nearest neighbors whose normals lie near its line (|dot|
    above 1/2): near 0 for normals oriented consistently, about a third for unoriented ones
    (a plane fit's sign left as it fell: more than 3 of 6 coin flips); NaN where none was
    sampled."""
    sample = rows[_sample_queries(len(rows), size)]
    indptr, indices = search.neighbors(sample)
    near = _graph_rows(v[sample], search, indptr, indices, AWAY_NEIGHBORS)
    with np.errstate(invalid="ignore"):
        dots = np.einsum("ij,ikj->ik", given[sample], given[np.maximum(near, 0)])
    usable = (near >= 0) & (np.abs(dots) > 0.5)
    counted = usable.sum(axis=1)
    away = (usable & (dots < -0.5)).sum(axis=1)
    seen = counted > 0
    return float(np.mean(away[seen] > 0.5 * counted[seen])) if seen.any() else np.nan


def _given_note(given, v, search, finite):
    """``CurvatureResult.orientation`` for normals used as given: "as given", and where many
    of them face away from their neighbors' (:func:`facing_away` at least
    ``GIVEN_AWAY_SHARE``), that the curvature's signs follow each of them."""
    rows = np.arange(len(given)) if finite is None else finite
    share = facing_away(given, v, search, rows) if len(rows) else np.nan
    if not share >= GIVEN_AWAY_SHARE:
        return "as given"
    return (f"as given; {100 * share:.0f} % of the points sampled face away from most of "
            f"their neighbours' normals (unoriented normals?): each curvature's sign follows "
            f"its point's normal; orient them consistently, or pass none to have them "
            f"estimated and oriented")


def face_weights(v, f, face_normals, adjacency=None):
    """Weights (n,) in [0, 1] of the face normals ``face_normals`` against plane fits, by
    inverse variance: ``t^2 / (t^2 + e^2)``, t = :data:`FACE_MIX_TILT` the plane fits' error,
    e the face normals' expected tilt (:func:`meshcurv.normals.face_normal_error`). About 1
    on smooth meshes however coarse (where plane fits tilt with the curvature across an
    uneven or truncated ball), towards 0 on noisy ones (noise of 0.1 % of the diagonal on a
    torus 240 x 60: ~0.01); 0 where the face normals' error is not known. ``adjacency``: the
    mesh's :func:`meshcurv.neighbors.edge_adjacency`, if already made."""
    error = face_normal_error(v, f, face_normals, adjacency)
    t2 = FACE_MIX_TILT * FACE_MIX_TILT
    with np.errstate(invalid="ignore"):
        weight = t2 / (t2 + error * error)
    return np.where(np.isfinite(weight), weight, 0.0)


def _pca_field(v, face_normals, search, finite, radius, plan, progress, point_weights=None,
               plain=None, face_weight=None):
    """The block normals of every vertex before the blocks (:func:`_block_normals`' plane
    fits), for the normal-aware circle fits: (n, 3), NaN where the neighborhood is too small.
    Measured, on noisy meshes these normals serve the circle fits far better than the face
    normals (torus 240 x 60, 0.3 % noise: mean |dk| 0.036 with them, 0.135 with face normals,
    0.206 with none) and cost what the blocks would spend on them.

    ``plain``: the same field without ``point_weights`` (n, 3), if at hand (filled in place and
    returned): it is the weighted one wherever no point of the neighborhood weighs less than
    1, so only the vertices within ``radius`` of such a point are fitted again (every vertex
    where that is most of them)."""
    rows = np.arange(len(v)) if finite is None else finite
    if search.rank is not None:
        rows = search.rank          # the grid's cell order: neighborhoods stay in cache
    if plain is not None:
        near = _refit_rows(v, search, rows, radius, point_weights)
        if near is not None:
            rows, nv = near, plain
        else:
            plain = None
    if plain is None:
        nv = np.full((len(v), 3), np.nan)
    for pos in blocks(rows, progress, "normals", block_size(search, rows, radius, "points")):
        indptr, indices = search.neighbors(pos)
        nv[pos] = _block_normals(None, face_normals, pos, v[pos], indptr, indices, radius,
                                 search, plan, point_weights, face_weight)
    return nv


def _refit_rows(v, search, rows, radius, point_weights):
    """The vertices among ``rows`` whose ball of ``radius`` holds a point of weight below 1
    (``point_weights`` per row of ``search.points``), where a fit without the weights must be
    made again with them; None where that is more than half of ``rows`` (fit them all)."""
    light = np.flatnonzero(point_weights < 1.0)
    near = _near_points(v, search.points[light], rows, radius)
    return near if len(near) <= len(rows) // 2 else None


def _near_points(v, centres, rows, radius):
    """The vertices among ``rows`` within ``radius`` of any of the points ``centres`` (m, 3),
    ascending (a few more at the margin: any neighbor list holding a centre, ball or k-ring,
    is among theirs)."""
    if len(centres) == 0 or len(rows) == 0:
        return np.zeros(0, dtype=np.int64)
    reach = radius * (1.0 + 1e-9)
    grid = ball_grid(centres, reach)
    if grid is None:
        return np.asarray(rows, dtype=np.int64)
    return np.sort(rows[ball_counts(grid, v[rows], reach) > 0])


def _block_normals(nv, face_normals, idx, xb, indptr, indices, radius, search, plan,
                   point_weights=None, face_weight=None):
    """Unit normals of one block: taken from ``nv``, or PCA plane fits oriented like the face
    normals (and mixed with them by ``face_weight``, by vertex, where given), towards the
    viewpoint or towards +z."""
    if nv is not None:
        qb = nv[idx]
    else:
        qb = pca_normals(search.points, xb, indptr, indices, radius, point_weights)
        if face_normals is not None:
            orient_like(qb, face_normals[idx])
            # no plane fit (fewer than 3 points in the ball): the faces' normal
            qb = np.where(np.isfinite(qb).all(axis=1)[:, None], qb, face_normals[idx])
            if face_weight is not None:
                with np.errstate(invalid="ignore", divide="ignore"):
                    qb /= np.linalg.norm(qb, axis=1, keepdims=True)
                mixed = qb + face_weight[idx, None] * (face_normals[idx] - qb)
                qb = np.where(np.isfinite(mixed), mixed, qb)
        elif plan.viewpoint is not None:
            orient_towards(qb, xb, plan.viewpoint)
        else:
            orient_along(qb, _UP)
    with np.errstate(invalid="ignore", divide="ignore"):
        return qb / np.linalg.norm(qb, axis=1, keepdims=True)


class _Outputs:
    """The result arrays of :func:`run`, filled block by block."""

    def __init__(self, m):
        self.k1, self.k2, self.residual, self.noise = (np.full(m, np.nan) for _ in range(4))
        self.d1, self.d2, self.normals = (np.full((m, 3), np.nan) for _ in range(3))
        self.n_samples = np.zeros(m, dtype=np.int32)
        self.n_neighbors = np.zeros(m, dtype=np.int32)
        self.status = np.zeros(m, dtype=np.int8)
        self.outlier_score = np.full(m, np.nan)
        # the radius of each row's estimate, as a multiple of the call's (retried rows: more)
        self.radius_factor = np.ones(m)
        # rows whose given normal is far off their neighborhood's plane (:func:`_off_surface`)
        self.off_surface = 0

    def flag_outliers(self):
        """No curvature, status OUTLIER, where the outlier score reaches the Tukey cutoff (the
        points of weight 0 in their neighbors' fits) - unless the point's own position or
        normal already gave a reason."""
        with np.errstate(invalid="ignore"):
            out = (self.outlier_score >= TUKEY_C) & (self.status != Status.NO_POSITION) & \
                (self.status != Status.NO_NORMAL)
        for a in (self.k1, self.k2, self.d1, self.d2, self.residual):
            a[out] = np.nan
        self.status[out] = Status.OUTLIER

    def result(self, radius):
        valid = np.isfinite(self.k1)
        return CurvatureResult(k1=self.k1, k2=self.k2, d1=self.d1, d2=self.d2,
                               normals=self.normals, valid=valid,
                               n_neighbors=self.n_neighbors, n_samples=self.n_samples,
                               residual=self.residual, noise=self.noise, radius=radius,
                               status=self.status, outlier_score=self.outlier_score,
                               radius_used=np.where(valid, float(radius) * self.radius_factor,
                                                    np.nan))


def _normal_field(nv, search, plan):
    """Unit normals of every vertex for the normal-aware circle fits - ``nv`` (given, face,
    spanning-tree or :func:`_pca_field` normals) - in the order of ``search.points`` ((n, 3));
    None when ``plan.normal_constraints`` is off."""
    field = nv
    if not plan.normal_constraints or field is None:
        return None
    with np.errstate(invalid="ignore", divide="ignore"):
        field = field / np.linalg.norm(field, axis=1, keepdims=True)
    return _by_row(field, search)


def _fit_block(out, pos, xb, qb, indptr, indices, radius, search, plan, given_a2=0.0,
               field_of_points=None, point_weights=None, side_normals=None,
               side_flatness=False):
    """Local jet (noise, refined normal) and the fused fits of one block, into ``out[pos]``;
    ``given_a2``: the noise variance of given normals (:func:`given_normal_noise`); with the
    normals of ``search.points`` (see :func:`_normal_field`), normal-aware fits;
    ``point_weights`` (per row of ``search.points``) weight the neighbors in all of them.

    Normals estimated from the points themselves carry nothing the positions do not where
    those are clean, only the bias of their own neighborhoods (Table 2 paraboloid, radius 2:
    mean |dk1| 0.0015 -> 0.0021 at full weight); where there is noise they average it over a
    second neighborhood. Their rows' weight is scaled by ``1 - beta`` (beta the noise blend of
    the weights, 1 on clean data); given normals keep theirs, unless they are refined like
    estimated ones (``refine_normals=True``: e.g. a tiled run's spanning-tree normals).
    ``side_normals`` (per row of ``search.points``): the normals that tell where a ball
    reaches around the surface (:data:`WRAP_POINTS`); None: not checked. ``side_flatness``:
    also mark the balls whose own shape says so (:func:`meshcurv.fit.wrap.beyond_a_cap`; where the side
    normals are estimated over those balls, :func:`side_normals_estimated`)."""
    b = len(xb)
    if plan.normals == "given" and not plan.refine:
        qb, off = _off_surface(search, xb, qb, indptr, indices, radius, point_weights)
        out.off_surface += off
    noise = np.empty(b)
    start = qb.copy() if plan.refine else None
    # normals used as given: the bias correction's tilt test needs the quadric's normal about
    # them, from the same fits as the noise
    quadric = np.empty((b, 3)) if (plan.bias_correction and plan.normals == "given"
                                   and not plan.refine) else None
    jet.local_jet(search.points, xb, qb, indptr, indices, radius,
                  (plan.refine and plan.normal_fit != "sphere") or quadric is not None, noise,
                  point_weights, quadric)
    beta = weight_blend(noise, radius, "auto")
    by_sphere = plan.refine and plan.normal_fit != "quadric"
    if by_sphere or given_a2 > 0:
        fitted, residual, tilt_gain = sphere_normals(search.points, xb, indptr, indices, radius)
        fitted = _oriented_like(fitted, qb)
        if not by_sphere:
            qb = mix_given_normals(qb, fitted, tilt_gain, noise, radius, given_a2)
            quadric = None     # fitted about the normals before the mix
        elif plan.normal_fit == "sphere":
            qb = fitted
        else:
            qb = _mix_normals(qb, fitted, sphericity(noise / radius, residual))
    if plan.refine:
        qb = _mix_normals(start, qb, beta)
    k1, k2, residual, samples, nbrs = (np.empty(b) for _ in range(5))
    d1, d2 = np.empty((b, 3)), np.empty((b, 3))
    status = np.empty(b, dtype=np.int8)
    blend = beta if plan.weighting == "auto" else weight_blend(noise, radius, plan.weighting)
    # the share of the bias correction the measured noise leaves; the slabs' taper trades
    # points for a smooth edge and is on where the correction is, for the same reason (a
    # smaller systematic error against more noise)
    # (the shape check's extra jet fit only where the correction or the taper uses it)
    used = plan.bias_correction or plan.weighting == "auto"
    bias_gain = clean_fraction(bias_noise(search, xb, qb, indptr, indices, radius, noise,
                                          point_weights) if used else noise,
                               BIAS_NOISE_SCALE * radius)
    taper = bias_gain if plan.weighting == "auto" else blend
    # estimated normals' rows: by the measured noise, none where it could not be measured
    constraints = (None, None, None) if field_of_points is None else (
        field_of_points, noise,
        np.ones(b) if plan.normals == "given" and not plan.refine else
        np.where(np.isfinite(noise), 1.0 - beta, 0.0))
    # the normal rows' weight each fit measured: the bias correction's smaller fit takes the
    # same, so the two radii fit the same combination of rows and their bias scales alike
    row_weight = None if field_of_points is None else np.full(b, np.nan)
    fused.curvature_cga(search.points, xb, qb, indptr, indices, radius, blend, plan.fit,
                        (k1, k2, d1, d2, samples, residual, nbrs, status), search.rank,
                        *constraints, point_weights, row_weight, taper)
    if plan.bias_correction:
        k1, k2, d1, d2 = _bias_corrected(search, xb, qb, indptr, indices, radius, blend, plan,
                                         (k1, k2, d1, d2), bias_gain,
                                         constraints + (point_weights,),
                                         samples, quadric, row_weight, taper)
    # the circle fits take the ball for a patch seen from its tangent plane
    wraps = np.zeros(b, dtype=bool)
    if side_normals is not None:
        wraps = wrap.folding_weight(search.points, side_normals, xb, qb, indptr, indices,
                                    radius, point_weights) >= WRAP_POINTS
    if side_flatness:
        wraps |= wrap.beyond_a_cap(search.points, xb, indptr, indices, radius, point_weights)
    if wraps.any():
        for a in (k1, k2, d1, d2, residual):
            a[wraps] = np.nan
        status[wraps] = Status.WRAPS_AROUND
    out.k1[pos], out.k2[pos], out.d1[pos], out.d2[pos] = k1, k2, d1, d2
    out.normals[pos], out.n_samples[pos], out.residual[pos] = qb, samples, residual
    out.n_neighbors[pos], out.noise[pos], out.status[pos] = nbrs, noise, status


def side_normals_estimated(plan, mesh):
    """Whether the folding test's normals are estimated over the fits' own balls: a cloud's,
    unless given and used as they are (a mesh's are its faces'). Its balls' shape is then
    checked too (:func:`meshcurv.fit.wrap.beyond_a_cap`)."""
    return not mesh and (plan.normals != "given" or plan.refine)


def _off_surface(search, xb, qb, indptr, indices, radius, point_weights):
    """``(normals, count)``: the given normals ``qb`` (b, 3) with NaN rows where they are more
    than 60 degrees (:data:`GIVEN_OFF_COS`) off the plane fit of their neighborhood, where
    that ball is a patch of surface (:func:`meshcurv.normals.pca.plane_agreement` at
    :data:`PATCH_FLATNESS`), and how many rows that is."""
    agree = plane_agreement(search.points, xb, qb, indptr, indices, radius, PATCH_FLATNESS,
                            point_weights)
    with np.errstate(invalid="ignore"):
        off = agree < GIVEN_OFF_COS
    count = int(np.count_nonzero(off))
    return (np.where(off[:, None], np.nan, qb) if count else qb), count


def bias_noise(search, xb, qb, indptr, indices, radius, noise, point_weights=None):
    """The noise (b,) that sets the bias correction's share and the slabs' taper: ``noise``
    (the local jet's residual at ``radius``, model units) less the shape's higher orders where
    they are what it measures. Rows whose correction ``noise`` leaves less than half on fit
    the jet again within ``radius / sqrt 2`` (normals ``qb``, the same lists and
    ``point_weights``); where its residual s falls below ``SHAPE_RESIDUAL_DROP`` of ``noise``
    (less where noise alone could: ``SHAPE_FALSE_DROP``) the noise is what is left of s once
    the shape's share (``noise``, scaled by ``2^-SHAPE_RESIDUAL_ORDER`` in variance) is taken
    out of it; elsewhere ``noise``. The result's ``noise`` field stays the jet's residual."""
    gain = clean_fraction(noise, BIAS_NOISE_SCALE * radius)
    rows = np.flatnonzero((gain < BIAS_HALF_GAIN) & np.isfinite(noise))
    if len(rows) == 0:
        return noise
    sub_ptr, sub_idx = csr_rows(indptr, indices, rows)
    small = np.empty(len(rows))
    centres = xb[rows]
    jet.local_jet(search.points, centres, qb[rows], sub_ptr, sub_idx, radius / np.sqrt(2.0),
                  False, small, point_weights)
    # the smaller fit's degrees of freedom: its points (x included) less the quartic's terms
    inside = count_within(search.points, centres, sub_ptr, sub_idx, 0.5 * radius * radius)
    dof = inside + 1 - jet._QUARTIC
    # one quantile per distinct count (a few dozen), not per row
    counts, which = np.unique(np.maximum(dof, 1), return_inverse=True)
    spread = np.sqrt(chi2.ppf(SHAPE_FALSE_DROP, counts) / counts)[which]
    threshold = np.where(dof > 0, np.minimum(SHAPE_RESIDUAL_DROP, spread), 0.0)
    shape = 2.0 ** -SHAPE_RESIDUAL_ORDER
    with np.errstate(invalid="ignore"):
        left = np.sqrt(np.maximum(0.0, (small ** 2 - shape * noise[rows] ** 2) / (1.0 - shape)))
        drops = np.isfinite(left) & (small < threshold * noise[rows])
    out = noise.copy()
    out[rows] = np.where(drops, left, noise[rows])
    return out


def _bias_corrected(search, xb, qb, indptr, indices, radius, blend, plan, large, gain,
                    constraints, large_samples, quadric=None, row_weight=None, taper=None):
    """``large`` (k1, k2, d1, d2) at ``radius`` extrapolated to radius 0 with a second fit over
    the same lists within ``BIAS_RATIO * radius`` (same normals, normal ``constraints`` and
    point weights (the last four arguments of :func:`meshcurv.fit.fused.curvature_cga`) and
    weight profile; the
    half-frequency Euler model, which absorbs what a tilted normal does to opposite half-sets
    of a smaller, more unevenly filled ball), mixed in by ``gain`` (m,), the share the
    measured noise leaves (:func:`clean_fraction` at :data:`BIAS_NOISE_SCALE`). Rows whose
    gain is below :data:`BIAS_MIN_GAIN` keep ``large`` as it is, without the second fit.
    ``quadric``: the local quadric's normals about ``qb`` (see :func:`_tilt`) where already
    fitted, else None; ``row_weight``: the normal rows' weights the fit at ``radius`` used
    (``curvature_cga``'s), which the smaller fit then uses too (None: its own); ``taper``:
    the slabs' taper blend of that fit (None: ``blend``)."""
    rows = np.flatnonzero(gain >= BIAS_MIN_GAIN)
    if len(rows) == 0:
        return large
    everything = len(rows) == len(xb)
    if not everything:
        indptr, indices = csr_rows(indptr, indices, rows)
        xb, qb, blend, gain, large_samples = (a[rows] for a in (xb, qb, blend, gain,
                                                                  large_samples))
        taper = None if taper is None else taper[rows]
        # the per-query constraints (noise, normal gain) and normals; the per-point field
        # and point weights stay whole
        field, row_noise, row_gain, point_weights = constraints
        row_noise, row_gain, quadric, row_weight = (
            None if a is None else a[rows] for a in (row_noise, row_gain, quadric, row_weight))
        constraints = (field, row_noise, row_gain, point_weights)
    b = len(xb)
    small = tuple(np.empty(b) for _ in range(2)) + tuple(np.empty((b, 3)) for _ in range(2))
    scratch = (np.empty(b), np.empty(b), np.empty(b), np.empty(b, dtype=np.int8))
    fused.curvature_cga(search.points, xb, qb, indptr, indices, radius * BIAS_RATIO, blend,
                        plan.fit[:6] + (True,) + plan.fit[7:], small + scratch, search.rank,
                        *constraints, row_weight, taper)
    # only where the smaller ball saw every direction the larger one did: where a sparse or
    # clumpy sampling leaves half-sets of the smaller ball empty, its fit is no measurement of
    # the bias (clumpy torus: max |dk| 0.39 -> 1.7 with the correction applied there)
    gain = np.where(scratch[0] >= large_samples, gain, 0.0)
    if plan.normals == "given" and not plan.refine:
        # normals used as given may be noisy: their tilt from the local quadric's normal
        # turns into an uneven error of the smaller fit's half-sets that the extrapolation
        # doubles (benchmark clouds, clean points, normal noise 0.1: mean |dH| 0.006 -> 0.018)
        gain = gain * clean_fraction(_tilt(search, xb, qb, indptr, indices, radius,
                                           constraints[-1], quadric), BIAS_TILT_SCALE)
    corrected = extrapolate_to_zero(tuple(a if everything else a[rows] for a in large),
                                    small, qb, gain)
    if everything:
        return corrected
    out = tuple(a.copy() for a in large)
    for a, c in zip(out, corrected):
        a[rows] = c
    return out


def _tilt(search, xb, qb, indptr, indices, radius, point_weights, fitted=None):
    """Angle (radians, (b,)) between the unit normals ``qb`` and the normals of the local
    quadric fitted around them (:func:`meshcurv.fit.jet.local_jet`, its ``refined`` output;
    ``fitted`` when already computed); NaN where it has none."""
    if fitted is None:
        fitted = np.empty_like(qb)
        jet.local_jet(search.points, xb, qb, indptr, indices, radius, True, np.empty(len(xb)),
                      point_weights, fitted)
    cos = np.clip(np.einsum("ij,ij->i", fitted, qb), -1.0, 1.0)
    return np.where(np.isfinite(cos), np.arccos(cos), np.nan)


def run(v, f, given_normals, radius, query, plan, progress=False):
    """Principal curvatures at the vertices ``query`` of ``v``: the estimator's block loop.

    Parameters
    ----------
    v : (n, 3) float64, contiguous; f : (m, 3) int64 or None, validated faces
    given_normals : (n, 3) float64 or None; radius : float, model units, squaring safely
    query : (q,) int64 vertex indices; plan : :class:`meshcurv.options.Plan`
    progress : bool, progress bars

    Returns
    -------
    CurvatureResult with q rows
    """
    return run_radii(v, f, given_normals, [radius], query, plan, progress)[0]


def run_radii(v, f, given_normals, radii, query, plan, progress=False):
    """:func:`run` at every radius of ``radii`` (floats, model units): a list of
    CurvatureResult, one per radius in that order.

    Ball neighborhoods come from one search over the largest radius, whose lists serve every
    radius (each kernel keeps the neighbors within its own). k-rings are searched per radius:
    the k-ring limited to a smaller ball is not the larger one cut to that ball.
    """
    what = "vertices" if f is not None else "points"
    if plan.use_kring:
        finite = None
        searches = [kring_search(v, f, radii[0])]
        searches += [_search_like(searches[0], v, f, finite, r) for r in radii[1:]]
        # work per query from a sample: smaller blocks for large balls, an error where infeasible
        block = min(block_size(s, query, r, what) for s, r in zip(searches, radii))
    else:
        finite = np.flatnonzero(np.isfinite(v).all(axis=1))
        shared = ball_search(v, finite, max(radii))
        searches = [shared] * len(radii)
        block = block_size(shared, query, max(radii), what)
    # faces wound coherently and outward once for every radius: they orient the face normals
    repair = ""
    if f is not None and plan.normals not in ("given", "mst"):
        m = len(f)
        f, turned, repeated = coherent_faces(v, f, searches[0].adjacency)
        repair = _repair_note(m, turned, repeated)
    scales = [_prepare_scale(v, f, given_normals, r, s, finite, query, block, plan, progress,
                             repair) for s, r in zip(searches, radii)]
    outs = [_Outputs(len(query)) for _ in radii]
    # queries by grid cell for ball queries (the points a block touches then stay in cache);
    # as given for k-rings, whose memory accesses follow the mesh's own numbering
    order = len(query) if plan.use_kring else spatial_order(v[query], max(radii))
    # the folding test's normals: a mesh's face normals (local, where a wide ball's plane
    # fits may be anything), else the fits' field
    sides = [sc.field if sc.face_normals is None else _by_row(sc.face_normals, sc.search)
             for sc in scales]
    flatness = side_normals_estimated(plan, f is not None)
    for pos in blocks(order, progress, "curvature", block):
        idx = query[pos]
        xb = v[idx]
        lists = None if plan.use_kring else shared.neighbors(idx)
        for out, sc, side in zip(outs, scales, sides):
            indptr, indices = sc.search.neighbors(idx) if plan.use_kring else lists
            qb = _block_normals(sc.block_normals, sc.face_normals, idx, xb, indptr, indices,
                                sc.radius, sc.search, plan, sc.weights, sc.face_weight)
            _fit_block(out, pos, xb, qb, indptr, indices, sc.radius, sc.search, plan,
                       sc.given_a2, sc.field, sc.weights, side, flatness)
            del indptr, indices
        del lists
    results = []
    for out, sc in zip(outs, scales):
        if plan.sparse_retry:
            # retried rows get normals of their own, wider balls (not this radius' field)
            retry_sparse(out, v, f, sc.start_normals, sc.face_normals, sc.radius, query, plan,
                         sc.search, sc.face_weight)
        if sc.score is not None:
            out.outlier_score[:] = sc.score[query]
            out.flag_outliers()
        res = out.result(sc.radius)
        res.orientation = sc.note
        if out.off_surface:
            res.orientation += (f"; {out.off_surface} given normals are more than 60 degrees "
                                f"off the plane fit of their neighbourhood (wrong, or from "
                                f"another frame?): no estimate there (status NO_NORMAL)")
        if plan.normals == "mst":
            res = reoriented_by_fits(res, v, sc.start_normals, query, sc.search, block)
        results.append(res)
    return results


class _Scale(NamedTuple):
    """What the blocks of one radius use (:func:`_prepare_scale`): the radius and its search;
    the outlier ``score`` (by vertex) and ``weights`` (by row of ``search.points``), None
    without the outlier pass; ``start_normals``, ``face_normals`` and ``note`` of
    :func:`_start_normals` (and its ``face_weight``); ``block_normals``, the same or the
    plane-fit field of
    :func:`_pca_field`; ``given_a2`` (:func:`given_normal_noise`); ``field``, the neighbors'
    normals of the normal-aware fits (:func:`_normal_field`) or None."""

    radius: float
    search: Search
    score: object
    weights: object
    start_normals: object
    face_normals: object
    note: str
    block_normals: object
    given_a2: float
    field: object
    face_weight: object = None


def _repair_note(m, turned, repeated):
    """The orientation note's account of :func:`meshcurv.normals.winding.coherent_faces` on
    ``m`` faces: ``turned`` of them turned, ``repeated`` left out as repeats; "" if none."""
    said = ([f"{repeated} of {m} faces repeating another left out"] if repeated else [])
    said += ([f"{turned} of {m - repeated} faces turned to wind like their neighbours, "
              f"outward where closed"] if turned else [])
    return f" ({'; '.join(said)})" if said else ""


def _prepare_scale(v, f, given_normals, r, s, finite, query, block, plan, progress,
                   repair=""):
    """The :class:`_Scale` of radius ``r`` over the search ``s``; ``repair``: see
    :func:`_start_normals`."""
    score = weights = weight = tree = plain = halves = None
    # estimated normals get the wide field's mix (see below; a mesh's where its normal rows
    # weigh something); the split halves of the neighborhoods come with the outlier pass's
    # lists when they are of this radius
    mixes = plan.normal_constraints and plan.refine and plan.wide_field
    # not from the lists: before the outlier pass, whose plane fits take the faces' sides
    start = None if plan.normals == "mst" else _start_normals(v, f, given_normals, r, s,
                                                              finite, plan, progress,
                                                              repair=repair)
    if mixes and f is not None:
        mixes = _normal_rows_weigh(v, s, r, plan, start)
    if plan.robust_points:
        # scores by vertex; weights by row of s.points (the grid's order where it has one);
        # the same lists give the spanning tree's or the unweighted plane-fit normals
        rows = _scored_rows(v, s, query, finite, block, plan)
        faces = (None, None) if start is None else (start[1], start[3])
        score, tree, plain, halves = _outlier_pass(v, f, r, s, rows, plan, progress, block,
                                                   *faces, split=mixes and s.radius == r)
        weight = outliers.outlier_weight(score)
        weights = _by_row(weight, s)
    if start is None:
        # the spanning tree's normals unweighted (from the outlier pass's lists, or their own):
        # they are estimate_normals', which tiled runs share between tiles (the weighted local
        # jet refines them)
        start = ((tree[0], None, tree[1], None) if tree is not None else
                 _start_normals(v, f, given_normals, r, s, finite, plan, progress))
    nv, face_normals, note, face_weight = start
    given_a2 = given_normal_noise(v, nv, r, s, query) if plan.check_given else 0.0
    block_nv = nv
    if plan.normal_constraints and nv is None:
        block_nv = _pca_field(v, face_normals, s, finite, r, plan, progress, weights, plain,
                              face_weight)
    field = block_nv
    # estimated normals made before the outlier weights (a mesh's, the spanning tree's, a
    # tile's) are fitted again with them for the neighbors' normal rows, keeping their sides:
    # a stray point tilts the plane fits of all its neighbors (the plane-fit field above has
    # the weights already)
    reweigh = (plan.normal_constraints and plan.refine and nv is not None
               and weights is not None and np.any(weights < 1.0))
    if mixes:
        # estimated normals (a mesh's plane fits oriented like its faces; a cloud's spanning
        # tree's, a tile's, or plane fits turned towards the viewpoint or +z) fitted again for
        # the neighbors' normal rows over the neighborhood of FIELD_RATIO times the radius,
        # with the outlier weights, keeping their sides: the orientation rule decides signs
        # only
        wide = _search_like(s, v, f, finite, FIELD_RATIO * r)
        field = _pca_field(v, nv if nv is not None else face_normals, wide, finite,
                           FIELD_RATIO * r, plan, progress, _by_row(weight, wide))
        # a cloud's are unweighted plane fits: fitted again only where a neighborhood holds a
        # down-weighted point
        narrow = _pca_field(v, nv, s, finite, r, plan, progress, weights, nv.copy()) \
            if reweigh else block_nv
        # the mix's halves follow the order of the lists: those of a ball of this radius (a
        # list of radii shares the largest one's lists), as a call at this radius alone has
        own = s if s.radius == r else _search_like(s, v, f, finite, r)
        field = _mixed_field(v, narrow, field, r, own, finite, block, _by_row(weight, own),
                             halves)
    elif reweigh:
        field = _pca_field(v, nv, s, finite, r, plan, progress, weights)
    return _Scale(r, s, score, weights, nv, face_normals, note, block_nv, given_a2,
                  _normal_field(field, s, plan), face_weight)


def _normal_rows_weigh(v, search, radius, plan, start):
    """Whether the normal rows of a mesh's circle fits weigh something (see
    :data:`WIDE_FIELD_GAIN`): the gain ``1 - beta`` the blocks give them, from the noise of
    :func:`meshcurv.fit.jet.local_jet` at a sample of the vertices (all of them, whatever
    the query: a row's estimate does not depend on which others are asked for) with their
    block normals (``start``: :func:`_start_normals`' tuple)."""
    nv, face_normals, _, face_weight = start
    sample = _sample_queries(len(v), WIDE_FIELD_SAMPLE)
    if not len(sample):
        return False
    indptr, indices = search.neighbors(sample)
    xb = v[sample]
    qb = _block_normals(nv, face_normals, sample, xb, indptr, indices, radius, search, plan,
                        face_weight=face_weight)
    noise = np.empty(len(sample))
    jet.local_jet(search.points, xb, qb, indptr, indices, radius, False, noise)
    gain = np.where(np.isfinite(noise), 1.0 - weight_blend(noise, radius, "auto"), 0.0)
    return bool(np.quantile(gain, 0.99) >= WIDE_FIELD_GAIN)


def field_mix(disagreement, split):
    """Weight (n,) in [0, 1] of each point's wide plane-fit normal (over FIELD_RATIO times the
    radius) against its narrow one (over the radius) in the normal-aware fits' field.

    ``disagreement``: the mean over the point's ball of ``sin^2`` of the angle between the
    narrow and the wide normal; ``split``: the same mean of
    :func:`meshcurv.normals.pca.split_disagreement`, how far noise alone (position noise and a
    random sampling) moves a plane fit of half a ball, whatever the shape. Where noise alone
    separates the narrow and wide fits, ``disagreement`` is ``E = FIELD_NOISE_RATIO *
    split``; what it holds beyond E, ``b2 = disagreement - E``, is the fits' bias (the
    curvature's variation across a ball, an anisotropic sampling), which grows like the
    squared radius: the narrow fit's squared bias is ``b2 / (rho^2 - 1)^2``, rho =
    FIELD_RATIO, the wide fit's rho^4 times it. The wide fit's noise is a part of the narrow
    one's (nested least squares), so the mix of least expected squared error of the two is
    ``(E - b2 / (rho^2 - 1)) / (E + b2)``: 1 (wide) where the two differ as noise makes them,
    0 (narrow) where the bias reaches ``(rho^2 - 1) E``. 1 where either is NaN (the wide fit
    alone)."""
    with np.errstate(invalid="ignore", divide="ignore"):
        noise = FIELD_NOISE_RATIO * split
        bias = np.maximum(disagreement - noise, 0.0)
        mix = np.clip((noise - bias / (FIELD_RATIO ** 2 - 1.0)) / (noise + bias), 0.0, 1.0)
    return np.where(np.isfinite(mix), mix, 1.0)


def _mixed_field(v, narrow, wide, radius, search, finite, block, point_weights=None,
                 halves=None):
    """The normal field (n, 3) of the normal-aware fits: ``narrow + mix (wide - narrow)``,
    normalised, with ``wide`` (turned to ``narrow``'s side) the plane fits over FIELD_RATIO
    times ``radius`` and ``mix`` of :func:`field_mix` from the ball of ``radius`` (``search``'s
    lists; ``point_weights`` per row of its points weight the split fits and the means);
    ``wide`` where ``narrow`` is NaN. The two halves of a ball are its list's alternate
    entries (:func:`meshcurv.normals.pca.split_disagreement`): the grid's order, which
    interleaves a regular sampling (a random half of a grid is noisier than the grid, and
    made the mix take the wide fits too often: icosphere-scaled ellipsoid cloud, 0.1 % noise,
    mean |dk| 0.033 -> 0.038). The grid's lists are the same in a tile as in the whole cloud.
    ``halves``: the split disagreement without ``point_weights`` (n,), if at hand: it is
    fitted again only near down-weighted points, as in :func:`_pca_field`."""
    n = len(v)
    rows = np.arange(n) if finite is None else finite
    if search.rank is not None:
        rows = search.rank          # the grid's cell order: neighborhoods stay in cache
    with np.errstate(invalid="ignore"):
        cos = np.einsum("ij,ij->i", narrow, wide)
    values = np.full((n, 2), np.nan)
    values[:, 0] = np.maximum(0.0, 1.0 - cos * cos)
    split_rows = rows
    if halves is not None:
        near = _refit_rows(v, search, rows, radius, point_weights)
        if near is not None:
            split_rows = near
            values[:, 1] = halves
    for pos in blocks(split_rows, False, "", block):
        indptr, indices = search.neighbors(pos)
        values[pos, 1] = split_disagreement(search.points, v[pos], indptr, indices, radius,
                                            point_weights)
    means = np.full((n, 2), np.nan)
    by_row = values if search.rank is None else values[search.rank]
    for pos in blocks(rows, False, "", block):
        indptr, indices = search.neighbors(pos)
        part = np.empty((len(pos), 2))
        ball_mean(search.points, v[pos], indptr, indices, radius * radius, by_row, part,
                  point_weights)
        means[pos] = part
    mix = field_mix(means[:, 0], means[:, 1])
    turned = np.where((cos < 0)[:, None], -wide, wide)
    with np.errstate(invalid="ignore", divide="ignore"):
        mixed = narrow + mix[:, None] * (turned - narrow)
        mixed /= np.linalg.norm(mixed, axis=1, keepdims=True)
    return np.where(np.isfinite(mixed).all(axis=1)[:, None], mixed, wide)


def _by_row(values, search):
    """Per-vertex ``values`` (n, ...) in the order of ``search.points`` (None stays None)."""
    return values if values is None or search.rank is None else values[search.rank]


def _needs_support(out, plan):
    """Rows of ``out`` estimated from too few points: fits that failed for lack of them (and,
    for estimated normals, plane fits that had no 3 points), and estimates whose local cubic
    fit had no 11 points (noise NaN: no noise measured, normal not refined)."""
    lacking = np.isin(out.status, SPARSE_STATUSES)
    if plan.normals != "given":
        lacking |= out.status == Status.NO_NORMAL
    thin = (out.status == Status.OK) & ~np.isfinite(out.noise)
    return np.flatnonzero(lacking | thin)


def _reference_normals(nv, trusted, rank, indptr, indices):
    """A sign reference per neighbor list: the sum of the normals ``nv`` (vertex order) of its
    ``trusted`` vertices ((n,) bool, finite normals), zero where it has none (``rank`` maps
    list entries to vertices, None if they are vertices)."""
    rows = indices if rank is None else rank[indices]
    nb = np.where(trusted[rows, None], nv[rows], 0.0)
    owner = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    ref = np.zeros((len(indptr) - 1, 3))
    np.add.at(ref, owner, nb)
    return ref


def _refit(v, idx, nv, face_normals, r, search, plan, own_normals, trusted=None,
           face_weight=None):
    """:class:`_Outputs` of the vertices ``idx`` at radius ``r`` over ``search``. Normals: the
    given or face ones (``nv``); else plane fits over the ball of ``r``, oriented like the
    faces, the viewpoint or, for spanning-tree normals (``own_normals`` False), the
    spanning-tree normals ``nv`` of the ``trusted`` vertices in the ball (see
    :func:`_reference_normals`; none where the ball holds none of them)."""
    sub = _Outputs(len(idx))
    # the folding test's normals (:func:`_fit_block`), as the call's: a mesh's faces', else
    # the given or spanning-tree ones, plane fits' over these balls being what it doubts
    side = _by_row(face_normals if face_normals is not None else nv, search)
    for pos in blocks(len(idx), False, "", block_size(search, idx, r, "points")):
        xb = v[idx[pos]]
        indptr, indices = search.neighbors(idx[pos])
        if plan.normals == "mst" and not own_normals:
            qb = pca_normals(search.points, xb, indptr, indices, r)
            ref = _reference_normals(nv, trusted, search.rank, indptr, indices)
            orient_like(qb, ref)
            qb[~np.any(ref != 0.0, axis=1)] = np.nan     # no side to take: no normal
            with np.errstate(invalid="ignore", divide="ignore"):
                qb /= np.linalg.norm(qb, axis=1, keepdims=True)
        else:
            qb = _block_normals(nv, face_normals, idx[pos], xb, indptr, indices, r, search,
                                plan, face_weight=face_weight)
        _fit_block(sub, pos, xb, qb, indptr, indices, r, search, plan, side_normals=side,
                   side_flatness=side_normals_estimated(plan, face_normals is not None))
    return sub


def _take(out, rows, sub, done):
    """Copy the rows ``done`` of ``sub`` into rows ``rows[done]`` of ``out``."""
    for name in ("k1", "k2", "d1", "d2", "normals", "n_samples", "residual", "noise",
                 "n_neighbors", "status"):
        getattr(out, name)[rows[done]] = getattr(sub, name)[done]


def retry_sparse(out, v, f, nv, face_normals, radius, query, plan, search, face_weight=None):
    """Re-estimate, in place, the rows of ``out`` that had too few points (:func:`_needs_support`).

    First at ``SPARSE_FACTORS`` times ``radius``, each row at the first factor whose fit
    succeeds with a ball of at most ``MAX_BALL_FRACTION`` of the finite points. The fits that
    still fail then at ``radius`` and at those factors again with half-sets of
    ``SPARSE_MIN_POINTS`` point: a coarse ring (a low-poly mesh's 1-ring) puts one or two points
    in each half-set, and the circle through x and one point p centred on the normal line is
    the classic ``2 h / |p - x|^2`` estimate of the normal curvature towards p (exact on
    spheres), 5 or more of them averaged by the Euler fit. ``search`` is the search of
    ``radius``. A wider ball reaching around the surface serves nothing (the folding test of
    :func:`_fit_block`, with the call's normals). Rows nothing serves keep their estimate,
    except on clouds with estimated normals, where an estimate from fewer than 11 points has
    no checked normal and is dropped. ``face_weight``: as in :func:`_block_normals`.
    """
    rows = _needs_support(out, plan)
    if not len(rows):
        return
    finite = np.flatnonzero(np.isfinite(v).all(axis=1))
    most = MAX_BALL_FRACTION * len(finite)
    sparse = plan._replace(fit=plan.fit[:2] + (float(SPARSE_MIN_POINTS),) + plan.fit[3:])
    wide = {1.0: search}       # the searches of the larger radii, made when first needed

    def search_at(factor):
        if factor not in wide:
            wide[factor] = _search_like(search, v, f, finite, radius * factor)
        return wide[factor]
    passes = [(factor, plan) for factor in SPARSE_FACTORS]
    if plan.fit[2] > SPARSE_MIN_POINTS:
        passes += [(factor, sparse) for factor in (1.0,) + SPARSE_FACTORS]
    # sign references of the spanning-tree normals: points with 11 neighbors (a sparse clump's
    # tree may be a piece of its own, turned away from its own centroid), and those oriented
    # by a pass
    trusted = np.zeros(len(v), dtype=bool)
    trusted[query] = np.isfinite(out.noise) & np.isfinite(out.normals).all(axis=1)
    reference = nv.copy() if plan.normals == "mst" else None
    for factor, how in passes:
        rows = rows[(out.status[rows] != Status.OK) |
                    (~np.isfinite(out.noise[rows]) & (how is plan))]
        if not len(rows):
            break
        local = rows[search_at(factor).counts(query[rows]) <= most] if factor > 1.0 else rows
        if not len(local):
            continue
        sub = _refit(v, query[local], reference if reference is not None else nv,
                     face_normals, radius * factor, search_at(factor), how,
                     how is sparse and factor == 1.0, trusted, face_weight)
        done = (sub.status == Status.OK) & ((sub.n_neighbors <= most) | (factor == 1.0))
        if how is sparse and not plan.use_kring:
            # one-point half-sets of a cloud only where the cubic fit checked the normal; a
            # mesh's rings are its own neighborhoods (an icosahedron's 1-ring: 5 points)
            done &= np.isfinite(sub.noise)
        _take(out, local, sub, done)
        out.radius_factor[local[done]] = factor
        if reference is not None:
            oriented = done & np.isfinite(sub.noise)
            trusted[query[local[oriented]]] = True
            reference[query[local[oriented]]] = sub.normals[oriented]
    if plan.normals in ("mst", "pca") and not plan.use_kring:
        # a plane fit through fewer than 11 points of a clumpy cloud may be tilted by 90
        # degrees, and no larger ball served: no estimate
        thin = (out.status == Status.OK) & ~np.isfinite(out.noise)
        for name in ("k1", "k2", "d1", "d2", "residual"):
            getattr(out, name)[thin] = np.nan
        out.status[thin] = Status.TOO_FEW_NEIGHBORS
