"""Tiled curvature estimation on Dask for clouds larger than one process: spatial tiles with a halo.

The cloud is cut into square tiles of side ``tile_size`` in x, y (columns, unbounded in z). A tile
task gets the tile's own points plus every point within the halo (``>= radius``, which is also the
PCA-normal radius) of the tile, in input order, and estimates curvature at its own points only
(``principal_curvatures(..., query=own)``). The neighbour lists of the own points then hold the
same points as in a whole-cloud run, so a tile's values are those of the untiled run with the
same normals, bit for bit: the neighbour search bins points into cells counted from 0 in
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
   estimates at its own points and writes the results per input chunk
   (``results/t_IX_IY/cNNNNNN.npz``) and then a ``done.json`` marker;
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
- ``orientation=(x, y, z)`` viewpoint: every normal is flipped towards that scanner position,
  so tiles agree by construction and the result equals the untiled run;
- ``orientation="mst"``: each tile orients its tile + halo by minimum-spanning-tree propagation
  (:func:`meshcurv.normals.orient_mst`). A tile's halo points are its neighbours' own points, so
  each pair of adjacent tiles votes ``sum(n_A . n_B)`` over their shared points; the driver then
  flips whole tiles along a maximum spanning tree of the tile graph (strongest overlaps first)
  and finally flips each connected group of tiles so its normals point away from its centroid on
  average, the rule ``orient_mst`` applies to a whole cloud. The curvature pass runs with the
  flipped normals (refined like estimated ones), so its values equal an untiled run given the
  same normals with ``refine_normals=True``; the normals agree
  with an untiled MST run wherever the propagation itself agrees (smooth, well-sampled surfaces).

>>> from meshcurv.tiled import annotate_tiled                                  # doctest: +SKIP
>>> annotate_tiled("big.laz", "big_curv.laz", radius=0.5, tile_size=50.0,
...                orientation=(0.0, 0.0, 1000.0))                           # doctest: +SKIP
"""

import contextlib
import json
import logging
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np
from tqdm.auto import tqdm

from .io import las
from .io import atomic_write, first_line

__all__ = ["TileError", "TiledReport", "TileGrid", "annotate_tiled", "principal_curvatures_tiled"]

# Relative safety margin on the halo: a neighbour at exactly ``radius`` must land in the halo
# even after the rounding of (x - origin) / tile_size.
_HALO_MARGIN = 1e-6

# Keywords of principal_curvatures that the tiled run sets itself.
_RESERVED = ("vertices", "faces", "normals", "radius", "orientation", "query", "progress")


class TileError(RuntimeError):
    """A tile (or an input chunk) that failed on a worker; the message names the tile and file."""


@dataclass(frozen=True)
class TileGrid:
    """Square tiles of side ``tile_size`` in x, y starting at ``origin``; halo in model units.

    Tile ``(ix, iy)`` owns the points with ``floor((x - ox) / tile_size) == ix`` (same for y) and
    sees every point whose x, y lie within ``halo`` of its square.
    """

    origin: tuple
    tile_size: float
    halo: float

    @classmethod
    def for_radius(cls, origin, tile_size, radius):
        """Grid whose halo covers ``radius`` with a margin against rounding.

        Raises ValueError for tiles narrower than the radius: their work would be mostly halo,
        and every point would belong to many tiles.
        """
        if not tile_size >= radius:
            raise ValueError(f"tile_size ({tile_size}) must be at least the radius ({radius})")
        # the absolute term covers the rounding of (x - origin) / tile_size, ~1e-16 tile sizes
        halo = radius * (1 + _HALO_MARGIN) + 1e-9 * tile_size
        return cls(origin=(float(origin[0]), float(origin[1])), tile_size=float(tile_size),
                   halo=float(halo))

    def own_keys(self, xyz):
        """(k, 2) int64 tile index of each point's own tile; ``xyz`` is (k, 3) float64."""
        o = np.asarray(self.origin, dtype=np.float64)
        return np.floor((xyz[:, :2] - o) / self.tile_size).astype(np.int64)

    def memberships(self, xyz):
        """All (point, tile) pairs of tile + halo membership of the finite points ``xyz``.

        Returns
        -------
        point : (p,) int64 row into ``xyz``; keys : (p, 2) int64 tiles; own : (p,) bool
        """
        o = np.asarray(self.origin, dtype=np.float64)
        lo = np.floor((xyz[:, :2] - self.halo - o) / self.tile_size).astype(np.int64)
        hi = np.floor((xyz[:, :2] + self.halo - o) / self.tile_size).astype(np.int64)
        own = self.own_keys(xyz)
        lo = np.minimum(lo, own)
        hi = np.maximum(hi, own)
        span = int((hi - lo).max(initial=0)) + 1
        pts, keys = [], []
        for dx in range(span):
            for dy in range(span):
                k = lo + (dx, dy)
                ok = np.flatnonzero((k <= hi).all(axis=1))
                pts.append(ok)
                keys.append(k[ok])
        point = np.concatenate(pts)
        keys = np.concatenate(keys)
        return point, keys, (keys == own[point]).all(axis=1)

    def tile_square(self, name):
        """Lower x, y corner (2,) of the tile called ``name`` ("t_IX_IY")."""
        key = np.array(name.split("_")[1:], dtype=np.int64)
        return np.asarray(self.origin, dtype=np.float64) + key * self.tile_size


@dataclass
class TiledReport:
    """What a tiled run did.

    Attributes
    ----------
    n_points : int; n_tiles : int; radius, tile_size, halo : float, model units
    computed, skipped : lists of tile names (``"t_IX_IY"``) computed now / found finished
    tile_stats : dict tile name -> {"n_own", "n_total": points owned / in tile + halo,
        "seconds": curvature task time, "peak_rss_bytes": peak resident memory of the worker
        process during the task, "peak_traced_bytes" (with ``measure_memory``): peak of the
        Python/numpy allocations of the task, and with ``orientation="mst"`` the same for the
        normal pass prefixed ``normals_``}
    flips : dict tile name -> +1/-1 applied to the tile's MST normals (``orientation="mst"``)
    stage_seconds : dict stage -> wall time: "start" (cluster), "scatter", "normals", "tiles",
        "write"
    seconds : wall time of the whole run; out_path : str or None
    """

    n_points: int
    n_tiles: int
    radius: float
    tile_size: float
    halo: float
    computed: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    tile_stats: dict = field(default_factory=dict)
    flips: dict = field(default_factory=dict)
    stage_seconds: dict = field(default_factory=dict)
    seconds: float = 0.0
    out_path: str = None


# ----------------------------------------------------------------------------- small helpers

def _tile_name(key):
    return f"t_{int(key[0])}_{int(key[1])}"


def _atomic_savez(path, **arrays):
    def write(tmp):
        with open(tmp, "wb") as fh:     # a file object: given a name, savez appends ".npz"
            np.savez(fh, **arrays)
    atomic_write(path, write)


def _atomic_json(path, obj):
    def write(tmp):
        with open(tmp, "w") as fh:
            json.dump(obj, fh)
    atomic_write(path, write)


def _read_json(path):
    with open(path) as fh:
        return json.load(fh)


def _prepare_work(work, manifest):
    """Reuse ``work`` if it was made for the same input and parameters, else start it afresh."""
    mpath = os.path.join(work, "manifest.json")
    if os.path.exists(mpath):
        try:
            same = _read_json(mpath) == json.loads(json.dumps(manifest))
        except (OSError, ValueError):
            same = False
        if not same:
            shutil.rmtree(work)
    for sub in ("pieces", "normals", "results", "chunks"):
        os.makedirs(os.path.join(work, sub), exist_ok=True)
    if not os.path.exists(mpath):
        _atomic_json(mpath, manifest)


class _TaskMemory:
    """Peak memory of the task running in this process (one task per worker process).

    ``peak_rss_bytes``: the kernel's high-water mark of resident memory (Linux ``VmHWM``, reset at
    the start through ``/proc/self/clear_refs``), which counts numba and library allocations too;
    elsewhere the process's lifetime peak. ``peak_traced_bytes``: peak of the allocations that
    Python and numpy report to ``tracemalloc`` (only when ``trace``).
    """

    def __init__(self, trace=False):
        self.trace = trace

    def __enter__(self):
        import tracemalloc

        try:
            with open("/proc/self/clear_refs", "w") as fh:
                fh.write("5")
        except OSError:
            pass
        if self.trace:
            tracemalloc.start()
        return self

    def stats(self):
        import resource
        import tracemalloc

        out = {}
        try:
            with open("/proc/self/status") as fh:
                hwm = [ln for ln in fh if ln.startswith("VmHWM:")]
            out["peak_rss_bytes"] = int(hwm[0].split()[1]) * 1024
        except (OSError, IndexError, ValueError):
            out["peak_rss_bytes"] = int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024
        if self.trace and tracemalloc.is_tracing():
            out["peak_traced_bytes"] = int(tracemalloc.get_traced_memory()[1])
        return out

    def __exit__(self, *exc):
        import tracemalloc

        if self.trace and tracemalloc.is_tracing():
            tracemalloc.stop()
        return False


def _prepare_worker(threads):
    """Numba threads for this task; the first time in a process, load the compiled kernels
    (from numba's cache) on a tiny cloud, so that a tile task's memory is the tile's alone."""
    import numba

    from .api import estimate_normals, principal_curvatures

    if threads:
        numba.set_num_threads(min(int(threads), numba.config.NUMBA_NUM_THREADS))
    global _WORKER_READY
    if not _WORKER_READY:
        g = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0), indexing="ij"), -1).reshape(-1, 2)
        pts = np.column_stack([g, 0.1 * (g ** 2).sum(axis=1)])
        estimate_normals(pts, 1.5)
        principal_curvatures(pts, radius=1.5, orientation=(1.0, 1.0, 10.0), query=[5])
        _WORKER_READY = True


_WORKER_READY = False


# ----------------------------------------------------------------------------- stage 1: scatter

def _scatter(xyz, normals, first, chunk_id, grid, work):
    """Write this chunk's points into the pieces of every tile whose tile + halo holds them.

    xyz : (k, 3) float64 points ``first .. first + k - 1``; normals : (k, 3) float64 or None.
    Returns ``{tile name: [n_own, n_total]}`` (also stored as ``chunks/cNNNNNN.json``).
    """
    finite = np.flatnonzero(np.isfinite(xyz).all(axis=1))  # non-finite points: no tile, NaN out
    point, keys, own = grid.memberships(xyz[finite])
    point = finite[point]
    # group by tile, keeping input order inside a tile (stable sort)
    order = np.lexsort((point, keys[:, 1], keys[:, 0]))
    point, keys, own = point[order], keys[order], own[order]
    starts = np.flatnonzero(np.r_[True, (np.diff(keys, axis=0) != 0).any(axis=1)])
    ends = np.r_[starts[1:], len(point)]
    summary = {}
    for a, b in (zip(starts, ends) if len(point) else ()):
        name = _tile_name(keys[a])
        folder = os.path.join(work, "pieces", name)
        os.makedirs(folder, exist_ok=True)
        rows = point[a:b]
        arrays = dict(idx=rows + first, xyz=xyz[rows], own=own[a:b])
        if normals is not None:
            arrays["normals"] = normals[rows]
        _atomic_savez(os.path.join(folder, f"c{chunk_id:06d}.npz"), **arrays)
        summary[name] = [int(own[a:b].sum()), int(b - a)]
    _atomic_json(os.path.join(work, "chunks", f"c{chunk_id:06d}.json"), summary)
    return summary


def _scatter_file_task(in_path, first, stop, chunk_id, grid, work):
    """Dask task: read points ``first .. stop - 1`` of a LAS/LAZ file and scatter them."""
    try:
        for _, xyz, nv in las.iter_las_chunks(in_path, stop - first, start=first, stop=stop):
            return _scatter(xyz, nv, first, chunk_id, grid, work)
        return _scatter(np.zeros((0, 3)), None, first, chunk_id, grid, work)
    except las.LasReadError:
        raise
    except Exception as e:
        raise TileError(f"{in_path}: splitting points {first}..{stop - 1} into tiles failed "
                        f"({type(e).__name__}: {e})") from e


def _load_tile(work, name, chunk_ids):
    """A tile + halo from its pieces, in input order.

    Returns
    -------
    idx : (m,) int64 global point index; xyz : (m, 3) float64; own : (m,) bool;
    normals : (m, 3) float64 or None (given in the input); chunk_of : (m,) int64 input chunk
    """
    folder = os.path.join(work, "pieces", name)
    parts = []
    for c in chunk_ids:
        with np.load(os.path.join(folder, f"c{c:06d}.npz")) as z:
            parts.append({k: z[k] for k in z.files})
    idx = np.concatenate([p["idx"] for p in parts])
    xyz = np.concatenate([p["xyz"] for p in parts])
    own = np.concatenate([p["own"] for p in parts])
    normals = np.concatenate([p["normals"] for p in parts]) if "normals" in parts[0] else None
    chunk_of = np.repeat(np.asarray(chunk_ids, dtype=np.int64), [len(p["idx"]) for p in parts])
    return idx, xyz, own, normals, chunk_of


# ----------------------------------------------------------------------------- stage 2: normals

def _normals_task(name, work, chunk_ids, radius, grid, in_path, threads=None,
                  measure_memory=False):
    """Dask task: MST-oriented normals of one tile; writes ``normals/<tile>.npz`` and ``.json``.

    The npz holds ``own_normals`` (n_own, 3) in tile order and the overlap data for the vote
    between tiles: ``band_idx, band_normals`` (own points within the halo width of the tile's
    border) and ``halo_idx, halo_normals, halo_owner`` (the halo points, their tile).
    """
    from .api import estimate_normals

    t0 = time.perf_counter()
    try:
        _prepare_worker(threads)
        with _TaskMemory(measure_memory) as mem:
            idx, xyz, own, _, _ = _load_tile(work, name, chunk_ids)
            nv = estimate_normals(xyz, radius)
            rel = xyz[:, :2] - grid.tile_square(name)
            border = own & ((rel < grid.halo) | (rel > grid.tile_size - grid.halo)).any(axis=1)
            _atomic_savez(os.path.join(work, "normals", f"{name}.npz"), own_normals=nv[own],
                          band_idx=idx[border], band_normals=nv[border], halo_idx=idx[~own],
                          halo_normals=nv[~own], halo_owner=grid.own_keys(xyz[~own]))
            # partial sums for the outward decision of a group of tiles:
            # sum p.n, sum n, sum p, count
            ok = own & np.isfinite(nv).all(axis=1)
            p, n = xyz[ok], nv[ok]
            stats = {"orient": [float(np.einsum("ij,ij->", p, n)), *n.sum(axis=0).tolist(),
                                *p.sum(axis=0).tolist(), int(ok.sum())]}
            stats.update(mem.stats())
        stats["seconds"] = time.perf_counter() - t0
        _atomic_json(os.path.join(work, "normals", f"{name}.json"), stats)
        return stats
    except Exception as e:
        raise TileError(f"tile {name} of {in_path}: normal estimation failed: "
                        f"{type(e).__name__}: {e}") from e


def _tile_flips(work, names):
    """+1/-1 per tile so that tiles agree in their overlaps and each group points outward.

    Reads the overlap data of one tile and its neighbours' border bands at a time, so the
    driver's memory is bounded by a few tiles' borders.
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import (breadth_first_order, connected_components,
                                      minimum_spanning_tree)

    if not names:
        return {}
    pos = {n: i for i, n in enumerate(names)}

    def npz(name, *keys):
        with np.load(os.path.join(work, "normals", f"{name}.npz")) as z:
            return [z[k] for k in keys]

    rows, cols, votes = [], [], []
    for a in names:
        h_idx, h_nv, owner = npz(a, "halo_idx", "halo_normals", "halo_owner")
        for key in np.unique(owner, axis=0):
            b = _tile_name(key)
            if b not in pos:
                continue
            sel = (owner == key).all(axis=1)
            b_idx, b_nv = npz(b, "band_idx", "band_normals")
            _, ia, ib = np.intersect1d(h_idx[sel], b_idx, assume_unique=True, return_indices=True)
            vote = float(np.nansum(np.einsum("ij,ij->i", h_nv[sel][ia], b_nv[ib])))
            if vote != 0.0:
                rows.append(pos[a])
                cols.append(pos[b])
                votes.append(vote)
    n = len(names)
    vote_m = coo_matrix((np.asarray(votes, dtype=np.float64), (rows, cols)), shape=(n, n)).tocsr()
    vote_m = vote_m + vote_m.T
    # the spanning tree keeps the strongest agreements or disagreements (smallest 1 / |vote|)
    strength = vote_m.copy()
    strength.data = 1.0 / (np.abs(strength.data) + 1e-12)
    tree = minimum_spanning_tree(strength)
    tree = tree + tree.T
    n_comp, labels = connected_components(tree, directed=False)
    flips = np.ones(n)
    done = np.zeros(n, dtype=bool)
    for root in range(n):
        if done[root]:
            continue
        order, pred = breadth_first_order(tree, root, directed=False, return_predecessors=True)
        for i in order:
            if pred[i] >= 0:
                flips[i] = flips[pred[i]] * np.sign(vote_m[i, pred[i]])
            done[i] = True
    # outward decision per group of tiles: sum over points of (p - centroid) . n
    st = np.array([_read_json(os.path.join(work, "normals", f"{nm}.json"))["orient"]
                   for nm in names], dtype=np.float64).reshape(n, 8)
    for c in range(n_comp):
        g = labels == c
        cnt = st[g, 7].sum()
        if cnt == 0:
            continue
        centroid = st[g, 4:7].sum(axis=0) / cnt
        score = np.sum(flips[g] * (st[g, 0] - st[g, 1:4] @ centroid))
        if score < 0:
            flips[g] *= -1.0
    return {nm: int(f) for nm, f in zip(names, flips)}


# ----------------------------------------------------------------------------- stage 3: curvature

def _result_rows(res):
    """The per-row arrays of a CurvatureResult, ``{name: (m, ...) array}``."""
    m = len(res)
    return {k: v for k, v in vars(res).items() if isinstance(v, np.ndarray) and len(v) == m}


def _curvature_task(name, work, chunk_ids, radius, orientation, options, in_path, flip=None,
                    threads=None, measure_memory=False):
    """Dask task: estimate one tile; writes results per input chunk and ``done.json``.

    With ``flip`` (``orientation="mst"``) the tile's stored MST normals times ``flip`` are used,
    refined as the estimator refines its own estimated normals (``refine_normals=True`` unless
    the options say otherwise).
    """
    from .api import principal_curvatures

    t0 = time.perf_counter()
    try:
        _prepare_worker(threads)
        with _TaskMemory(measure_memory) as mem:
            idx, xyz, own, normals, chunk_of = _load_tile(work, name, chunk_ids)
            if flip is not None:
                with np.load(os.path.join(work, "normals", f"{name}.npz")) as z:
                    normals = np.full(xyz.shape, np.nan)
                    normals[own] = z["own_normals"] * float(flip)
                # these normals were estimated: treat them as the estimator treats its own
                if options.get("refine_normals") is None:
                    options = dict(options, refine_normals=True)
            res = principal_curvatures(xyz, normals=normals, radius=radius,
                                       orientation=orientation, query=np.flatnonzero(own),
                                       **options)
            rows = _result_rows(res)
            out = os.path.join(work, "results", name)
            os.makedirs(out, exist_ok=True)
            own_idx, own_chunk = idx[own], chunk_of[own]
            for c in np.unique(own_chunk):
                sel = own_chunk == c
                _atomic_savez(os.path.join(out, f"c{int(c):06d}.npz"), idx=own_idx[sel],
                              **{k: v[sel] for k, v in rows.items()})
            stats = {"n_own": int(own.sum()), "n_total": int(len(own))}
            stats.update(mem.stats())
        stats["seconds"] = time.perf_counter() - t0
        _atomic_json(os.path.join(out, "done.json"), stats)
        return stats
    except Exception as e:
        raise TileError(f"tile {name} of {in_path} failed: {type(e).__name__}: {e}") from e


# ----------------------------------------------------------------------------- stage 4: assembly

def _gather(work, tiles, chunk_id, first, count):
    """Result arrays of points ``first .. first + count - 1`` from the tiles that own them; points
    no tile owns (non-finite coordinates) keep NaN / 0 / False."""
    out = {}
    for name in tiles:
        with np.load(os.path.join(work, "results", name, f"c{chunk_id:06d}.npz")) as z:
            r = {k: z[k] for k in z.files}
        rows = r.pop("idx") - first
        for k, a in r.items():
            if k not in out:
                fill = np.nan if a.dtype.kind == "f" else 0
                out[k] = np.full((count,) + a.shape[1:], fill, dtype=a.dtype)
            out[k][rows] = a
    if not out:  # a chunk of non-finite points only
        out = {k: np.full(count, np.nan) for k in ("k1", "k2", "residual", "noise")}
        out.update({k: np.full((count, 3), np.nan) for k in ("d1", "d2", "normals")})
        out.update(n_neighbors=np.zeros(count, np.int32), n_samples=np.zeros(count, np.int32),
                   valid=np.zeros(count, bool))
    return out


def _as_result(arrays, radius):
    from .result import CurvatureResult

    return CurvatureResult(radius=float(radius), **arrays)


# ----------------------------------------------------------------------------- the driver

@contextlib.contextmanager
def connect(scheduler, timeout="20s"):
    """A ``distributed.Client`` for ``scheduler``: an address (connected here, waiting at most
    ``timeout``, and closed on exit) or an existing Client (used as is).

    Raises OSError "cannot connect to the Dask scheduler <address>: <reason>" (one line).
    """
    if not isinstance(scheduler, str):
        yield scheduler
        return
    from distributed import Client

    try:
        client = Client(scheduler, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as exc:
        raise OSError(f"cannot connect to the Dask scheduler {scheduler}: "
                      f"{first_line(exc)}") from None
    try:
        yield client
    finally:
        client.close()


@contextlib.contextmanager
def _dask_client(scheduler, n_workers, threads_per_task=None):
    """(client, numba threads per task): the given Client, one connected to an address, or a
    LocalCluster of ``n_workers`` one-thread processes, closed on exit.

    Threads per task: ``threads_per_task`` if given; for the LocalCluster the cores shared out
    among its workers; else None (numba's default, all cores of the worker's machine).
    """
    from distributed import Client, LocalCluster

    if threads_per_task is not None and int(threads_per_task) < 1:
        raise ValueError(f"threads_per_task must be at least 1, got {threads_per_task}")
    if scheduler is not None:
        with connect(scheduler) as client:
            yield client, threads_per_task
        return
    n_workers = int(n_workers or min(os.cpu_count() or 1, 8))
    cluster = None
    try:
        with _workers_ignore_sigint():
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                                   dashboard_address=None)
        with Client(cluster) as client:
            client.run(_quiet_worker)
            yield client, threads_per_task or max(1, (os.cpu_count() or 1) // n_workers)
    except BaseException:
        # interrupted or failed: the caller reports it in one line; the scheduler and nannies
        # in this process would add warnings about the workers they stop
        _set_distributed_log_level(logging.CRITICAL)
        raise
    finally:
        if cluster is not None:
            try:
                cluster.close()
            finally:
                _set_distributed_log_level(None)


@contextlib.contextmanager
def _workers_ignore_sigint():
    """Ignore SIGINT in this process while a LocalCluster starts its worker processes.

    The workers inherit the ignored signal, so a Ctrl-C in the terminal (sent to the whole
    process group) reaches only the driver, which closes the cluster and reports one line,
    instead of every worker printing a KeyboardInterrupt traceback. A Ctrl-C during these
    seconds of start-up is lost; workers restarted later get it again (see _quiet_worker).
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


def _quiet_worker():
    """Run in each worker process of our LocalCluster: the driver reports a failed task in one
    line (tile and reason), so the worker's own log of it (a multi-line "Compute Failed" block)
    and its warnings while the cluster shuts down are not printed. A Ctrl-C is for the driver."""
    import signal
    import threading

    for name in ("distributed", "distributed.worker"):
        logging.getLogger(name).setLevel(logging.CRITICAL)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)


_SAVED_LOG_LEVELS = {}


def _set_distributed_log_level(level):
    """Set the level of distributed's loggers in this process; None restores them."""
    names = ("distributed", "distributed.scheduler", "distributed.nanny", "distributed.worker",
             "distributed.core", "distributed.client", "distributed.deploy.spec")
    for name in names:
        logger = logging.getLogger(name)
        if level is None:
            if name in _SAVED_LOG_LEVELS:
                logger.setLevel(_SAVED_LOG_LEVELS.pop(name))
        else:
            _SAVED_LOG_LEVELS.setdefault(name, logger.level)
            logger.setLevel(level)


def _run(client, jobs, desc, unit, in_path, progress):
    """Submit ``jobs`` ({name: (func, args, kwargs)}) and wait for all.

    The first failure cancels the rest and is raised naming its tile or chunk and the file.
    Returns {name: task result}.
    """
    from distributed import as_completed

    token = f"{os.getpid()}-{time.time_ns()}"
    futures = {client.submit(func, *args, key=f"meshcurv-{desc}-{name}-{token}", pure=False,
                             **kwargs): name
               for name, (func, args, kwargs) in jobs.items()}
    results = {}
    bar = tqdm(total=len(futures), desc=desc, unit=unit, disable=not progress)
    try:
        for fut in as_completed(futures):
            name = futures[fut]
            try:
                results[name] = fut.result()
            except (TileError, las.LasReadError):
                raise
            except Exception as e:  # KilledWorker, CommClosedError, ...: the worker is gone
                raise TileError(f"{unit} {name} of {in_path}: {desc} task failed "
                                f"({type(e).__name__}: {e})") from e
            bar.update(1)
    except BaseException:
        client.cancel(list(futures))
        raise
    finally:
        bar.close()
    return results


def _options_manifest(radius, grid, orientation, options, chunk_size):
    return {"radius": radius, "tile_size": grid.tile_size, "halo": grid.halo,
            "origin": list(grid.origin), "chunk_size": chunk_size,
            "orientation": orientation if isinstance(orientation, str) else list(orientation),
            "options": {k: options[k] for k in sorted(options)}}


def _check_options(orientation, options):
    """Reject estimator options the tiled run cannot take, before any work starts; returns
    ``orientation`` as "mst" or a tuple (sent to every task)."""
    from .options import check_options

    reserved = sorted(set(options) & set(_RESERVED))
    if reserved:
        raise ValueError(f"the tiled run sets {reserved} itself; pass them as its own arguments")
    if options.get("neighborhood", "ball") not in ("auto", "ball"):
        raise ValueError("tiled runs are for point clouds: neighborhood must be 'ball'")
    if options.get("normal_estimation", "pca") not in ("auto", "pca"):
        raise ValueError("tiled runs are for point clouds: normal_estimation must be 'pca'")
    orientation = check_options(orientation=orientation, **options)
    return orientation if isinstance(orientation, str) else tuple(map(float, orientation))


def _process(client, threads, work, grid, radius, orientation, options, chunk_jobs, in_path,
             progress, measure_memory, report, has_normals):
    """Stages 1-3 on a connected client. Returns {chunk id: [tiles owning points of it]}."""
    summaries = {int(f[1:7]): _read_json(os.path.join(work, "chunks", f))
                 for f in os.listdir(os.path.join(work, "chunks")) if f.endswith(".json")}
    todo = {f"c{cid:06d}": job for cid, job in chunk_jobs.items() if cid not in summaries}
    t0 = time.perf_counter()
    if todo:
        done = _run(client, todo, "scatter", "chunk", in_path, progress)
        summaries.update({int(k[1:]): v for k, v in done.items()})
    report.stage_seconds["scatter"] = report.stage_seconds.get("scatter", 0.0) + (
        time.perf_counter() - t0)
    tiles = {}
    for cid in sorted(summaries):
        for name in summaries[cid]:
            tiles.setdefault(name, []).append(cid)
    names = sorted(n for n, cids in tiles.items() if any(summaries[c][n][0] for c in cids))
    report.n_tiles = len(names)
    task_kw = {"threads": threads, "measure_memory": measure_memory}

    flips = {}
    t0 = time.perf_counter()
    if isinstance(orientation, str) and not has_normals:
        normal_stats = {}
        jobs = {}
        for name in names:
            marker = os.path.join(work, "normals", f"{name}.json")
            if os.path.exists(marker):
                normal_stats[name] = _read_json(marker)
            else:
                jobs[name] = (_normals_task, (name, work, tiles[name], radius, grid, in_path),
                              task_kw)
        normal_stats.update(_run(client, jobs, "normals", "tile", in_path, progress))
        flips = _tile_flips(work, names)
        report.flips = flips
        report.stage_seconds["normals"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    jobs = {}
    for name in names:
        marker = os.path.join(work, "results", name, "done.json")
        if os.path.exists(marker):
            report.skipped.append(name)
            report.tile_stats[name] = _read_json(marker)
        else:
            jobs[name] = (_curvature_task, (name, work, tiles[name], radius, orientation, options,
                                            in_path), dict(task_kw, flip=flips.get(name)))
    report.computed = sorted(jobs)
    report.tile_stats.update(_run(client, jobs, "tiles", "tile", in_path, progress))
    report.stage_seconds["tiles"] = time.perf_counter() - t0
    if flips:
        for name in names:
            report.tile_stats[name].update(
                {f"normals_{k}": v for k, v in normal_stats[name].items() if k != "orient"})
    return {cid: [n for n, (n_own, _) in s.items() if n_own] for cid, s in summaries.items()}


def _default_tile_size(n_points, extent, radius, target=1_000_000):
    """Side (model units) of square tiles holding about ``target`` points of a uniform cloud,
    and at least 4 radii (a cloud flat in x or y counts as one radius wide)."""
    area = max(float(extent[0]), radius) * max(float(extent[1]), radius)
    return max(float(np.sqrt(area * target / max(n_points, 1))), 4.0 * radius)


def annotate_tiled(in_path, out_path, radius=None, tile_size=None, *, orientation="mst",
                   scheduler=None, n_workers=None, chunk_size=500_000, work_dir=None,
                   keep_work=False, progress=True, float_type="f8", measure_memory=False,
                   return_result=False, threads_per_task=None, **options):
    """Annotate a LAS/LAZ file with curvature fields, tile by tile on Dask; output in input order.

    Parameters
    ----------
    in_path, out_path : str, .las or .laz (``out_path`` must differ from ``in_path``; .laz is
        compressed with lazrs). Both, and ``work_dir``, must be visible to every worker (on
        several machines: a shared file system).
    radius : float, model units. Default: :func:`meshcurv.default_radius` of the first chunk.
    tile_size : float, model units, side of the square x, y tiles. Default: about 10^6 points
        per tile from the header's extent.
    orientation : "mst" or (3,) viewpoint
        Used when the file has no normals. A viewpoint (scanner position) reproduces the untiled
        run exactly; "mst" orients per tile and makes tiles agree (see the module docstring).
    scheduler : None, str or distributed.Client
        None starts a LocalCluster (``n_workers`` processes, one thread each) and closes it at
        the end; a string is the address of an existing scheduler ("tcp://host:8786").
    n_workers : int, workers of the LocalCluster (default: the number of cores, at most 8)
    chunk_size : int, points per read/scatter/write chunk (bounds the driver's memory)
    work_dir : str, default ``out_path + ".meshcurv-work"``; keeps finished tiles for a rerun
    keep_work : bool, keep the work folder after success
    progress : bool, progress bars over chunks and tiles
    float_type : "f8" or "f4", type of the written float fields
    measure_memory : bool, also trace each tile task's peak Python/numpy allocations
    return_result : bool, also return the CurvatureResult (one row per point; needs memory for
        the whole cloud, meant for checks on small files)
    threads_per_task : int, numba threads of a tile task. Default: the cores shared out among
        the LocalCluster's workers; with ``scheduler`` given, numba's default (all cores of
        the worker's machine) - set it to cores / worker threads on a shared machine
    **options : passed to :func:`meshcurv.principal_curvatures` (n_directions, slab, ...)

    Returns
    -------
    TiledReport (and the CurvatureResult with ``return_result``)

    Raises
    ------
    ValueError
        Bad arguments, or an input that already has curvature dimensions (an annotated file);
        raised before any work.
    LasReadError
        Unreadable or truncated input; names the file and the points. No output is written.
    TileError
        A tile task failed or its worker died; names the tile and the file. Finished tiles stay
        in the work folder and a rerun resumes from them. No output is written.

    Examples
    --------
    >>> annotate_tiled("scan.laz", "scan_curv.laz", radius=0.3, tile_size=25.0,
    ...                orientation=(0, 0, 500))                      # doctest: +SKIP
    """
    t0 = time.perf_counter()
    in_path, out_path = os.path.abspath(in_path), os.path.abspath(out_path)
    las.check_paths(in_path, out_path)
    orientation = _check_options(orientation, options)
    chunk_size = int(chunk_size)
    if chunk_size < 1:
        raise ValueError(f"chunk_size must be a positive number of points, got {chunk_size}")
    # an annotated input is refused now, not after the whole computation
    names = las.check_annotatable(in_path)
    with las.open_las(in_path) as reader:
        header = reader.header
        n_points = int(header.point_count)
        mins, maxs = np.asarray(header.mins, float), np.asarray(header.maxs, float)
        has_normals = las.normal_dims(header.point_format) is not None
    if isinstance(radius, str):
        raise ValueError(f"tiled runs need a radius in model units or None, got {radius!r} "
                         "(a data-driven radius needs the whole cloud)")
    if radius is None:
        from .neighbors import default_radius

        first = next(las.iter_las_chunks(in_path, chunk_size, stop=chunk_size), None)
        radius = default_radius(first[1]) if first is not None else float("nan")
    radius = float(radius)
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive number of model units, got {radius}")
    if tile_size is None:
        tile_size = _default_tile_size(n_points, maxs[:2] - mins[:2], radius)
    tile_size = float(tile_size)
    if not (np.isfinite(tile_size) and tile_size > 0):
        raise ValueError(f"tile_size must be a positive number of model units, got {tile_size}")
    grid = TileGrid.for_radius(mins[:2], tile_size, radius)
    work = os.path.abspath(work_dir or out_path + ".meshcurv-work")
    st = os.stat(in_path)
    manifest = {"input": in_path, "size": st.st_size, "mtime_ns": st.st_mtime_ns,
                **_options_manifest(radius, grid, orientation, options, chunk_size)}
    report = TiledReport(n_points=n_points, n_tiles=0, radius=radius, tile_size=tile_size,
                         halo=grid.halo, out_path=out_path)
    chunk_jobs = {c: (_scatter_file_task, (in_path, s, min(s + chunk_size, n_points), c, grid,
                                           work), {})
                  for c, s in enumerate(range(0, n_points, chunk_size))}
    t_start = time.perf_counter()
    with _dask_client(scheduler, n_workers, threads_per_task) as (client, threads):
        # connected before the work folder exists: an unreachable scheduler leaves nothing
        report.stage_seconds["start"] = time.perf_counter() - t_start
        _prepare_work(work, manifest)
        try:
            own_tiles = _process(client, threads, work, grid, radius, orientation, options,
                                 chunk_jobs, in_path, progress, measure_memory, report,
                                 has_normals)
        except las.LasReadError:
            # an unreadable input leaves nothing worth resuming: a fixed file starts afresh
            shutil.rmtree(work, ignore_errors=True)
            raise
    write_normals = not has_normals
    kept = []

    def fields_for(first, count):
        chunk_id = first // chunk_size
        res = _as_result(_gather(work, own_tiles.get(chunk_id, []), chunk_id, first, count),
                         radius)
        if return_result:
            kept.append(res)
        return las.result_fields(res, normals=write_normals, float_type=float_type)

    t_write = time.perf_counter()
    las.annotate_las(in_path, out_path, fields_for, names, chunk_size=chunk_size,
                     float_type=float_type)
    report.stage_seconds["write"] = time.perf_counter() - t_write
    if not keep_work:
        shutil.rmtree(work, ignore_errors=True)
    report.seconds = time.perf_counter() - t0
    if not return_result:
        return report
    return report, _concat_results(kept, radius)


def _concat_results(parts, radius):
    rows = [_result_rows(p) for p in parts]
    if not rows:
        return _as_result(_gather("", [], 0, 0, 0), radius)
    return _as_result({k: np.concatenate([r[k] for r in rows]) for k in rows[0]}, radius)


def principal_curvatures_tiled(vertices, radius, tile_size, normals=None, *, orientation="mst",
                               scheduler=None, n_workers=None, chunk_size=500_000,
                               work_dir=None, progress=False, measure_memory=False,
                               return_report=False, threads_per_task=None, **options):
    """:func:`meshcurv.principal_curvatures` of an in-memory point cloud, computed in tiles on Dask.

    The driver cuts the cloud into tile + halo pieces in a work folder (which workers must see);
    each task loads one tile + halo only. With given normals or a viewpoint ``orientation`` the
    result equals ``principal_curvatures(vertices, normals=..., radius=radius, orientation=...)``
    bit for bit (module docstring).

    Parameters
    ----------
    vertices : (n, 3) float, model units; normals : (n, 3) float, optional
    radius : float, model units; tile_size : float, model units (x, y side of a tile)
    orientation, scheduler, n_workers, progress, measure_memory, threads_per_task, options :
        as in :func:`annotate_tiled`
    work_dir : str, optional; default a temporary folder, removed afterwards
    return_report : bool, also return the :class:`TiledReport`

    Returns
    -------
    CurvatureResult with one row per vertex, input order (and the report if asked)

    Examples
    --------
    >>> res = principal_curvatures_tiled(pts, radius=0.5, tile_size=20.0,
    ...                                  orientation=(0, 0, 100))          # doctest: +SKIP
    """
    t0 = time.perf_counter()
    v = np.ascontiguousarray(np.asarray(vertices, dtype=np.float64))
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be an (n, 3) array, got shape {v.shape}")
    nv = None
    if normals is not None:
        nv = np.asarray(normals, dtype=np.float64)
        if nv.shape != v.shape:
            raise ValueError(f"normals must have the shape of vertices {v.shape}, got {nv.shape}")
    orientation = _check_options(orientation, options)
    if isinstance(radius, str):
        raise ValueError(f"tiled runs need a radius in model units, got {radius!r}")
    radius, tile_size, chunk_size = float(radius), float(tile_size), int(chunk_size)
    if not (np.isfinite(radius) and radius > 0 and np.isfinite(tile_size) and tile_size > 0):
        raise ValueError("radius and tile_size must be positive numbers of model units")
    finite = np.isfinite(v).all(axis=1)
    origin = v[finite, :2].min(axis=0) if finite.any() else np.zeros(2)
    grid = TileGrid.for_radius(origin, tile_size, radius)
    n = len(v)
    report = TiledReport(n_points=n, n_tiles=0, radius=radius, tile_size=tile_size, halo=grid.halo)
    with contextlib.ExitStack() as stack:
        # connected before the work folder exists: an unreachable scheduler leaves nothing
        t_start = time.perf_counter()
        client, threads = stack.enter_context(_dask_client(scheduler, n_workers,
                                                           threads_per_task))
        report.stage_seconds["start"] = time.perf_counter() - t_start
        work = work_dir or stack.enter_context(tempfile.TemporaryDirectory(prefix="meshcurv-"))
        # an array cannot be recognised again: always start afresh
        _prepare_work(work, {"input": "memory", "n": n, "token": time.time_ns(),
                             **_options_manifest(radius, grid, orientation, options, chunk_size)})
        t_scatter = time.perf_counter()
        for c, s in enumerate(range(0, n, chunk_size)):
            _scatter(v[s:s + chunk_size], None if nv is None else nv[s:s + chunk_size], s, c,
                     grid, work)
        report.stage_seconds["scatter"] = time.perf_counter() - t_scatter
        own_tiles = _process(client, threads, work, grid, radius, orientation, options, {},
                             "<array>", progress, measure_memory, report, nv is not None)
        t_write = time.perf_counter()
        parts = [_as_result(_gather(work, own_tiles.get(c, []), c, s, min(chunk_size, n - s)),
                            radius)
                 for c, s in enumerate(range(0, n, chunk_size))]
    res = _concat_results(parts, radius)
    report.stage_seconds["write"] = time.perf_counter() - t_write
    report.seconds = time.perf_counter() - t0
    return (res, report) if return_report else res
