"""Numpy specification of the tangent frame (:mod:`meshcurv.fit.frame`)."""

import numpy as np

__all__ = ["tangent_u"]


def tangent_u(q, n):
    """First axis tu of the tangent frame (numpy specification of
    :func:`meshcurv.fit.frame.tangent_frame`; tv = n x tu).

    The first offset ``q`` ((k, 3), neighbors relative to x, in the order of their indices) at
    least 30 degrees off the unit normal n, made tangential and unit; a fixed axis orthogonal
    to n if there is none.
    """
    for qj in q:
        t = qj - (qj @ n) * n
        if t @ t > 0.25 * (qj @ qj) and t @ t > 0:
            return t / np.linalg.norm(t)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t = a - (a @ n) * n
    return t / np.linalg.norm(t)
