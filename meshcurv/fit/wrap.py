"""Balls that reach around the surface: a ball wider than a tube or sphere holds its far
side and the surface bending around to it. Compiled kernel :func:`folding_weight`; its numpy
specification is :func:`meshcurv.fit.wrap_spec.folding_weight`.
Where the normals are estimated over the balls themselves, :func:`beyond_a_cap` tells it
from the balls' shape.

The circle fits take a neighborhood for a patch of surface seen from its tangent plane; past a
quarter turn around a tube (radius R > sqrt 2 r) it folds back over that plane. A neighbor p
with unit normal a is on the far side when its normal is turned from the query's n by more
than :data:`TURN` (``a . n < cos TURN``) and it lies across its own tangent plane from the
query x as a point that far around a circle does: on a circle seen from one of its points, a
point at angle t around it has ``|(x - p) . a| = |x - p| sin(t / 2)``, so the test is
``|(x - p) . a| > |x - p| sin(TURN / 2)``. A neighbor whose normal a failed orientation
flipped, but which lies beside x along the surface (``(x - p) . a`` near 0), is not far.

Two sheets facing away from each other (a thin plate, a pipe's wall) have far sides too, but
the circle fits cope with them (flat sheets 0.1 apart in balls of 0.3 with their normals:
exact; a pipe wall 1 / 1.1 at 0.15-0.3: 2 % of k); what they miss is the surface bending
between them. The weight of folding is the smaller of the far side's and that of the bend,
the neighbors whose normals are turned by between 180 - TURN and TURN degrees.

TURN is 120 degrees, a third of a turn: mean |dk| / k1 of meshcurv's estimate (a torus 3 / 0.4
of 300 x 24 vertices, an icosphere of radius 0.3 with 2562; the ball's reach around the circle
in brackets) at R = 1.41 r (90 degrees) 0.0004 and 0.0001, 1.6 r (106) 0.006 and 0.015, 1.8 r
(128) 0.028 and 0.089, 2 r (180: the whole section) 0.11 and 0.60, 2.4 r 0.53 and 0.45, all
marked valid before this test; at 1.8 r and beyond the far side holds 0.3-25 % of the ball's
points.
"""

import math

import numpy as np
from numba import njit, prange

from ..neighbors.csr import count_within, csr_rows
from ..normals.pca import ball_spread

__all__ = ["folding_weight", "beyond_a_cap", "TURN", "CAP_FLATNESS", "SECTION_KEEP"]

TURN = math.radians(120.0)

_TURN_COS = math.cos(TURN)

# The flatness (:func:`meshcurv.normals.pca.ball_spread`) of an evenly sampled spherical cap
# whose rim lies TURN around from its centre: (1 - cos T) / (2 (2 + cos T)) = 1/2. A ball
# less flat than that reaches around more than the test above allows, whatever the normals say
# (a tube's ball gets there at 1.9 times its radius).
CAP_FLATNESS = (1.0 - _TURN_COS) / (2.0 * (2.0 + _TURN_COS))

# The share of a ball's width (its middle eigenvalue, model units) that the ball of radius / s
# keeps where it holds a round section still (:func:`beyond_a_cap`): at s = sqrt 2 a tube's
# section lies whole in both balls and keeps it all; a surface's patch and a ball of noise
# keep half (1 / s^2), and noise as wide as 0.76 of the radius is needed to reach 0.85 there.
# At s = 2, where a section 4 times narrower than the ball stays whole, half.
SECTION_KEEP = ((2.0, 0.85), (4.0, 0.5))
_ACROSS2 = math.sin(0.5 * TURN) ** 2


@njit(parallel=True, cache=True)
def folding_weight(points, normals, query_points, query_normals, indptr, indices, radius,
                   point_weights=None):
    """The weight of folding (m,) in each query point's ball of ``radius`` (module
    docstring): the smaller of the weights of its neighbors on the far side and on the bend
    (their counts, or the sums of their ``point_weights``); 0 where the query point or its
    normal is undefined.

    Parameters
    ----------
    points, normals : (n, 3) float64, the neighbors and their unit normals (NaN: left out)
    query_points, query_normals : (m, 3) float64, unit normals
    indptr, indices : CSR lists into ``points``
    radius : float, model units
    point_weights : (n,) float64 in [0, 1] or None
    """
    m = query_points.shape[0]
    out = np.zeros(m)
    r2 = radius * radius
    for q in prange(m):
        x0, x1, x2 = query_points[q, 0], query_points[q, 1], query_points[q, 2]
        n0, n1, n2 = query_normals[q, 0], query_normals[q, 1], query_normals[q, 2]
        if not np.isfinite(x0 + x1 + x2 + n0 + n1 + n2):
            continue
        far = 0.0
        bend = 0.0
        for e in range(indptr[q], indptr[q + 1]):
            j = indices[e]
            a0, a1, a2 = normals[j, 0], normals[j, 1], normals[j, 2]
            cos = a0 * n0 + a1 * n1 + a2 * n2
            if not cos < -_TURN_COS:                 # NaN normals too
                continue
            d0 = x0 - points[j, 0]
            d1 = x1 - points[j, 1]
            d2 = x2 - points[j, 2]
            dd = d0 * d0 + d1 * d1 + d2 * d2
            if not dd <= r2:
                continue
            w = 1.0 if point_weights is None else point_weights[j]
            if cos >= _TURN_COS:
                bend += w
            else:
                across = d0 * a0 + d1 * a1 + d2 * a2
                if across * across > _ACROSS2 * dd:
                    far += w
        out[q] = min(far, bend)
    return out


def beyond_a_cap(points, xb, indptr, indices, radius, point_weights=None):
    """Whether each ball (b,) reaches around the surface by its shape alone: it is less flat
    than a cap reaching a third of a turn around a sphere (the smallest eigenvalue of its
    points' covariance over the middle one, :func:`meshcurv.normals.pca.ball_spread`, above
    :data:`CAP_FLATNESS`), and, in the balls of ``radius / s`` about the
    same point (s = sqrt 2 and 2, each holding at least half the points a surface through the
    point would put there, ``1 / s^2`` of them), either
    - its flatness falls at least like the square of the radius, as a surface's shape makes
      it (measured 0.22-0.43 and 0.08-0.19 of it at the two, on the tori and spheres of
      this module from 1.8 times their radius), or
    - the ball of radius / sqrt 2 or radius / 2 is as little flat (a section still round
      there) and its middle eigenvalue, the section's width (model units), keeps at least
      :data:`SECTION_KEEP` of the ball's, where a surface's falls like the square of the
      radius: a tube narrower than the ball (a pole, a branch, a wire; a pole of radius 0.1
      in balls of 0.44: 97 % of its rows marked, k1 0.3 for 10 before). At radius / 2 alone
      tubes 2.2-4 times narrower than the ball passed (pole of radius 0.1 alone at 0.3 and
      0.35: 97 % and 98 % of the rows valid, median k1 0.18 and 0.32 for 10; the torus
      3 / 0.4 cloud at 3 and 3.5 times its radius 96 % and 95 %, k1 0.9 of itself off);
      radius / sqrt 2 marks them all; at 0.277, 2.77 times the pole's radius, 91 % (the
      rest: balls not less flat than a cap to begin with).

    Noise makes a ball's flatness rise as it shrinks and its width fall with it: a ball of
    noise is no fold; a point lying off the surface in noise sees the surface in its ball
    but few points near it. Measured on CNC clouds without normals at sigma_eps 0.2 and
    balls of ~50 points (noise 0.4 of the radius): 819, 18420 and 37 rows of 25k-50k above
    1/2, 2, 17 and 1 of them marked; none at the default radius (the test at radius / sqrt 2
    added 5 rows of torus_050000 there, no row of the other CNC clouds, of the terrains, of
    the falling-density half sphere or of the sphere with spikes in ``docs/accuracy_cases``).
    At a border, noise as wide as the half-ball can pass for a round section: squares with
    noise of 0.2 and 0.5 of the radius, 3 and 1 border rows of 40k marked with balls of ~800
    points; 0.2 and 0.3, 4 and 13 of 3000 with ~60 (none a radius from the border)."""
    ev = ball_spread(points, xb, indptr, indices, radius, point_weights)
    with np.errstate(invalid="ignore", divide="ignore"):
        flat = ev[:, 0] / ev[:, 1]
        out = flat > CAP_FLATNESS
    rows = np.flatnonzero(out)
    if len(rows):
        centres = xb[rows]
        sub = csr_rows(indptr, indices, rows)
        total = count_within(points, centres, *sub, radius * radius)
        surface = np.ones(len(rows), dtype=bool)
        tube = np.zeros(len(rows), dtype=bool)
        for s2, keep in SECTION_KEEP:
            inner = radius / math.sqrt(s2)
            small = ball_spread(points, centres, *sub, inner, point_weights)
            enough = 2.0 * s2 * count_within(points, centres, *sub, inner * inner) >= total
            with np.errstate(invalid="ignore", divide="ignore"):
                surface &= enough & (small[:, 0] / small[:, 1] <= flat[rows] / s2)
                # eigenvalues in units of the inner radius squared
                tube |= enough & (small[:, 0] / small[:, 1] > CAP_FLATNESS) & (
                    small[:, 1] / s2 >= keep * ev[rows, 1])
        out[rows] = surface | tube
    return out
