"""Numpy / scipy.sparse specification of the rings' noise
(:func:`meshcurv.ring_noise.ring_noise`): the second differences as sparse matrix products."""

import numpy as np
import scipy.sparse as sp

from .neighbors import edge_adjacency
from .ring_noise import _residual

__all__ = ["ring_noise"]


def ring_noise(v, f, adjacency=None):
    """:func:`meshcurv.ring_noise.ring_noise` with scipy.sparse's matrices: the products and
    sums its kernels replicate bit for bit."""
    v = np.asarray(v, dtype=np.float64)
    n = len(v)
    indptr, indices = edge_adjacency(f, n) if adjacency is None else adjacency
    counts = np.diff(indptr)
    rows = np.repeat(np.arange(n), counts)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        edge = np.bincount(rows, np.linalg.norm(v[rows] - v[indices], axis=1), n) / counts
        ring_mean = sp.csr_matrix((1.0 / counts[rows], indices, indptr), shape=(n, n))
        residual = _residual(v, f, ring_mean.__matmul__, indptr, indices, counts)
        second = sp.identity(n, format="csr") - ring_mean
        second = second @ second
        per_unit = np.asarray(second.multiply(second).sum(axis=1)).ravel()
        two_rings = ring_mean @ ring_mean
        noise = np.sqrt((two_rings @ (residual * residual)) / (two_rings @ per_unit))
    return noise, edge
