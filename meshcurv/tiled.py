"""Tiled curvature estimation on Dask for clouds larger than one process: spatial tiles with a halo.

The cloud is cut into square tiles of side ``tile_size`` in x, y (columns, unbounded in z). A tile
task gets the tile's own points plus every point within the halo (``>= radius``, which is also the
PCA-normal radius) of the tile, in input order, and estimates curvature at its own points only
(``principal_curvatures(..., query=own)``). Because the neighbour lists, the tangent frames and the
normals of the own points then see exactly what a whole-cloud run sees, a tile's values equal the
untiled run's when the orientation is well defined per point (given normals, or a viewpoint).

Pipeline, every stage resumable from a work folder (``OUT.meshcurv-work`` next to the output):

1. scatter: tasks read ranges of the input (chunk coordinates) and write, per tile they touch,
   a piece ``pieces/t_IX_IY/cNNNNNN.npz`` (global index, xyz, own flag, normals if given);
2. tiles: one task per tile loads its pieces (tile + halo only), estimates, writes its results
   per input chunk ``results/t_IX_IY/cNNNNNN.npz`` and then a ``done.json`` marker;
3. orientation: for ``orientation="mst"`` tiles are made to agree in their overlaps (below);
4. write: the driver streams the input once more and writes the output in input order, through
   a temporary file renamed at the end (never a partial output). The work folder is removed.

A rerun with the same input and parameters skips finished chunks and tiles; other parameters or a
changed input start afresh.

Normal orientation across tiles
-------------------------------
- given normals (NormalX.. / nx.. in the file, ``normals=`` in memory): used as they are;
- ``orientation=(x, y, z)`` viewpoint: every normal is flipped towards that scanner position,
  so tiles agree by construction and the result equals the untiled run;
- ``orientation="mst"``: each tile orients its tile + halo by minimum-spanning-tree propagation
  (:func:`meshcurv.normals.orient_mst`). A tile's halo points are its neighbours' own points, so
  each pair of adjacent tiles votes ``sum(n_A . n_B)`` over their shared points; the driver then
  flips whole tiles along a maximum spanning tree of the tile graph (strongest overlaps first)
  and finally flips each connected group of tiles so its normals point away from its centroid on
  average, the rule ``orient_mst`` applies to a whole cloud. Flipping a tile's normal maps its
  results exactly: ``k1, k2, d1, d2, n -> -k2, -k1, d2, d1, -n``. Signs then agree with an
  untiled MST run wherever the propagation itself agrees (smooth, well-sampled surfaces).

>>> from meshcurv.tiled import annotate_tiled                                  # doctest: +SKIP
>>> annotate_tiled("big.laz", "big_curv.laz", radius=0.5, tile_size=50.0,
...                orientation=(0.0, 0.0, 1000.0))                           # doctest: +SKIP
"""

import contextlib
import dataclasses
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np
from tqdm.auto import tqdm

from . import las

__all__ = ["TileError", "TiledReport", "TileGrid", "annotate_tiled", "principal_curvatures_tiled"]

# Relative safety margin on the halo: a neighbour at exactly ``radius`` must land in the halo
# even after the rounding of (x - origin) / tile_size.
_HALO_MARGIN = 1e-6


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

    def own_keys(self, xyz):
        """(k, 2) int64 tile index of each point's own tile."""
        o = np.asarray(self.origin, dtype=np.float64)
        return np.floor((xyz[:, :2] - o) / self.tile_size).astype(np.int64)

    def memberships(self, xyz):
        """All (point, tile) pairs of tile + halo membership.

        Returns
        -------
        point : (p,) int64 row into ``xyz``; keys : (p, 2) int64 tiles; own : (p,) bool
        """
        o = np.asarray(self.origin, dtype=np.float64)
        lo = np.floor((xyz[:, :2] - self.halo - o) / self.tile_size).astype(np.int64)
        hi = np.floor((xyz[:, :2] + self.halo - o) / self.tile_size).astype(np.int64)
        own = self.own_keys(xyz)
        # own tile always inside [lo, hi]; rounding cannot move it out, but make it explicit
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


@dataclass
class TiledReport:
    """What a tiled run did.

    Attributes
    ----------
    n_points : int; n_tiles : int; radius, tile_size, halo : float, model units
    computed, skipped : lists of tile names (``"t_IX_IY"``) computed now / found finished
    tile_stats : dict tile name -> {"n_own", "n_total", "seconds", "peak_traced_bytes",
        "maxrss_bytes"}; seconds : wall time of the whole run; out_path : str or None
    """

    n_points: int
    n_tiles: int
    radius: float
    tile_size: float
    halo: float
    computed: list = field(default_factory=list)
    skipped: list = field(default_factory=list)
    tile_stats: dict = field(default_factory=dict)
    seconds: float = 0.0
    out_path: str = None


# ----------------------------------------------------------------------------- small file helpers

def _tile_name(key):
    return f"t_{int(key[0])}_{int(key[1])}"


def _atomic_savez(path, **arrays):
    tmp = f"{path}.{os.getpid()}.tmp"
    with open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    os.replace(tmp, path)


def _atomic_json(path, obj):
    tmp = f"{path}.{os.getpid()}.tmp"
    with open(tmp, "w") as fh:
        json.dump(obj, fh)
    os.replace(tmp, path)


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
    for sub in ("pieces", "results", "chunks"):
        os.makedirs(os.path.join(work, sub), exist_ok=True)
    if not os.path.exists(mpath):
        _atomic_json(mpath, manifest)


# ----------------------------------------------------------------------------- stage 1: scatter

def _scatter(xyz, normals, first, chunk_id, grid, work):
    """Write this chunk's points into the pieces of every tile whose tile + halo holds them.

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
    for a, b in zip(starts, ends):
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


# ----------------------------------------------------------------------------- stage 2: tiles

def _tile_normals(xyz, radius):
    """PCA normals at every point of tile + halo, oriented by MST propagation within it."""
    from scipy.spatial import cKDTree

    from .neighborhoods import ball_neighbors
    from .normals import orient_mst, pca_normals

    nv = np.full(xyz.shape, np.nan)
    finite = np.flatnonzero(np.isfinite(xyz).all(axis=1))
    if len(finite):
        tree = cKDTree(xyz[finite])
        for s in range(0, len(xyz), 65536):
            idx = np.arange(s, min(s + 65536, len(xyz)))
            indptr, indices = ball_neighbors(tree, finite, xyz[idx], radius)
            nv[idx] = pca_normals(xyz, xyz[idx], indptr, indices, radius)
    return orient_mst(xyz, nv)


def _estimate_tile(xyz, own, normals, radius, orientation, options):
    """Curvature at the own points of one tile + halo; returns (CurvatureResult, halo normals)."""
    from .estimator import principal_curvatures

    query = np.flatnonzero(own)
    halo_normals = None
    if normals is None and isinstance(orientation, str):
        normals = _tile_normals(xyz, radius)
        halo_normals = normals[~own]
    if normals is not None:
        res = principal_curvatures(xyz, normals=normals, radius=radius, query=query, **options)
    else:
        res = principal_curvatures(xyz, radius=radius, orientation=orientation, query=query,
                                   normal_estimation="pca", **options)
    return res, halo_normals


def _tile_task(name, work, chunk_ids, radius, orientation, options, grid, in_path,
               threads=None, measure_memory=False):
    """Dask task: estimate one tile from its pieces; writes results per chunk and ``done.json``."""
    import resource
    import tracemalloc

    t0 = time.perf_counter()
    try:
        if threads:
            import numba

            numba.set_num_threads(int(threads))
        if measure_memory:
            tracemalloc.start()
        folder = os.path.join(work, "pieces", name)
        parts = []
        for c in chunk_ids:
            with np.load(os.path.join(folder, f"c{c:06d}.npz")) as z:
                parts.append({k: z[k] for k in z.files})
        idx = np.concatenate([p["idx"] for p in parts])
        xyz = np.concatenate([p["xyz"] for p in parts])
        own = np.concatenate([p["own"] for p in parts])
        normals = np.concatenate([p["normals"] for p in parts]) if "normals" in parts[0] else None
        chunk_of = np.concatenate([np.full(len(p["idx"]), c) for c, p in zip(chunk_ids, parts)])
        del parts
        res, halo_normals = _estimate_tile(xyz, own, normals, radius, orientation, options)
        out = os.path.join(work, "results", name)
        os.makedirs(out, exist_ok=True)
        own_idx, own_chunk = idx[own], chunk_of[own]
        for c in np.unique(own_chunk):
            sel = own_chunk == c
            _atomic_savez(os.path.join(out, f"c{int(c):06d}.npz"), idx=own_idx[sel],
                          **{k: getattr(res, k)[sel] for k in _row_fields()})
        stats = {"n_own": int(own.sum()), "n_total": int(len(own))}
        if halo_normals is not None:
            # overlap data for the cross-tile vote: own points near the border, halo normals
            ox, oy = grid.origin
            key = np.array(name.split("_")[1:], dtype=np.int64)
            lo = np.array([ox, oy]) + key * grid.tile_size
            rel = xyz[:, :2] - lo
            border = own & ((rel < grid.halo) | (rel > grid.tile_size - grid.halo)).any(axis=1)
            _atomic_savez(os.path.join(out, "overlap.npz"), band_idx=idx[border],
                          band_normals=res.normals[np.flatnonzero(border[own])],
                          halo_idx=idx[~own], halo_normals=halo_normals,
                          halo_owner=grid.own_keys(xyz[~own]))
            # partial sums for the outward decision: sum p.n, sum n, sum p, count
            ok = np.isfinite(res.normals).all(axis=1)
            p, n = xyz[own][ok], res.normals[ok]
            stats["orient"] = [float(np.einsum("ij,ij->", p, n)), *n.sum(axis=0).tolist(),
                               *p.sum(axis=0).tolist(), int(ok.sum())]
        if measure_memory:
            stats["peak_traced_bytes"] = int(tracemalloc.get_traced_memory()[1])
            tracemalloc.stop()
        stats["maxrss_bytes"] = int(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) * 1024
        stats["seconds"] = time.perf_counter() - t0
        _atomic_json(os.path.join(out, "done.json"), stats)
        return stats
    except Exception as e:
        if measure_memory and tracemalloc.is_tracing():
            tracemalloc.stop()
        raise TileError(f"tile {name} of {in_path} failed: {type(e).__name__}: {e}") from e


# ----------------------------------------------------------------------------- stage 3: orientation

def _tile_flips(work, names, grid):
    """+1/-1 per tile so that tiles agree in their overlaps and each group points outward."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order, connected_components, minimum_spanning_tree

    pos = {n: i for i, n in enumerate(names)}
    bands = {}

    def band(name):
        if name not in bands:
            with np.load(os.path.join(work, "results", name, "overlap.npz")) as z:
                bands[name] = (z["band_idx"], z["band_normals"])
        return bands[name]

    rows, cols, votes = [], [], []
    for a in names:
        with np.load(os.path.join(work, "results", a, "overlap.npz")) as z:
            h_idx, h_nv, owner = z["halo_idx"], z["halo_normals"], z["halo_owner"]
        for key in np.unique(owner, axis=0):
            b = _tile_name(key)
            if b not in pos:
                continue
            sel = (owner == key).all(axis=1)
            b_idx, b_nv = band(b)
            _, ia, ib = np.intersect1d(h_idx[sel], b_idx, assume_unique=True, return_indices=True)
            dots = np.einsum("ij,ij->i", h_nv[sel][ia], b_nv[ib])
            vote = float(np.nansum(dots))
            if vote != 0.0:
                rows.append(pos[a])
                cols.append(pos[b])
                votes.append(vote)
    n = len(names)
    votes = np.asarray(votes)
    # symmetric vote matrix; the spanning tree keeps the strongest agreements (smallest 1/|vote|)
    vote_m = coo_matrix((votes, (rows, cols)), shape=(n, n)).tocsr()
    vote_m = vote_m + vote_m.T
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
    st = np.array([_read_json(os.path.join(work, "results", nm, "done.json"))["orient"]
                   for nm in names]).reshape(n, 8)
    for c in range(n_comp):
        g = labels == c
        cnt = st[g, 7].sum()
        if cnt == 0:
            continue
        centroid = st[g, 4:7].sum(axis=0) / cnt
        score = np.sum(flips[g] * (st[g, 0] - st[g, 1:4] @ centroid))
        if score < 0:
            flips[g] *= -1.0
    return dict(zip(names, flips))


# ----------------------------------------------------------------------------- stage 4: assembly

def _row_fields():
    """Names of the per-row array fields of CurvatureResult (all but ``valid`` and ``radius``)."""
    from .estimator import CurvatureResult

    return [f.name for f in dataclasses.fields(CurvatureResult) if f.name not in ("valid", "radius")]


def _empty_rows(name, count):
    if name in ("d1", "d2", "normals"):
        return np.full((count, 3), np.nan)
    if name in ("n_neighbors", "n_samples"):
        return np.zeros(count, dtype=np.int64)
    return np.full(count, np.nan)


def _gather(work, tiles, chunk_id, first, count, flips):
    """Result arrays of points ``first .. first + count - 1`` from the tiles that own them; points
    no tile owns (non-finite coordinates) keep NaN / 0."""
    out = {k: _empty_rows(k, count) for k in _row_fields()}
    for name in tiles:
        with np.load(os.path.join(work, "results", name, f"c{chunk_id:06d}.npz")) as z:
            r = {k: z[k] for k in z.files}
        rows = r.pop("idx") - first
        if flips.get(name, 1.0) < 0:
            # the same fits seen from the other side: kappa -> -kappa swaps the roles of k1, k2
            r["k1"], r["k2"] = -r["k2"], -r["k1"]
            r["d1"], r["d2"] = r["d2"], r["d1"]
            r["normals"] = -r["normals"]
        for k, a in r.items():
            out[k][rows] = a
    return out


def _as_result(arrays, radius):
    from .estimator import CurvatureResult

    return CurvatureResult(valid=np.isfinite(arrays["k1"]), radius=float(radius), **arrays)


# ----------------------------------------------------------------------------- the driver

@contextlib.contextmanager
def _dask_client(scheduler, n_workers):
    """A distributed Client: the given one, one connected to an address, or a LocalCluster."""
    from distributed import Client, LocalCluster

    if scheduler is not None and not isinstance(scheduler, str):
        yield scheduler, None
        return
    if isinstance(scheduler, str):
        with Client(scheduler) as client:
            yield client, None
        return
    n_workers = int(n_workers or min(os.cpu_count() or 1, 8))
    with LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        yield client, max(1, (os.cpu_count() or 1) // n_workers)


def _run(client, submit, jobs, desc, progress):
    """Submit ``jobs`` ({name: args}) and wait; the first failure cancels the rest and is raised
    naming its tile or chunk."""
    from distributed import as_completed

    futures = {}
    for name, (func, args, kwargs) in jobs.items():
        futures[client.submit(func, *args, key=f"meshcurv-{name}-{submit}", pure=False,
                              retries=0, **kwargs)] = name
    results = {}
    bar = tqdm(total=len(futures), desc=desc, unit="tile" if desc == "tiles" else "chunk",
               disable=not progress)
    try:
        for fut in as_completed(futures):
            name = futures[fut]
            try:
                results[name] = fut.result()
            except (TileError, las.LasReadError):
                raise
            except Exception as e:  # KilledWorker, CommClosedError, ...: the worker is gone
                raise TileError(f"{desc[:-1]} {name}: {type(e).__name__}: {e}") from e
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


def _check_orientation(orientation):
    if isinstance(orientation, str):
        if orientation != "mst":
            raise ValueError(f"orientation must be 'mst' or a (3,) viewpoint, got {orientation!r}")
        return orientation
    vp = np.asarray(orientation, dtype=np.float64)
    if vp.shape != (3,) or not np.isfinite(vp).all():
        raise ValueError("orientation must be 'mst' or a finite (3,) viewpoint")
    return tuple(float(c) for c in vp)


def _process(client, threads, work, grid, radius, orientation, options, chunk_jobs, in_path,
             progress, measure_memory, report):
    """Stages 1-3 on a connected client: scatter, tiles, flips. Returns (chunk summaries, flips)."""
    token = f"{os.getpid()}-{time.time_ns()}"
    summaries = {int(f[1:7]): _read_json(os.path.join(work, "chunks", f))
                 for f in os.listdir(os.path.join(work, "chunks")) if f.endswith(".json")}
    todo = {f"c{cid:06d}": job for cid, job in chunk_jobs.items() if cid not in summaries}
    if todo:
        done = _run(client, token, todo, "chunks", progress)
        summaries.update({int(k[1:]): v for k, v in done.items()})
    tiles = {}
    for cid in sorted(summaries):
        for name, (n_own, _) in summaries[cid].items():
            tiles.setdefault(name, []).append(cid)
    names = sorted(n for n, cids in tiles.items()
                   if any(summaries[c][n][0] for c in cids))  # tiles that own points
    report.n_tiles = len(names)
    jobs = {}
    for name in names:
        marker = os.path.join(work, "results", name, "done.json")
        if os.path.exists(marker):
            report.skipped.append(name)
            report.tile_stats[name] = _read_json(marker)
        else:
            jobs[name] = (_tile_task, (name, work, tiles[name], radius, orientation, options,
                                       grid, in_path), {"threads": threads,
                                                        "measure_memory": measure_memory})
    report.computed = sorted(jobs)
    report.tile_stats.update(_run(client, token, jobs, "tiles", progress))
    flips = {}
    if isinstance(orientation, str) and "orient" in next(iter(report.tile_stats.values()), {}):
        flips = _tile_flips(work, names, grid)
    own_tiles = {cid: [n for n, (n_own, _) in s.items() if n_own] for cid, s in summaries.items()}
    return own_tiles, flips


def _default_tile_size(n_points, extent, target=1_000_000):
    area = max(float(extent[0]) * float(extent[1]), 1e-300)
    return float(np.sqrt(area * target / max(n_points, 1)))


def annotate_tiled(in_path, out_path, radius=None, tile_size=None, *, orientation="mst",
                   scheduler=None, n_workers=None, chunk_size=500_000, work_dir=None,
                   keep_work=False, progress=True, float_type="f8", measure_memory=False,
                   **options):
    """Annotate a LAS/LAZ file with curvature fields, tile by tile on Dask; output in input order.

    Parameters
    ----------
    in_path, out_path : str, .las or .laz (``out_path`` must differ from ``in_path``; .laz is
        compressed with lazrs). Both must be visible to every worker (a shared file system).
    radius : float, model units. Default: :func:`meshcurv.default_radius` of the first chunk.
    tile_size : float, model units, side of the square x, y tiles. Default: about 10^6 points
        per tile from the header's extent.
    orientation : "mst" or (3,) viewpoint
        Used when the file has no normals. A viewpoint (scanner position) reproduces the untiled
        run exactly; "mst" orients per tile and makes tiles agree (see the module docstring).
    scheduler : None, str or distributed.Client
        None starts a LocalCluster (``n_workers`` processes, one thread each); a string is the
        address of an existing scheduler ("tcp://host:8786").
    chunk_size : int, points per read/scatter/write chunk (bounds the driver's memory)
    work_dir : str, default ``out_path + ".meshcurv-work"``; keeps finished tiles for a rerun
    keep_work : bool, keep the work folder after success
    progress : bool, progress bars over chunks and tiles
    float_type : "f8" or "f4", type of the written float fields
    measure_memory : bool, trace each tile task's peak Python/numpy memory (tracemalloc)
    **options : passed to :func:`meshcurv.principal_curvatures` (n_directions, slab, ...)

    Returns
    -------
    TiledReport

    Raises
    ------
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
    las._check_paths(in_path, out_path)
    orientation = _check_orientation(orientation)
    with las._open(in_path) as reader:
        header = reader.header
        n_points = int(header.point_count)
        mins, maxs = np.asarray(header.mins, float), np.asarray(header.maxs, float)
        has_normals = las._normal_dims(header.point_format) is not None
    if radius is None:
        first = next(las.iter_las_chunks(in_path, chunk_size, stop=chunk_size), None)
        from .neighborhoods import default_radius

        radius = default_radius(first[1]) if first is not None else float("nan")
    radius = float(radius)
    if not (np.isfinite(radius) and radius > 0):
        raise ValueError(f"radius must be a positive number of model units, got {radius}")
    if tile_size is None:
        tile_size = _default_tile_size(n_points, maxs[:2] - mins[:2])
    tile_size = float(tile_size)
    if not (np.isfinite(tile_size) and tile_size > 0):
        raise ValueError(f"tile_size must be a positive number of model units, got {tile_size}")
    grid = TileGrid(origin=(float(mins[0]), float(mins[1])), tile_size=tile_size,
                    halo=radius * (1 + _HALO_MARGIN) + _HALO_MARGIN * tile_size * 1e-3)
    work = os.path.abspath(work_dir or out_path + ".meshcurv-work")
    st = os.stat(in_path)
    manifest = {"input": in_path, "size": st.st_size, "mtime_ns": st.st_mtime_ns,
                **_options_manifest(radius, grid, orientation, options, int(chunk_size))}
    _prepare_work(work, manifest)
    report = TiledReport(n_points=n_points, n_tiles=0, radius=radius, tile_size=tile_size,
                         halo=grid.halo, out_path=out_path)
    chunk_jobs = {c: (_scatter_file_task, (in_path, s, min(s + chunk_size, n_points), c, grid,
                                           work), {})
                  for c, s in enumerate(range(0, n_points, chunk_size))}
    try:
        with _dask_client(scheduler, n_workers) as (client, threads):
            own_tiles, flips = _process(client, threads, work, grid, radius, orientation, options,
                                        chunk_jobs, in_path, progress, measure_memory, report)
    except las.LasReadError:
        # an unreadable input leaves nothing worth resuming: a fixed file starts afresh anyway
        shutil.rmtree(work, ignore_errors=True)
        raise
    write_normals = not has_normals
    names = list(las.CURVATURE_FIELDS) + (list(las.NORMAL_FIELDS) if write_normals else [])

    def fields_for(first, count):
        arrays = _gather(work, own_tiles.get(first // chunk_size, []), first // chunk_size,
                         first, count, flips)
        return las.result_fields(_as_result(arrays, radius), normals=write_normals,
                                 float_type=float_type)

    las.annotate_las(in_path, out_path, fields_for, names, chunk_size=chunk_size,
                     float_type=float_type)
    if not keep_work:
        shutil.rmtree(work, ignore_errors=True)
    report.seconds = time.perf_counter() - t0
    return report


def principal_curvatures_tiled(vertices, radius, tile_size, normals=None, *, orientation="mst",
                               scheduler=None, n_workers=None, chunk_size=500_000,
                               work_dir=None, progress=False, measure_memory=False,
                               return_report=False, **options):
    """:func:`meshcurv.principal_curvatures` of an in-memory point cloud, computed in tiles on Dask.

    The driver cuts the cloud into tile + halo pieces in a work folder (which workers must see);
    each task loads one tile + halo only. With given normals or a viewpoint ``orientation`` the
    result equals ``principal_curvatures(vertices, normals=..., radius=radius, orientation=...)``.

    Parameters
    ----------
    vertices : (n, 3) float, model units; normals : (n, 3) float, optional
    radius : float, model units; tile_size : float, model units (x, y side of a tile)
    orientation, scheduler, n_workers, progress, measure_memory, options : as in
        :func:`annotate_tiled`
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
    orientation = _check_orientation(orientation)
    radius, tile_size = float(radius), float(tile_size)
    if not (np.isfinite(radius) and radius > 0 and np.isfinite(tile_size) and tile_size > 0):
        raise ValueError("radius and tile_size must be positive numbers of model units")
    finite = np.isfinite(v).all(axis=1)
    origin = v[finite, :2].min(axis=0) if finite.any() else np.zeros(2)
    grid = TileGrid(origin=(float(origin[0]), float(origin[1])), tile_size=tile_size,
                    halo=radius * (1 + _HALO_MARGIN) + _HALO_MARGIN * tile_size * 1e-3)
    n = len(v)
    report = TiledReport(n_points=n, n_tiles=0, radius=radius, tile_size=tile_size, halo=grid.halo)
    with contextlib.ExitStack() as stack:
        work = work_dir or stack.enter_context(tempfile.TemporaryDirectory(prefix="meshcurv-"))
        _prepare_work(work, {"input": "memory", "n": n, "token": time.time_ns(),
                             **_options_manifest(radius, grid, orientation, options,
                                                 int(chunk_size))})
        for c, s in enumerate(range(0, n, chunk_size)):
            _scatter(v[s:s + chunk_size], None if nv is None else nv[s:s + chunk_size], s, c,
                     grid, work)
        with _dask_client(scheduler, n_workers) as (client, threads):
            own_tiles, flips = _process(client, threads, work, grid, radius, orientation,
                                        options, {}, "<array>", progress, measure_memory, report)
        parts = [_gather(work, own_tiles.get(c, []), c, s, min(chunk_size, n - s), flips)
                 for c, s in enumerate(range(0, n, chunk_size))]
    arrays = {k: np.concatenate([p[k] for p in parts]) if parts else _empty_rows(k, 0)
              for k in _row_fields()}
    res = _as_result(arrays, radius)
    report.seconds = time.perf_counter() - t0
    return (res, report) if return_report else res
