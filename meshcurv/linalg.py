"""Numba helpers every compiled kernel shares: the 3x3 symmetric eigensolver (Jacobi), the
small symmetric solve (Cholesky), the offset of a neighbor inside the ball, and the chunk size
of the per-point ``prange`` loops.

A leaf: imports nothing of meshcurv.
"""

import math

from numba import njit

# Points per chunk handed to one thread (keeps scratch arrays per chunk, not per point).
CHUNK = 256


@njit(cache=True)
def jacobi_rotation(app, aqq, apq):
    """``(c, s, t)``: cosine, sine and tangent of the Jacobi rotation that zeroes the entry
    ``apq`` of a symmetric matrix with diagonal entries ``app``, ``aqq`` (Golub & Van Loan,
    sym.schur2); ``apq`` non-zero."""
    tau = (aqq - app) / (2.0 * apq)
    if tau >= 0.0:
        t = 1.0 / (tau + math.sqrt(1.0 + tau * tau))
    else:
        t = -1.0 / (-tau + math.sqrt(1.0 + tau * tau))
    c = 1.0 / math.sqrt(1.0 + t * t)
    return c, t * c, t


@njit(cache=True)
def smallest_eigvec_jacobi3(a, out):
    """Unit eigenvector of the smallest eigenvalue of the symmetric 3x3 ``a`` (overwritten).

    Cyclic Jacobi rotations to machine precision (as accurate as LAPACK's ``eigh`` here, unlike
    a closed-form cubic); the rotations are accumulated in the local ``v00 .. v22``.
    """
    v00 = 1.0
    v01 = 0.0
    v02 = 0.0
    v10 = 0.0
    v11 = 1.0
    v12 = 0.0
    v20 = 0.0
    v21 = 0.0
    v22 = 1.0
    for sweep in range(50):
        off = a[0, 1] * a[0, 1] + a[0, 2] * a[0, 2] + a[1, 2] * a[1, 2]
        diag = a[0, 0] * a[0, 0] + a[1, 1] * a[1, 1] + a[2, 2] * a[2, 2]
        if off <= 1e-36 * diag or off == 0.0:
            break
        for pq in range(3):
            if pq == 0:
                p, q, r = 0, 1, 2
            elif pq == 1:
                p, q, r = 0, 2, 1
            else:
                p, q, r = 1, 2, 0
            apq = a[p, q]
            if apq == 0.0:
                continue
            c, s, t = jacobi_rotation(a[p, p], a[q, q], apq)
            app = a[p, p]
            aqq = a[q, q]
            arp = a[r, p]
            arq = a[r, q]
            a[p, p] = app - t * apq
            a[q, q] = aqq + t * apq
            a[p, q] = 0.0
            a[q, p] = 0.0
            a[r, p] = c * arp - s * arq
            a[p, r] = a[r, p]
            a[r, q] = s * arp + c * arq
            a[q, r] = a[r, q]
            # columns p, q of the accumulated rotation V
            if p == 0 and q == 1:
                v00, v01 = c * v00 - s * v01, s * v00 + c * v01
                v10, v11 = c * v10 - s * v11, s * v10 + c * v11
                v20, v21 = c * v20 - s * v21, s * v20 + c * v21
            elif p == 0:
                v00, v02 = c * v00 - s * v02, s * v00 + c * v02
                v10, v12 = c * v10 - s * v12, s * v10 + c * v12
                v20, v22 = c * v20 - s * v22, s * v20 + c * v22
            else:
                v01, v02 = c * v01 - s * v02, s * v01 + c * v02
                v11, v12 = c * v11 - s * v12, s * v11 + c * v12
                v21, v22 = c * v21 - s * v22, s * v21 + c * v22
    k = 0
    if a[1, 1] < a[k, k]:
        k = 1
    if a[2, 2] < a[k, k]:
        k = 2
    if k == 0:
        x, y, z = v00, v10, v20
    elif k == 1:
        x, y, z = v01, v11, v21
    else:
        x, y, z = v02, v12, v22
    s = 1.0 / math.sqrt(x * x + y * y + z * z)
    out[0] = x * s
    out[1] = y * s
    out[2] = z * s


@njit(cache=True)
def normal_frame(n0, n1, n2, frame):
    """Rows of ``frame`` (3, 3): a unit tangent t (e_x x n, or e_y x n where n is near e_x),
    n x t, and the unit normal n = (n0, n1, n2): a right-handed frame about n."""
    if abs(n0) < 0.9:
        t0, t1, t2 = 0.0, -n2, n1
    else:
        t0, t1, t2 = n2, 0.0, -n0
    s = 1.0 / math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    frame[0, 0], frame[0, 1], frame[0, 2] = t0 * s, t1 * s, t2 * s
    frame[1, 0] = n1 * frame[0, 2] - n2 * frame[0, 1]
    frame[1, 1] = n2 * frame[0, 0] - n0 * frame[0, 2]
    frame[1, 2] = n0 * frame[0, 1] - n1 * frame[0, 0]
    frame[2, 0], frame[2, 1], frame[2, 2] = n0, n1, n2


@njit(cache=True)
def solve_sym(m, rhs, npar, sol):
    """Solve the small symmetric positive system m @ sol = rhs by Cholesky; False if singular."""
    # in place copy-free Cholesky on a (npar, npar) scratch held in m
    for i in range(npar):
        for j in range(i + 1):
            s = m[i, j]
            for k in range(j):
                s -= m[i, k] * m[j, k]
            if i == j:
                if s <= 1e-12 * max(1.0, abs(m[i, i])):
                    return False
                m[i, i] = math.sqrt(s)
            else:
                m[i, j] = s / m[j, j]
    solve_factored(m, rhs, npar, sol)
    return True


@njit(cache=True)
def solve_factored(m, rhs, npar, sol):
    """``sol`` = A^-1 ``rhs`` for the A whose Cholesky factor :func:`solve_sym` left in the
    lower triangle of ``m[:npar, :npar]``: another right-hand side of the same system."""
    for i in range(npar):
        s = rhs[i]
        for k in range(i):
            s -= m[i, k] * sol[k]
        sol[i] = s / m[i, i]
    for i in range(npar - 1, -1, -1):
        s = sol[i]
        for k in range(i + 1, npar):
            s -= m[k, i] * sol[k]
        sol[i] = s / m[i, i]


@njit(cache=True)
def inverse_entry(m, npar, k, y):
    """``(A^-1)[k, k]`` of the symmetric positive A whose Cholesky factor :func:`solve_sym`
    left in the lower triangle of ``m[:npar, :npar]``: ``|L^-1 e_k|^2``, by forward
    substitution (the variance factor of a least-squares fit's k-th coefficient); ``y``
    (>= npar,) is scratch."""
    y[k] = 1.0 / m[k, k]
    total = y[k] * y[k]
    for i in range(k + 1, npar):
        s = 0.0
        for j in range(k, i):
            s -= m[i, j] * y[j]
        y[i] = s / m[i, i]
        total += y[i] * y[i]
    return total


@njit(cache=True)
def ball_offset(points, k, x0, x1, x2, r2max, inv_r):
    """Offset of ``points[k]`` from (x0, x1, x2) in units of the radius, and its squared length:
    ``(inside, qx, qy, qz, r2)``. ``inside`` is False for a coincident point (the query point
    itself) and beyond the radius: the neighborhood every fit here works on."""
    qx = points[k, 0] - x0
    qy = points[k, 1] - x1
    qz = points[k, 2] - x2
    d2 = qx * qx + qy * qy + qz * qz
    return d2 > 0.0 and d2 <= r2max, qx * inv_r, qy * inv_r, qz * inv_r, d2 * inv_r * inv_r


@njit(cache=True)
def sym_eig_jacobi(a, vecs, npar):
    """Eigen-decomposition of the symmetric ``a[:npar, :npar]`` by cyclic Jacobi rotations.

    ``a`` is overwritten: its diagonal holds the eigenvalues (unsorted) and the columns of
    ``vecs[:npar, :npar]`` the unit eigenvectors in the same order. Converges quadratically to
    machine precision (the small eigenvalues of a positive semi-definite matrix to round-off
    of the large ones).
    """
    for i in range(npar):
        for j in range(npar):
            vecs[i, j] = 1.0 if i == j else 0.0
    for sweep in range(60):
        off = 0.0
        diag = 0.0
        for i in range(npar):
            diag += a[i, i] * a[i, i]
            for j in range(i + 1, npar):
                off += a[i, j] * a[i, j]
        if off <= 1e-36 * diag or off == 0.0:
            break
        for p in range(npar - 1):
            for q in range(p + 1, npar):
                apq = a[p, q]
                if apq == 0.0:
                    continue
                c, s, _ = jacobi_rotation(a[p, p], a[q, q], apq)
                for k in range(npar):          # columns p, q: a <- a J
                    akp = a[k, p]
                    akq = a[k, q]
                    a[k, p] = c * akp - s * akq
                    a[k, q] = s * akp + c * akq
                for k in range(npar):          # rows p, q: a <- J^T a
                    apk = a[p, k]
                    aqk = a[q, k]
                    a[p, k] = c * apk - s * aqk
                    a[q, k] = s * apk + c * aqk
                a[p, q] = 0.0
                a[q, p] = 0.0
                for k in range(npar):
                    vkp = vecs[k, p]
                    vkq = vecs[k, q]
                    vecs[k, p] = c * vkp - s * vkq
                    vecs[k, q] = s * vkp + c * vkq


@njit(cache=True)
def insertion_sort(a, lo, hi):
    """Sort ``a[lo:hi]`` ascending in place (stable; for the few entries of a short range)."""
    for i in range(lo + 1, hi):
        x = a[i]
        j = i - 1
        while j >= lo and a[j] > x:
            a[j + 1] = a[j]
            j -= 1
        a[j + 1] = x


@njit(cache=True)
def select_median(a, n):
    """Median of ``a[:n]`` (float64, n >= 1), the value ``np.median`` gives (the mean of the
    two middle values for even n), without allocating: ``a[:n]`` is reordered in place.

    Quickselect with median-of-three pivots and branch-free Lomuto partitions (the branches of
    Hoare's scans are mispredicted half the time: twice the time at n = 100), the values equal
    to the pivot gathered next to it (all-equal values stay linear), insertion sort below 16
    values. With NaN among the values the result is unspecified, but every access stays
    inside ``a[:n]``.
    """
    half = n >> 1
    lo = 0
    hi = n - 1
    while hi - lo > 16:
        mid = (lo + hi) >> 1
        if a[mid] < a[lo]:
            a[lo], a[mid] = a[mid], a[lo]
        if a[hi] < a[mid]:
            a[hi], a[mid] = a[mid], a[hi]
            if a[mid] < a[lo]:
                a[lo], a[mid] = a[mid], a[lo]
        pivot = a[mid]
        a[mid], a[hi] = a[hi], a[mid]
        below = lo
        for j in range(lo, hi):
            x = a[j]
            a[j] = a[below]
            a[below] = x
            below += x < pivot
        # a[lo:below] < pivot <= a[below:hi + 1]
        if half < below:
            hi = below - 1
            continue
        a[below], a[hi] = a[hi], a[below]
        equal = below + 1
        for j in range(below + 1, hi + 1):
            x = a[j]
            a[j] = a[equal]
            a[equal] = x
            equal += x == pivot
        # a[below:equal] == pivot < a[equal:hi + 1]
        if half < equal:
            lo = hi = half
        else:
            lo = equal
    insertion_sort(a, lo, hi + 1)
    upper = a[half]
    if n & 1:
        return upper
    # a[:half] holds the half smallest values: the largest of them is the lower middle one
    lower = a[0]
    for i in range(1, half):
        if a[i] > lower:
            lower = a[i]
    return (lower + upper) / 2
