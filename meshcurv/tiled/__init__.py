"""Tiled curvature estimation on Dask for clouds larger than one process: spatial tiles with a halo.

The cloud is cut into square tiles of side ``tile_size`` in x, y (columns, unbounded in z). A tile
task gets the tile's own points plus every point within the halo of the tile (the radii that the
balls, the normal field and the outlier scores of its own points reach:
:func:`meshcurv.tiled.run._halo_reach`), in input order, and estimates curvature at its own
points only (``principal_curvatures(..., query=own)``). The neighbor lists of the own points then hold the
same points as in a whole-cloud run, so a tile's values are those of the untiled run with the
same normals, bit for bit: the neighbor search bins points into cells counted from 0 in
model units (``floor(x / cell)``), not from the corner of the points present, so a point exactly on
a cell wall (z = 0 in a quantized LAS file) falls in the same cell in a tile as in the whole cloud
and every ball is listed, and summed, in the same order.

Pipeline, every stage resumable from a work folder (``OUT.meshcurv-work`` next to the output):

1. scatter: tasks read ranges of the input (chunks of ``chunk_size`` points) and write, per tile
   they touch, a piece ``pieces/t_IX_IY/cNNNNNN.npz`` (global index, xyz, own flag, normals if
   the input has them);
2. normals (``orientation="mst"`` only): one task per tile estimates PCA normals over tile + halo,
   orients them by MST propagation inside the tile and stores them (``normals/t_IX_IY.npz``); the
   driver then decides one flip per tile so that tiles agree in their overlaps (below);
3. curvature: one task per tile loads its pieces (tile + halo only) and the tile's normals,
   estimates at its own points (at the radius the halo covers: ``sparse_retry`` is off, points
   with too few neighbors are not re-estimated at larger radii, and ``coarse_fit`` is
   "circles", the MLS blend's wider supports are not taken) and writes the results per input
   chunk (``results/t_IX_IY/cNNNNNN.npz``) and then a ``done.json`` marker;
4. write: the driver streams the input once more and writes the output in input order, through
   a temporary file renamed at the end (never a partial output). The work folder is removed
   unless ``keep_work`` is set.

A rerun with the same input and parameters skips finished chunks and tiles; other parameters or a
changed input start afresh. Memory of a tile task is bounded by the points of one tile + halo
(about ``density * (tile_size + 2 * halo)^2``); the driver of :func:`annotate_tiled` holds one
chunk at a time (unless asked to return the result).

Normal orientation across tiles
-------------------------------
- given normals (NormalX.. / nx.. in the file, ``normals=`` in memory): used as they are; the
  result equals the untiled run with those normals;
- ``orientation=(x, y, z)`` viewpoint, or ``"+z"``: every normal is flipped towards that scanner
  position (or up), so tiles agree by construction and the result equals the untiled run;
- ``orientation="mst"``: each tile orients its tile + halo by minimum-spanning-tree propagation
  (:func:`meshcurv.normals.orient_mst`). A tile's halo points are its neighbors' own points, so
  each pair of adjacent tiles votes ``sum(n_A . n_B)`` over their shared points; the driver then
  flips whole tiles along a maximum spanning tree of the tile graph (strongest overlaps first)
  and finally gives each connected group of tiles the sign a whole cloud's piece would get
  (:func:`meshcurv.normals.orient.piece_signs`: outward if closed, towards +z if open), from
  the tiles' partial sums. The curvature pass runs with the
  flipped normals (refined like estimated ones), so its values equal an untiled run given the
  same normals with ``refine_normals=True``; the normals agree
  with an untiled MST run wherever the propagation itself agrees (smooth, well-sampled surfaces).

Modules: ``grid`` (TileGrid: tiles, halo, memberships), ``work`` (the work folder: manifest,
atomic npz/json, pieces and results), ``tasks`` (the scatter, normals and curvature tasks),
``orient`` (the flips that make MST normals agree across tiles), ``cluster`` (Dask: connect,
LocalCluster, running a stage's tasks), ``run`` (the two drivers).

>>> from meshcurv.tiled import annotate_tiled                                  # doctest: +SKIP
>>> annotate_tiled("big.laz", "big_curv.laz", radius=0.5, tile_size=50.0,
...                orientation=(0.0, 0.0, 1000.0))                           # doctest: +SKIP
"""

from .cluster import connect
from .grid import TileGrid
from .run import TiledReport, annotate_tiled, principal_curvatures_tiled
from .tasks import TileError

__all__ = ["TileError", "TiledReport", "TileGrid", "annotate_tiled", "principal_curvatures_tiled",
           "connect"]
