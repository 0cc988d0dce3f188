"""The tangent frame (tu, tv, n) at a point: compiled kernel.

Its numpy specification is :func:`meshcurv.fit.frame_spec.tangent_u`.
"""

import math

from numba import njit

@njit(cache=True)
def tangent_frame(points, nbr, lo, hi, x, n, r2max, tu, tv, rank, point_weights=None):
    """Tangent frame (tu, tv, n) that rotates with the data.

    tu is the tangential part of the offset to the neighbor of lowest index lying at least
    30 degrees off the normal. The choice depends on neither the order of the neighbor list
    nor the coordinates' position, scale or orientation, so the frame - and with it the
    sampling planes - is equivariant under rotation, translation and scaling. Falls back to a
    fixed frame if there is no such neighbor. ``rank`` (or None: the row itself) is the index
    of each row of ``points``, for points stored in another order than the input's.
    Neighbors of weight 0 in ``point_weights`` (per row, optional) are passed over: a point
    left out of the fits does not turn their planes either.
    """
    found = False
    best = -1
    for j in range(lo, hi):
        k = nbr[j]
        key = k if rank is None else rank[k]
        if found and key >= best:
            continue
        if point_weights is not None and not point_weights[k] > 0.0:
            continue
        qx = points[k, 0] - x[0]
        qy = points[k, 1] - x[1]
        qz = points[k, 2] - x[2]
        if qx * qx + qy * qy + qz * qz > r2max:
            continue
        hq = qx * n[0] + qy * n[1] + qz * n[2]
        ux = qx - hq * n[0]
        uy = qy - hq * n[1]
        uz = qz - hq * n[2]
        t2 = ux * ux + uy * uy + uz * uz
        if t2 > 0.25 * (t2 + hq * hq) and t2 > 0.0:
            s = 1.0 / math.sqrt(t2)
            tu[0] = ux * s
            tu[1] = uy * s
            tu[2] = uz * s
            found = True
            best = key
    if not found:
        # any unit vector orthogonal to n
        if abs(n[0]) < 0.9:
            ax, ay, az = 1.0, 0.0, 0.0
        else:
            ax, ay, az = 0.0, 1.0, 0.0
        d = ax * n[0] + ay * n[1] + az * n[2]
        ux = ax - d * n[0]
        uy = ay - d * n[1]
        uz = az - d * n[2]
        s = 1.0 / math.sqrt(ux * ux + uy * uy + uz * uz)
        tu[0] = ux * s
        tu[1] = uy * s
        tu[2] = uz * s
    tv[0] = n[1] * tu[2] - n[2] * tu[1]
    tv[1] = n[2] * tu[0] - n[0] * tu[2]
    tv[2] = n[0] * tu[1] - n[1] * tu[0]
