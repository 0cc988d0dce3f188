"""The drivers of tiled runs: :func:`annotate_tiled` (a LAS/LAZ file) and
:func:`principal_curvatures_tiled` (an in-memory cloud), their argument checks and the stages
scatter -> normals -> curvature -> write (see :mod:`meshcurv.tiled`)."""

import contextlib
import math
import os
import shutil
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

from ..io import las
from ..options import check_options
from .cluster import dask_client, run_jobs
from .grid import TileGrid, default_tile_size
from .orient import tile_flips
from .tasks import curvature_task, normals_task, scatter, scatter_file_task
from .work import as_result, concat_results, gather, options_manifest, prepare_work, read_json

__all__ = ["TiledReport", "annotate_tiled", "principal_curvatures_tiled"]

_RESERVED = ("vertices", "faces", "normals", "radius", "orientation", "query", "progress")


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
    orientation : str, how the normals got their sign (``CurvatureResult.orientation``)
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
    orientation: str = None


@dataclass(frozen=True)
class _Stages:
    """What every stage of one run needs: the connected client, the work folder and the
    estimator's parameters (radius in model units, orientation "mst", "+z" or a (3,) tuple)."""

    client: object
    threads: object
    work: str
    grid: TileGrid
    radius: float
    orientation: object
    options: dict
    in_path: str
    progress: bool
    measure_memory: bool

    def run(self, jobs, desc, unit):
        return run_jobs(self.client, jobs, desc, unit, self.in_path, self.progress)

    def task_kw(self, **extra):
        return dict(threads=self.threads, measure_memory=self.measure_memory, **extra)


def _process(stages, chunk_jobs, report, has_normals):
    """Stages 1-3 on a connected client. Returns {chunk id: [tiles owning points of it]}."""
    summaries = _scatter_stage(stages, chunk_jobs, report)
    tiles = {}
    for cid in sorted(summaries):
        for name in summaries[cid]:
            tiles.setdefault(name, []).append(cid)
    names = sorted(n for n, cids in tiles.items() if any(summaries[c][n][0] for c in cids))
    report.n_tiles = len(names)
    flips, normal_stats = {}, {}
    if has_normals:
        report.orientation = "as given"
    elif isinstance(stages.orientation, tuple):
        report.orientation = "oriented towards the viewpoint"
    else:
        report.orientation = "oriented towards +z"      # "mst": replaced by the groups' rules
    if stages.orientation == "mst" and not has_normals:
        t0 = time.perf_counter()
        normal_stats = _normals_stage(stages, names, tiles)
        report.flips, report.orientation = tile_flips(stages.work, names, note=True)
        flips = report.flips
        report.stage_seconds["normals"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    _curvature_stage(stages, names, tiles, flips, report)
    report.stage_seconds["tiles"] = time.perf_counter() - t0
    if flips:
        for name in names:
            report.tile_stats[name].update(
                {f"normals_{k}": v for k, v in normal_stats[name].items() if k != "orient"})
    return {cid: [n for n, (n_own, _) in s.items() if n_own] for cid, s in summaries.items()}


def _scatter_stage(stages, chunk_jobs, report):
    """Stage 1: scatter the chunks not scattered yet. Returns {chunk id: {tile: [n_own,
    n_total]}} of every chunk (also those an earlier run scattered, or the caller did)."""
    chunks = os.path.join(stages.work, "chunks")
    summaries = {int(f[1:7]): read_json(os.path.join(chunks, f))
                 for f in os.listdir(chunks) if f.endswith(".json")}
    todo = {f"c{cid:06d}": job for cid, job in chunk_jobs.items() if cid not in summaries}
    t0 = time.perf_counter()
    if todo:
        done = stages.run(todo, "scatter", "chunk")
        summaries.update({int(k[1:]): v for k, v in done.items()})
    report.stage_seconds["scatter"] = report.stage_seconds.get("scatter", 0.0) + (
        time.perf_counter() - t0)
    return summaries


def _normals_stage(stages, names, tiles):
    """Stage 2: MST normals of the tiles that have none yet. Returns {tile: task stats}."""
    normal_stats, jobs = {}, {}
    for name in names:
        marker = os.path.join(stages.work, "normals", f"{name}.json")
        if os.path.exists(marker):
            normal_stats[name] = read_json(marker)
        else:
            jobs[name] = (normals_task, (name, stages.work, tiles[name], stages.radius,
                                         stages.grid, stages.in_path), stages.task_kw())
    normal_stats.update(stages.run(jobs, "normals", "tile"))
    return normal_stats


def _curvature_stage(stages, names, tiles, flips, report):
    """Stage 3: estimate the tiles not finished yet; records them in ``report``."""
    jobs = {}
    for name in names:
        marker = os.path.join(stages.work, "results", name, "done.json")
        if os.path.exists(marker):
            report.skipped.append(name)
            report.tile_stats[name] = read_json(marker)
        else:
            jobs[name] = (curvature_task, (name, stages.work, tiles[name], stages.radius,
                                           stages.orientation, stages.options, stages.in_path),
                          stages.task_kw(flip=flips.get(name)))
    report.computed = sorted(jobs)
    report.tile_stats.update(stages.run(jobs, "tiles", "tile"))


def _halo_reach(options):
    """Radii the halo covers: 1, plus 1 + :data:`meshcurv.pipeline.FIELD_RATIO` with
    normal-aware circle fits (a neighbor's field normal mixes plane fits over balls of up to
    that radius by means over its own ball, :func:`meshcurv.pipeline.field_mix`), plus 1 with
    the outlier pass (the points of those balls are scored on their own balls)."""
    from ..pipeline import FIELD_RATIO

    return (1 + (1 + FIELD_RATIO) * (options.get("normal_constraints", "auto") != "off")
            + bool(options.get("robust_points", True)))


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
    radius : float, model units. Default: :func:`meshcurv.default_radius` of the file,
        estimated from its first chunk (also where the file is in random order, see
        :func:`_first_chunk_radius`).
    tile_size : float, model units, side of the square x, y tiles. Default: about 10^6 points
        per tile from the header's extent.
    orientation : "mst", "+z" or (3,) viewpoint
        Used when the file has no normals. A viewpoint (scanner position) or "+z" (every normal
        up, the command line's default for LAS/LAZ) reproduces the untiled run exactly; "mst"
        orients per tile and makes tiles agree (see the module docstring).
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
    orientation = _check_estimator_options(orientation, options)
    chunk_size = _positive_count("chunk_size", chunk_size)
    # an annotated input is refused now, not after the whole computation
    names = las.check_annotatable(in_path)
    n_points, mins, maxs, has_normals = _header_summary(in_path)
    _refuse_text_radius(radius, " or None, got {!r} (a data-driven radius needs the whole cloud)")
    if radius is None:
        radius = _first_chunk_radius(in_path, chunk_size, n_points, mins, maxs)
    radius = _positive_length("radius", radius)
    if tile_size is None:
        tile_size = default_tile_size(n_points, maxs[:2] - mins[:2], radius)
    tile_size = _positive_length("tile_size", tile_size)
    grid = TileGrid.for_radius(mins[:2], tile_size, radius, _halo_reach(options))
    work = os.path.abspath(work_dir or out_path + ".meshcurv-work")
    st = os.stat(in_path)
    manifest = {"input": in_path, "size": st.st_size, "mtime_ns": st.st_mtime_ns,
                **options_manifest(radius, grid, orientation, options, chunk_size)}
    report = TiledReport(n_points=n_points, n_tiles=0, radius=radius, tile_size=tile_size,
                         halo=grid.halo, out_path=out_path)
    chunk_jobs = {c: (scatter_file_task, (in_path, s, min(s + chunk_size, n_points), c, grid,
                                          work), {})
                  for c, s in enumerate(range(0, n_points, chunk_size))}
    t_start = time.perf_counter()
    with dask_client(scheduler, n_workers, threads_per_task) as (client, threads):
        # connected before the work folder exists: an unreachable scheduler leaves nothing
        report.stage_seconds["start"] = time.perf_counter() - t_start
        prepare_work(work, manifest)
        stages = _Stages(client, threads, work, grid, radius, orientation, options, in_path,
                         progress, measure_memory)
        try:
            own_tiles = _process(stages, chunk_jobs, report, has_normals)
        except las.LasReadError:
            # an unreadable input leaves nothing worth resuming: a fixed file starts afresh
            shutil.rmtree(work, ignore_errors=True)
            raise
    t_write = time.perf_counter()
    kept = _write_output(in_path, out_path, work, own_tiles, names, radius, chunk_size,
                         float_type, not has_normals, return_result)
    report.stage_seconds["write"] = time.perf_counter() - t_write
    if not keep_work:
        shutil.rmtree(work, ignore_errors=True)
    report.seconds = time.perf_counter() - t0
    if not return_result:
        return report
    return report, concat_results(kept, radius)


def _header_summary(in_path):
    """``(n_points, mins (3,), maxs (3,), has_normals)`` from a LAS/LAZ header."""
    with las.open_las(in_path) as reader:
        header = reader.header
        return (int(header.point_count), np.asarray(header.mins, float),
                np.asarray(header.maxs, float), las.normal_dims(header.point_format) is not None)


def _first_chunk_radius(in_path, chunk_size, n_points, mins, maxs):
    """:func:`meshcurv.default_radius` of the whole file, estimated from its first
    ``chunk_size`` points (NaN if none); ``n_points``, ``mins``, ``maxs``: the header's count
    and bounds.

    The first points of a file sorted by acquisition (strips, scan lines) are all the points
    of a part of it; those of a file in random order are a sample of the whole, whose density
    is their share of the true one, and the radius that holds ~100 of them holds that many
    over the share of all points (a 50M-point file in random order: 100x too many). The share
    the chunk holds of the points where it lies is estimated from the x, y cells of a coarse
    grid over the header's bounds it occupies: its count over the count those cells would
    hold at the file's mean density (between the chunk's share of the file and 1), and the
    radius scales by its square root."""
    from ..neighbors import default_radius

    first = next(las.iter_las_chunks(in_path, chunk_size, stop=chunk_size), None)
    if first is None:
        return float("nan")
    points = first[1]
    return default_radius(points) * math.sqrt(_sampled_share(points, n_points, mins, maxs))


def _sampled_share(points, n_points, mins, maxs):
    """The share (in [len(points) / n_points, 1]) of the file's points near ``points`` that
    ``points`` holds (see :func:`_first_chunk_radius`)."""
    xy = points[np.isfinite(points).all(axis=1), :2]
    c = len(xy)
    lo = np.asarray(mins[:2], float)
    extent = np.asarray(maxs[:2], float) - lo
    if c == 0 or n_points <= c or not np.all(extent > 0.0):
        return 1.0
    unit = np.clip((xy - lo) / extent, 0.0, 1.0)

    def occupied(side):
        """Cells of a side x side grid over the bounds holding a point; their area (unit 1)."""
        cell = np.minimum((unit * side).astype(np.int64), side - 1)
        return len(np.unique(cell[:, 0] * side + cell[:, 1])) / float(side * side)

    # cells a random sample of this size fills with ~16 points each; then, twice, cells that
    # the chunk's own density fills with ~4 (finer where it is a compact part, whose edge
    # cells, partly empty, would count as its area; 4 leave 2 % of the cells of a random
    # sample empty)
    side = max(1, min(4096, int(math.sqrt(c / 16.0))))
    for _ in range(2):
        density = c / occupied(side)          # points per unit area where the chunk lies
        side = max(side, min(4096, int(math.sqrt(density / 4.0))))
    expected = n_points * occupied(side)      # the points there at the file's mean density
    return float(np.clip(c / expected, c / n_points, 1.0))


def _write_output(in_path, out_path, work, own_tiles, names, radius, chunk_size, float_type,
                  write_normals, keep):
    """Stage 4: stream the input once more and write it with the curvature fields, in input
    order. Returns the CurvatureResult of each chunk if ``keep``, else an empty list."""
    kept = []

    def fields_for(first, count):
        chunk_id = first // chunk_size
        res = as_result(gather(work, own_tiles.get(chunk_id, []), chunk_id, first, count),
                        radius)
        if keep:
            kept.append(res)
        return las.result_fields(res, normals=write_normals, float_type=float_type)

    las.annotate_las(in_path, out_path, fields_for, names, chunk_size=chunk_size,
                     float_type=float_type)
    return kept


def principal_curvatures_tiled(vertices, radius, tile_size, normals=None, *, orientation="mst",
                               scheduler=None, n_workers=None, chunk_size=500_000,
                               work_dir=None, progress=False, measure_memory=False,
                               return_report=False, threads_per_task=None, **options):
    """:func:`meshcurv.principal_curvatures` of an in-memory point cloud, computed in tiles on Dask.

    The driver cuts the cloud into tile + halo pieces in a work folder (which workers must see);
    each task loads one tile + halo only. With given normals, ``orientation="+z"`` or a
    viewpoint the result equals ``principal_curvatures(vertices, normals=..., radius=radius,
    orientation=..., sparse_retry=False, coarse_fit="circles")`` bit for bit (module
    docstring).

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
    orientation = _check_estimator_options(orientation, options)
    _refuse_text_radius(radius, ", got {!r}")
    radius, tile_size = _positive_length("radius", radius), _positive_length("tile_size", tile_size)
    chunk_size = _positive_count("chunk_size", chunk_size)
    finite = np.isfinite(v).all(axis=1)
    origin = v[finite, :2].min(axis=0) if finite.any() else np.zeros(2)
    grid = TileGrid.for_radius(origin, tile_size, radius, _halo_reach(options))
    n = len(v)
    report = TiledReport(n_points=n, n_tiles=0, radius=radius, tile_size=tile_size, halo=grid.halo)
    with contextlib.ExitStack() as stack:
        # connected before the work folder exists: an unreachable scheduler leaves nothing
        t_start = time.perf_counter()
        client, threads = stack.enter_context(dask_client(scheduler, n_workers,
                                                          threads_per_task))
        report.stage_seconds["start"] = time.perf_counter() - t_start
        work = work_dir or stack.enter_context(tempfile.TemporaryDirectory(prefix="meshcurv-"))
        # an array cannot be recognised again: always start afresh
        prepare_work(work, {"input": "memory", "n": n, "token": time.time_ns(),
                            **options_manifest(radius, grid, orientation, options, chunk_size)})
        t_scatter = time.perf_counter()
        for c, s in enumerate(range(0, n, chunk_size)):
            scatter(v[s:s + chunk_size], None if nv is None else nv[s:s + chunk_size], s, c,
                    grid, work)
        report.stage_seconds["scatter"] = time.perf_counter() - t_scatter
        stages = _Stages(client, threads, work, grid, radius, orientation, options, "<array>",
                         progress, measure_memory)
        own_tiles = _process(stages, {}, report, nv is not None)
        t_write = time.perf_counter()
        parts = [as_result(gather(work, own_tiles.get(c, []), c, s, min(chunk_size, n - s)),
                           radius)
                 for c, s in enumerate(range(0, n, chunk_size))]
    res = concat_results(parts, radius)
    res.orientation = report.orientation
    report.stage_seconds["write"] = time.perf_counter() - t_write
    report.seconds = time.perf_counter() - t0
    return (res, report) if return_report else res


def _check_estimator_options(orientation, options):
    """Reject estimator options the tiled run cannot take, before any work starts; returns
    ``orientation`` as "mst", "+z" or a tuple (sent to every task). Names and values are
    checked by :func:`meshcurv.options.check_options`; here only what tiles add: the run's own
    keywords, and point-cloud neighborhoods and normals."""
    reserved = sorted(set(options) & set(_RESERVED))
    if reserved:
        raise ValueError(f"the tiled run sets {reserved} itself; pass them as its own arguments")
    orientation = check_options(orientation=orientation, **options)
    if options.get("neighborhood", "ball") not in ("auto", "ball"):
        raise ValueError("tiled runs are for point clouds: neighborhood must be 'ball'")
    if options.get("normal_estimation", "pca") not in ("auto", "pca"):
        raise ValueError("tiled runs are for point clouds: normal_estimation must be 'pca'")
    if options.get("sparse_retry", False):
        raise ValueError("tiled runs estimate at the one radius their halo covers: "
                         "sparse_retry must be False")
    if options.get("coarse_fit", "circles") != "circles":
        raise ValueError("tiled runs estimate at the one radius their halo covers: "
                         "coarse_fit must be 'circles'")
    return orientation if isinstance(orientation, str) else tuple(map(float, orientation))


def _refuse_text_radius(radius, tail):
    """A radius given as text ("auto", "2%") needs the whole cloud: ValueError (one line),
    ``tail`` formatted with the radius ends the message."""
    if isinstance(radius, str):
        raise ValueError("tiled runs need a radius in model units" + tail.format(radius))


def _positive_length(name, value):
    """``value`` as a float; ValueError unless it is a positive finite number (model units)."""
    value = float(value)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"{name} must be a positive number of model units, got {value}")
    return value


def _positive_count(name, value):
    """``value`` as an int; ValueError unless it is at least 1."""
    value = int(value)
    if value < 1:
        raise ValueError(f"{name} must be a positive number of points, got {value}")
    return value
