"""Neighborhoods N(x): radius-limited k-rings over mesh edges, ball queries in point clouds.

Both return CSR lists ``(indptr, indices)``: the neighbors of query ``i`` are
``indices[indptr[i]:indptr[i + 1]]``, indices into the full vertex array. Points with NaN or
infinite coordinates are never anyone's neighbor and have no neighbors themselves.

Modules: :mod:`~meshcurv.neighbors.grid` (dense and hashed grid ball search),
:mod:`~meshcurv.neighbors.kring` (edge adjacency, k-rings), :mod:`~meshcurv.neighbors.csr`
(the streaming driver both share), :mod:`~meshcurv.neighbors.radius` (default radius).
"""

from .grid import (BallGrid, ball_counts, ball_grid, ball_neighbors, crowd_thinning,
                   spatial_order)
from .kring import KringWork, edge_adjacency, kring_counts, kring_neighbors
from .radius import (MAX_BALL_FRACTION, default_radius, power_of_two_scale, scaled_for_squares,
                     typical_extent)

__all__ = ["edge_adjacency", "kring_neighbors", "kring_counts", "KringWork", "BallGrid",
           "ball_grid", "spatial_order", "ball_neighbors", "ball_counts", "crowd_thinning",
           "default_radius",
           "power_of_two_scale", "scaled_for_squares", "typical_extent", "MAX_BALL_FRACTION"]
