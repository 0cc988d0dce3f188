"""The tasks of a tiled run, each run on a Dask worker: scatter (input chunk -> tile pieces),
normals (MST-oriented PCA normals of one tile) and curvature (the estimate of one tile)."""

import os
import time

import numpy as np

from ..io import las
from ..normals.orient import nearest_areas
from ..pipeline import TREE_NEIGHBORS
from .grid import tile_name
from .work import atomic_json, atomic_savez, load_tile, result_rows

__all__ = ["TileError", "scatter", "scatter_file_task", "normals_task", "curvature_task"]


class TileError(RuntimeError):
    """A tile (or an input chunk) that failed on a worker; the message names the tile and file."""


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

    from ..api import estimate_normals, principal_curvatures

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


def scatter(xyz, normals, first, chunk_id, grid, work):
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
        name = tile_name(keys[a])
        folder = os.path.join(work, "pieces", name)
        os.makedirs(folder, exist_ok=True)
        rows = point[a:b]
        arrays = dict(idx=rows + first, xyz=xyz[rows], own=own[a:b])
        if normals is not None:
            arrays["normals"] = normals[rows]
        atomic_savez(os.path.join(folder, f"c{chunk_id:06d}.npz"), **arrays)
        summary[name] = [int(own[a:b].sum()), int(b - a)]
    atomic_json(os.path.join(work, "chunks", f"c{chunk_id:06d}.json"), summary)
    return summary


def scatter_file_task(in_path, first, stop, chunk_id, grid, work):
    """Dask task: read points ``first .. stop - 1`` of a LAS/LAZ file and scatter them."""
    try:
        for _, xyz, nv in las.iter_las_chunks(in_path, stop - first, start=first, stop=stop):
            return scatter(xyz, nv, first, chunk_id, grid, work)
        return scatter(np.zeros((0, 3)), None, first, chunk_id, grid, work)
    except las.LasReadError:
        raise
    except Exception as e:
        raise TileError(f"{in_path}: splitting points {first}..{stop - 1} into tiles failed "
                        f"({type(e).__name__}: {e})") from e


def normals_task(name, work, chunk_ids, radius, grid, in_path, threads=None,
                  measure_memory=False):
    """Dask task: MST-oriented normals of one tile; writes ``normals/<tile>.npz`` and ``.json``.

    The npz holds ``own_normals`` (n_own, 3) in tile order and the overlap data for the vote
    between tiles: ``band_idx, band_normals`` (own points within the halo width of the tile's
    border) and ``halo_idx, halo_normals, halo_owner`` (the halo points, their tile).
    """
    from ..api import estimate_normals

    t0 = time.perf_counter()
    try:
        _prepare_worker(threads)
        with _TaskMemory(measure_memory) as mem:
            idx, xyz, own, _, _ = load_tile(work, name, chunk_ids)
            nv = estimate_normals(xyz, radius)
            rel = xyz[:, :2] - grid.tile_square(name)
            border = own & ((rel < grid.halo) | (rel > grid.tile_size - grid.halo)).any(axis=1)
            atomic_savez(os.path.join(work, "normals", f"{name}.npz"), own_normals=nv[own],
                          band_idx=idx[border], band_normals=nv[border], halo_idx=idx[~own],
                          halo_normals=nv[~own], halo_owner=grid.own_keys(xyz[~own]))
            # partial sums for the outward decision of a group of tiles, each point weighted
            # by its share of the area (as the untiled spanning tree weighs it):
            # sum a p.n, sum a n, sum a p, sum a, count
            ok = own & np.isfinite(nv).all(axis=1)
            p, n = xyz[ok], nv[ok]
            finite = np.isfinite(nv).all(axis=1) & np.isfinite(xyz).all(axis=1)
            a = nearest_areas(xyz[finite], p, radius, TREE_NEIGHBORS)[:, None]
            stats = {"orient": [float(np.einsum("ij,ij->", a * p, n)),
                                *(a * n).sum(axis=0).tolist(), *(a * p).sum(axis=0).tolist(),
                                float(a.sum()), int(ok.sum())]}
            stats.update(mem.stats())
        stats["seconds"] = time.perf_counter() - t0
        atomic_json(os.path.join(work, "normals", f"{name}.json"), stats)
        return stats
    except Exception as e:
        raise TileError(f"tile {name} of {in_path}: normal estimation failed: "
                        f"{type(e).__name__}: {e}") from e


def curvature_task(name, work, chunk_ids, radius, orientation, options, in_path, flip=None,
                    threads=None, measure_memory=False):
    """Dask task: estimate one tile; writes results per input chunk and ``done.json``.

    With ``flip`` (``orientation="mst"``) the tile's stored MST normals times ``flip`` are used,
    refined as the estimator refines its own estimated normals (``refine_normals=True`` unless
    the options say otherwise).
    """
    from ..api import principal_curvatures

    t0 = time.perf_counter()
    try:
        _prepare_worker(threads)
        with _TaskMemory(measure_memory) as mem:
            idx, xyz, own, normals, chunk_of = load_tile(work, name, chunk_ids)
            if flip is not None:
                with np.load(os.path.join(work, "normals", f"{name}.npz")) as z:
                    normals = np.full(xyz.shape, np.nan)
                    normals[own] = z["own_normals"] * float(flip)
                # these normals were estimated: treat them as the estimator treats its own
                if options.get("refine_normals") is None:
                    options = dict(options, refine_normals=True)
            # the halo covers ``radius`` only: no retries at larger radii, no MLS blend (its
            # supports reach further)
            res = principal_curvatures(xyz, normals=normals, radius=radius,
                                       orientation=orientation, query=np.flatnonzero(own),
                                       **dict(options, sparse_retry=False,
                                              coarse_fit="circles"))
            rows = result_rows(res)
            out = os.path.join(work, "results", name)
            os.makedirs(out, exist_ok=True)
            own_idx, own_chunk = idx[own], chunk_of[own]
            for c in np.unique(own_chunk):
                sel = own_chunk == c
                atomic_savez(os.path.join(out, f"c{int(c):06d}.npz"), idx=own_idx[sel],
                              **{k: v[sel] for k, v in rows.items()})
            stats = {"n_own": int(own.sum()), "n_total": int(len(own))}
            stats.update(mem.stats())
        stats["seconds"] = time.perf_counter() - t0
        atomic_json(os.path.join(out, "done.json"), stats)
        return stats
    except Exception as e:
        raise TileError(f"tile {name} of {in_path} failed: {type(e).__name__}: {e}") from e

