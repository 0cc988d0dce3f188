"""The ``meshcurv`` command: annotate files with principal curvatures, in batches, and inspect them.

Subcommands ``annotate``, ``batch`` and ``info``; run ``meshcurv --help``. Exit codes: 0 success,
1 a file could not be processed (or, for ``batch``, at least one failed), 2 command-line error.
Expected errors print one line ``meshcurv: error: ...`` on stderr and leave no output file.
"""

import argparse
import contextlib
import functools
import os
import sys
import time
import warnings
from dataclasses import dataclass

import numpy as np

from . import io, shape

__all__ = ["main", "AnnotateOptions", "parse_radius", "annotate_file", "run_batch"]

_DESCRIPTION = """\
Principal curvatures of meshes and point clouds by CGA circle fits (Seibert et al.).

Units: k1, k2, mean and curvedness in 1/model units, gaussian in 1/model units^2, shape index
without unit in [-1, 1] (+1 cap, +0.5 ridge, 0 saddle, -0.5 rut, -1 cup).
Sign: for OUTWARD normals, convex positive: a sphere of radius r gives k1 = k2 = +1/r, mean
+1/r, shape index +1; k1 >= k2 always. Meshes take the orientation of their faces
(counter-clockwise seen from outside); point clouds use their normals or estimate and orient
them (flip the cloud's normals to flip every sign).
Radius: in model units (--radius 0.05) or in percent of the bounding-box diagonal (--radius 2%),
as in MeshLab; default: the radius whose ball holds about 100 points.
Vertices are never reordered, merged or dropped (STL corners are merged by position on reading);
vertices without an estimate have NaN curvature, valid = 0, quality 0 and a grey colour.

Exit codes: 0 success, 1 a file could not be processed, 2 command-line error."""

_RADIUS_HELP = ("neighbourhood radius: a number in model units (0.05) or a percentage of the "
                "bounding-box diagonal (2%%); default: the radius whose ball holds ~100 points")


class CommandError(Exception):
    """An expected error with a one-line message and an exit code."""

    def __init__(self, message, code=1):
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class AnnotateOptions:
    """Estimation and output options shared by ``annotate`` and ``batch`` (picklable).

    radius : str or None, "2%" (of the bbox diagonal) or "0.05" (model units); None = default
    directions : int, planes through the normal (2 x directions circle fits)
    neighborhood : "auto" | "kring" | "ball"
    normals : "auto" (file normals for point clouds that have them, else estimated) |
        "file" (require normals in the file) | "estimate" (ignore file normals)
    quality : field written to ``quality`` and coloured
    colormap : MeshLab colour map name, see :data:`meshcurv.shape.COLORMAPS`
    viewpoint : (3,) tuple or None, orient estimated point-cloud normals towards this point
        (a scanner position) instead of along a spanning tree
    """

    radius: str = None
    directions: int = 8
    neighborhood: str = "auto"
    normals: str = "auto"
    quality: str = "mean"
    colormap: str = "Turbo"
    viewpoint: tuple = None


def parse_radius(text):
    """Parse a radius option: ``"2%"`` -> (2.0, True), ``"0.05"`` -> (0.05, False).

    Raises ValueError for anything that is not a positive finite number, optionally with ``%``.
    """
    s = str(text).strip()
    percent = s.endswith("%")
    try:
        value = float(s[:-1] if percent else s)
    except ValueError:
        raise ValueError(f"radius must be a number (model units) or a percentage like 2%, "
                         f"got {text!r}") from None
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"radius must be positive, got {text!r}")
    return value, percent


def _radius_in_model_units(spec, diagonal):
    """Absolute radius for ``spec`` ("2%", "0.05" or None = the estimator's default);
    ``diagonal()`` gives the bounding-box diagonal a percentage refers to."""
    if spec is None:
        return None
    value, percent = parse_radius(spec)
    return value / 100.0 * diagonal() if percent else value


def _check_options(options):
    """Raise CommandError(code 2) for option values no file can fix."""
    try:
        if options.radius is not None:
            parse_radius(options.radius)
        if options.quality not in shape.FIELDS:
            raise ValueError(f"--quality must be one of {', '.join(shape.FIELDS)}")
        if options.colormap.lower() not in (c.lower() for c in shape.COLORMAPS):
            raise ValueError(f"--colormap must be one of {', '.join(shape.COLORMAPS)}")
        from .options import check_options

        check_options(n_directions=options.directions, neighborhood=options.neighborhood)
    except ValueError as exc:
        raise CommandError(str(exc), 2) from None


def _normals_for(data, mode):
    """Normals to pass to the estimator, following ``AnnotateOptions.normals``."""
    if mode == "estimate":
        return None
    n = data.normals
    usable = io.usable_normals(n)
    if mode == "file":
        if not usable:
            raise io.MeshFileError(f"{data.path}: --normals file, but the file has no usable "
                                   "per-vertex normals (nx ny nz, finite, non-zero)")
        return n
    # auto: a point cloud's own normals (scanner, MeshLab) beat a PCA guess; for meshes the
    # estimator's own normals are as good and consistently oriented by the faces
    return n if (usable and data.is_point_cloud) else None


def annotate_file(input_path, output_path, options=AnnotateOptions(), preview=None,
                  progress=False):
    """Read ``input_path``, estimate curvatures, write the annotated PLY ``output_path``.

    Returns a dict of summary values (``n_vertices, n_faces, n_valid, radius, seconds``).
    Raises :class:`meshcurv.io.MeshFileError` or ValueError (message names the file) for bad
    input; no output file is left behind then.
    """
    from .api import no_estimate_reason, principal_curvatures

    t0 = time.perf_counter()
    io.check_distinct(input_path, output_path)
    if preview is not None:
        io.check_distinct(input_path, preview)
    data = io.read(input_path)
    n_finite = int(np.isfinite(data.vertices).all(axis=1).sum())
    if n_finite < 4:
        raise io.MeshFileError(f"{input_path}: too few points ({n_finite}) for a curvature "
                               "estimate")
    radius = _radius_in_model_units(options.radius, lambda: io.bbox_diagonal(data.vertices))
    try:
        result = principal_curvatures(
            data.vertices, None if data.is_point_cloud else data.faces,
            normals=_normals_for(data, options.normals), radius=radius,
            n_directions=int(options.directions), neighborhood=options.neighborhood,
            orientation="mst" if options.viewpoint is None else options.viewpoint,
            progress=progress)
    except ValueError as exc:
        raise io.MeshFileError(f"{input_path}: {exc}") from exc
    n_valid = int(result.valid.sum())
    if n_valid == 0:
        raise io.MeshFileError(f"{input_path}: no vertex got a curvature estimate "
                               f"({len(data.vertices)} vertices): "
                               f"{no_estimate_reason(result, n_finite, '--radius')}")
    io.write(output_path, data, result, quality=options.quality, colormap=options.colormap)
    if preview is not None:
        try:
            write_preview(preview, data, result)
        except BaseException:
            os.remove(output_path)  # all or nothing
            raise
    return {"input": os.fspath(input_path), "output": os.fspath(output_path),
            "n_vertices": len(data.vertices),
            "n_faces": 0 if data.is_point_cloud else len(data.faces),
            "n_valid": n_valid, "n_nonfinite": len(data.vertices) - n_finite,
            "radius": result.radius, "seconds": time.perf_counter() - t0}


def write_preview(path, data, result, elev=30.0, azim=-60.0):
    """Render a PNG of the surface coloured by shape index (matplotlib, Agg), atomically.

    Meshes are drawn as shaded triangles, point clouds as points; invalid vertices are grey.
    """
    if io.file_extension(path) != ".png":
        raise io.MeshFileError(f"{path}: the preview must be a .png file")
    try:
        import matplotlib
    except ImportError:
        raise io.MeshFileError(f"{path}: --preview needs matplotlib "
                               "(pip install 'meshcurv[plot]')") from None
    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt
    from matplotlib.colors import LinearSegmentedColormap, Normalize
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    v = data.vertices
    si = np.where(result.valid, result.shape_index, np.nan)
    lo, hi = np.nanmin(v, axis=0), np.nanmax(v, axis=0)
    fig = plt.figure(figsize=(7, 6), dpi=110)
    ax = fig.add_subplot(projection="3d")
    ax.view_init(elev=elev, azim=azim)
    # unit light towards the viewer, from the camera angles, for Lambert shading
    e, a = np.radians(elev), np.radians(azim)
    light = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    if not data.is_point_cloud:
        f = data.faces[np.isfinite(v[data.faces]).all(axis=(1, 2))]
        tri = v[f]
        fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # faces with no valid corner
            face_si = np.nanmean(si[f], axis=1)
        rgb = shape.colorize(face_si, "shape_index").astype(float) / 255.0
        rgb *= (0.35 + 0.65 * np.abs(fn @ light))[:, None]
        ax.add_collection3d(Poly3DCollection(tri, facecolors=rgb, edgecolors="none",
                                             linewidths=0))
    else:
        keep = np.flatnonzero(np.isfinite(v).all(axis=1))
        if len(keep) > 200_000:
            keep = np.sort(np.random.default_rng(0).choice(keep, 200_000, replace=False))
        rgb = shape.colorize(si[keep], "shape_index").astype(float) / 255.0
        ax.scatter(v[keep, 0], v[keep, 1], v[keep, 2], c=rgb, s=2, depthshade=True,
                   linewidths=0)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(np.maximum(hi - lo, 1e-9 * max(float(np.max(hi - lo)), 1.0)))
    ax.set_axis_off()
    lut = shape.colormap_table("turbo") / 255.0
    sm = plt.cm.ScalarMappable(norm=Normalize(-1, 1),
                               cmap=LinearSegmentedColormap.from_list("meshlab_turbo", lut))
    bar = fig.colorbar(sm, ax=ax, shrink=0.6, pad=0.02)
    bar.set_ticks([-1, -0.5, 0, 0.5, 1])
    bar.set_ticklabels(["cup -1", "rut -0.5", "saddle 0", "ridge 0.5", "cap +1"])
    bar.set_label("shape index (outward normals; grey: no estimate)")
    name = os.path.basename(data.path) if data.path else "surface"
    ax.set_title(f"{name}: shape index, radius {result.radius:.4g}")
    try:
        io.atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", bbox_inches="tight"))
    finally:
        plt.close(fig)


# ------------------------------------------------------------------------------------ batch

def _run_one(input_path, output_path, options):
    """Annotate one file; never raises. Returns a dict with ``status`` "ok" or "failed".

    The task both the process pool and Dask workers run: arguments are plain paths and a
    frozen dataclass, so nothing heavy crosses process boundaries.
    """
    try:
        summary = annotate_file(input_path, output_path, options)
        summary["status"] = "ok"
        return summary
    except (ValueError, OSError) as exc:       # io.MeshFileError is a ValueError
        message = io.first_line(exc)
    except Exception as exc:  # a bug, but one bad file must not stop a batch
        message = f"{type(exc).__name__}: {io.first_line(exc)}"
    return {"input": input_path, "output": output_path, "status": "failed", "error": message}


def _expand_inputs(inputs, out_dir=None):
    """Input paths, each as ``(path, from_folder)``; a directory contributes its readable files
    (not recursive), sorted. In a directory that is ``out_dir`` itself, files named like batch
    outputs (``*_curvature.ply``) are left out: they are outputs of an earlier run."""
    out = []
    for p in inputs:
        if os.path.isdir(p):
            is_out_dir = out_dir is not None and os.path.isdir(out_dir) \
                and os.path.samefile(p, out_dir)
            out.extend((os.path.join(p, f), True) for f in sorted(os.listdir(p))
                       if io.file_extension(f) in io.READERS
                       and os.path.isfile(os.path.join(p, f))
                       and not (is_out_dir and f.lower().endswith(_OUTPUT_SUFFIX + ".ply")))
        else:
            out.append((p, False))
    return out


def _file_id(path):
    """``(device, inode)`` of an existing file (hard links and symlinks share it), else None."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_dev, st.st_ino


def _batch_plan(inputs, out_dir):
    """``(inputs, outputs)`` of a batch, absolute paths, in order.

    Outputs are never inputs: a file found in an input folder that is the output of another
    input of this run (same path after resolving symlinks, or the same file) is left out, and a
    run in which an output would be one of its inputs (named on the command line, or reached
    through a link) is refused with CommandError (exit 2) before anything is written.
    """
    listed = [(os.path.abspath(p), from_folder)
              for p, from_folder in _expand_inputs(inputs, out_dir)]
    targets = [output_path_for(p, out_dir) for p, _ in listed]
    target_names = {os.path.realpath(o) for o in targets}
    target_ids = {i for i in map(_file_id, targets) if i is not None}

    def is_output(path):
        return os.path.realpath(path) in target_names or _file_id(path) in target_ids

    kept = [p for p, from_folder in listed if not (from_folder and is_output(p))]
    if not kept:
        raise CommandError(f"no input files in {' '.join(map(str, inputs))} (readable: "
                           f"{', '.join(sorted(io.READERS))}; outputs of this run are not "
                           "inputs)", 2)
    outputs = [output_path_for(p, out_dir) for p in kept]
    seen = {}
    for i, o in zip(kept, outputs):
        if o in seen:
            raise CommandError(f"{i} and {seen[o]} would both write {o}; rename one", 2)
        seen[o] = i
    input_names = {os.path.realpath(p): p for p in kept}
    input_ids = {_file_id(p): p for p in kept}
    input_ids.pop(None, None)
    for i, o in zip(kept, outputs):
        other = input_names.get(os.path.realpath(o)) or input_ids.get(_file_id(o))
        if other is not None:
            raise CommandError(f"{other} is both an input and the output of {i}; leave it "
                               "out or choose another --out-dir", 2)
    return kept, outputs


_OUTPUT_SUFFIX = "_curvature"


def output_path_for(input_path, out_dir, suffix=_OUTPUT_SUFFIX, extension=".ply"):
    """``out_dir/<stem><suffix>.ply`` for an input file."""
    stem = os.path.splitext(os.path.basename(input_path))[0]
    return os.path.join(out_dir, stem + suffix + extension)


@contextlib.contextmanager
def dask_client(scheduler):
    """:func:`meshcurv.tiled.connect`, with a one-line error when dask.distributed is missing
    (an unreachable scheduler raises its one-line OSError)."""
    try:
        import distributed  # noqa: F401
    except ImportError:
        raise CommandError("--dask-scheduler needs dask.distributed "
                           "(pip install 'meshcurv[dask]')", 2) from None
    from .tiled import connect

    with connect(scheduler) as client:
        yield client


class BatchInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a batch: ``done`` of ``total`` files have their output (workers stopped)."""

    def __init__(self, done, total):
        super().__init__(f"{done} of {total} files done")
        self.done, self.total = done, total


def run_batch(inputs, out_dir, options=AnnotateOptions(), jobs=1, overwrite=False,
              scheduler=None, progress=None):
    """Annotate many files; returns a list of per-file result dicts, in input order.

    Each dict has ``input, output, status`` ("ok", "skipped" or "failed") and, for failures,
    ``error``. Outputs that exist are skipped unless ``overwrite`` (writes are atomic, so an
    existing output is complete). Every file runs in a worker process (``jobs`` of them, reused
    from file to file): a file that crashes its process (segmentation fault, out of memory) is
    that file's failure, ``error`` "crashed (signal 11, SIGSEGV)", and the others complete.
    ``scheduler`` (a Dask scheduler address or a ``distributed.Client``) runs the files on a
    Dask cluster whose workers see the same paths: only paths and options travel, never mesh
    data. Outputs are never taken as inputs and never overwrite one (see :func:`_batch_plan`).
    Ctrl-C raises :class:`BatchInterrupted` once the workers are stopped.
    """
    out_dir = os.path.abspath(out_dir)
    inputs, outputs = _batch_plan(inputs, out_dir)
    results = [None] * len(inputs)
    todo = []
    for k, (i, o) in enumerate(zip(inputs, outputs)):
        if os.path.exists(o) and not overwrite:
            results[k] = {"input": i, "output": o, "status": "skipped"}
        else:
            todo.append(k)
    # temporary files of writes killed in an earlier run (outputs that exist are not rewritten)
    io.remove_stale_partials(out_dir, [os.path.basename(o) for o in outputs])
    try:
        if scheduler is not None and todo:
            with dask_client(scheduler) as client:  # connect before creating anything
                _batch_loop(todo, results, out_dir, progress, functools.partial(
                    _batch_dask, client, inputs, outputs, options, todo))
        elif todo:
            _batch_loop(todo, results, out_dir, progress, functools.partial(
                _batch_pool, inputs, outputs, options, todo, jobs=jobs))
    except KeyboardInterrupt:
        done = sum(r is not None and r["status"] in ("ok", "skipped") for r in results)
        raise BatchInterrupted(done, len(inputs)) from None
    return results


def _batch_loop(todo, results, out_dir, progress, run):
    """Create ``out_dir`` and call ``run(record)`` under a progress bar; ``record(k, result)``
    stores file k's result dict in ``results``."""
    from tqdm.auto import tqdm

    os.makedirs(out_dir, exist_ok=True)
    bar = tqdm(total=len(todo), desc="meshcurv batch", unit="file", file=sys.stderr,
               disable=progress is False or (progress is None and not sys.stderr.isatty()))

    def record(k, res):
        results[k] = res
        bar.update(1)
        if res["status"] == "failed":
            bar.write(f"failed: {_failure_text(res)}", file=sys.stderr)

    try:
        run(record)
    finally:
        bar.close()


def _failure_text(res):
    """``<input>: <reason>`` of a failed file (most reasons already start with the file)."""
    error = res["error"]
    return error if error.startswith(res["input"]) else f"{res['input']}: {error}"


def _worker_failure(k, inputs, outputs, exc):
    return {"input": inputs[k], "output": outputs[k], "status": "failed",
            "error": f"worker failed: {type(exc).__name__}: {io.first_line(exc)}"}


def _batch_pool(inputs, outputs, options, todo, record, jobs=1):
    """The pending files on ``jobs`` crash-isolated worker processes (one for a serial run),
    sharing the cores; a file whose worker dies is reported failed with the reason."""
    from .batch import WorkerPool

    if os.name != "posix":  # the worker pipes are POSIX file descriptors: no isolation here
        for k in todo:
            record(k, _run_one(inputs[k], outputs[k], options))
        return
    n_workers = max(1, min(jobs, len(todo)))
    threads = max(1, (os.cpu_count() or 1) // n_workers)
    task = _run_one  # looked up now: the worker imports it by name
    with WorkerPool(n_workers, threads) as pool:
        for k, res, error in pool.run((k, task, (inputs[k], outputs[k], options))
                                      for k in todo):
            if error is not None:
                res = {"input": inputs[k], "output": outputs[k], "status": "failed",
                       "error": error}
            record(k, res)


def _batch_dask(client, inputs, outputs, options, todo, record):
    """The pending files as Dask tasks: file paths travel, data stays on the workers."""
    from distributed import as_completed

    token = time.time_ns()
    futures = {client.submit(_run_one, inputs[k], outputs[k], options, pure=False,
                             key=f"meshcurv-{k}-{os.path.basename(inputs[k])}-{token}"): k
               for k in todo}
    try:
        for fut in as_completed(futures):
            k = futures[fut]
            try:
                res = fut.result()
            except Exception as exc:  # KilledWorker, lost connection, ...
                res = _worker_failure(k, inputs, outputs, exc)
            record(k, res)
    except BaseException:
        client.cancel(list(futures))
        raise


# ------------------------------------------------------------------------------------- info

def info_text(path):
    """Text summary of a file: geometry and, for annotated files, curvature statistics."""
    data = io.read(path)
    n = len(data.vertices)
    kind = "point cloud" if data.is_point_cloud else f"mesh, {len(data.faces)} faces"
    lines = [f"{path}: {n} vertices ({kind}), bounding-box diagonal "
             f"{io.bbox_diagonal(data.vertices):.6g}"]
    if "k1" not in data.fields or "k2" not in data.fields:
        lines.append("not annotated (no k1, k2 vertex properties); "
                     f"run: meshcurv annotate {path} -o OUT.ply")
        return "\n".join(lines)
    valid = (np.asarray(data.fields["valid"]).astype(bool) if "valid" in data.fields
             else np.isfinite(data.fields["k1"]))
    lines.append(f"valid: {int(valid.sum())} of {n} ({100.0 * valid.mean():.1f} %)")
    header = f"{'field':<12}{'min':>12}{'p2':>12}{'median':>12}{'p98':>12}{'max':>12}{'mean':>12}"
    lines.append(header)
    for name in shape.FIELDS:
        if name not in data.fields:
            continue
        x = np.asarray(data.fields[name], dtype=np.float64)[valid]
        x = x[np.isfinite(x)]
        if x.size == 0:
            lines.append(f"{name:<12}{'(no valid values)':>24}")
            continue
        stats = [x.min(), *np.percentile(x, [2, 50, 98]), x.max(), x.mean()]
        lines.append(f"{name:<12}" + "".join(f"{s:>12.5g}" for s in stats))
    if "n_neighbors" in data.fields:
        nb = np.asarray(data.fields["n_neighbors"])[valid]
        if nb.size:
            lines.append(f"neighbours per vertex: median {np.median(nb):.0f}, "
                         f"min {nb.min()}, max {nb.max()}")
    return "\n".join(lines)


# -------------------------------------------------------------------------------- argparse

def _add_estimation_options(p):
    """Options shared by annotate and batch (one place to add new ones)."""
    g = p.add_argument_group("estimation")
    g.add_argument("--radius", "-r", default=None, metavar="R", help=_RADIUS_HELP)
    g.add_argument("--directions", "-d", type=int, default=8, metavar="N",
                   help="planes through the normal; 2 x N circle fits per vertex (default 8)")
    g.add_argument("--neighborhood", choices=("auto", "kring", "ball"), default="auto",
                   help="kring: mesh-connected vertices within R (never crosses thin sheets); "
                        "ball: all points within R; auto: kring for meshes, ball for clouds")
    g.add_argument("--normals", choices=("auto", "file", "estimate"), default="auto",
                   help="auto: a point cloud's own normals if the file has them, else "
                        "estimated (PCA over the neighbourhood, oriented by the faces for "
                        "meshes, by --viewpoint or a spanning tree for clouds); "
                        "file: require the file's normals; estimate: ignore them")
    g.add_argument("--viewpoint", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="orient estimated point-cloud normals towards this point (the scanner "
                        "position, model units); exact and tile-independent, unlike the "
                        "default spanning-tree orientation")
    g = p.add_argument_group("output (PLY; a LAS/LAZ output has no quality or colour)")
    g.add_argument("--quality", choices=shape.FIELDS, default="mean",
                   help="field copied to the PLY 'quality' property and coloured (default mean)")
    g.add_argument("--colormap", default="Turbo", metavar="NAME",
                   help=f"colour ramp, MeshLab's names: {', '.join(shape.COLORMAPS)} "
                        "(default Turbo; shape index on [-1, 1], other fields clamped at the "
                        "2nd/98th percentile)")


def _positive_float(text):
    """argparse type: a positive finite number (model units)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number in model units, got {text!r}")
    if not (np.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def _options_from(args):
    return AnnotateOptions(radius=args.radius, directions=args.directions,
                           neighborhood=args.neighborhood, normals=args.normals,
                           quality=args.quality, colormap=args.colormap,
                           viewpoint=None if args.viewpoint is None else tuple(args.viewpoint))


def build_parser():
    """The argparse parser of the ``meshcurv`` command."""
    from . import __version__

    parser = argparse.ArgumentParser(
        prog="meshcurv", description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"meshcurv {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    readable = ", ".join(sorted(io.READERS))

    p = sub.add_parser(
        "annotate", help="write a PLY (or LAS/LAZ) with per-vertex curvature fields",
        description=_DESCRIPTION + f"\n\nReads {readable}.\nWrites (atomically; the output "
        "directory is created) a binary little-endian PLY with float64\nvertex properties "
        "k1 k2 mean gaussian shape_index curvedness, valid (uint8),\nd1x d1y d1z d2x d2y d2z "
        "(unit principal directions), nx ny nz, n_neighbors n_samples (int32),\nresidual, "
        "quality (the --quality field, 0 where invalid) and red green blue (uint8, the\n"
        "--colormap ramp over it), plus the faces. A .las/.laz output (from a .las/.laz input) "
        "keeps\nevery point record and adds k1 .. d2z as extra-bytes dimensions; with "
        "--tile-size or\n--dask-scheduler the cloud is processed in tiles on Dask.\n\nExamples:\n"
        "  meshcurv annotate examples/torus.ply -o out/torus_curvature.ply "
        "--preview out/torus_shape_index.png\n"
        "  meshcurv annotate scan.xyz -o scan_curvature.ply --radius 2% --quality shape_index\n"
        "  meshcurv annotate scan.laz -o scan_curvature.laz --radius 0.5 --tile-size 50",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("input", help=f"mesh or point cloud ({readable})")
    p.add_argument("-o", "--output", required=True,
                   help="annotated output: .ply, or .las/.laz for a .las/.laz input")
    p.add_argument("--preview", metavar="PNG", default=None,
                   help="also render a PNG coloured by shape index (needs matplotlib)")
    p.add_argument("--progress", action="store_true",
                   help="show progress bars (a tiled run shows them whenever stderr is a "
                   "terminal)")
    g = p.add_argument_group(
        "large LAS/LAZ clouds (tiled on Dask; input and output .las or .laz)")
    g.add_argument("--tile-size", type=_positive_float, default=None, metavar="S",
                   help="cut the cloud into S x S tiles (model units, in x and y) with a halo "
                        "of one radius and estimate them as Dask tasks; the result is written "
                        "in input order (default with --dask-scheduler: about 10^6 points per "
                        "tile). Needs the dask and las extras")
    g.add_argument("--dask-scheduler", metavar="ADDRESS", default=None,
                   help="run the tiles on this Dask scheduler (tcp://host:8786; workers must "
                        "see the input and output paths); without it --tile-size starts a "
                        "local cluster")
    _add_estimation_options(p)

    p = sub.add_parser(
        "batch", help="annotate many files (resumable, parallel, optionally on Dask)",
        description=_DESCRIPTION + "\n\nWrites OUT_DIR/<name>_curvature.ply per input; files "
        "whose output exists are skipped (re-run to resume); a failing file is reported and "
        "the batch goes on, also when it crashes its process (each file runs in a worker "
        "process, one per job); the exit code is 1 if any file failed.\n\nOutputs are never "
        "inputs: a file in an input folder that is the output of another input of the run is "
        "skipped, and so is every *_curvature.ply when the input folder is OUT_DIR itself; a "
        "run in which an output would replace one of its inputs is refused.",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("inputs", nargs="+", help="input files or directories (their readable files)")
    p.add_argument("--out-dir", "-O", required=True, help="directory for the annotated PLYs")
    p.add_argument("--jobs", "-j", type=int, default=1, help="parallel processes (default 1)")
    p.add_argument("--overwrite", action="store_true", help="recompute existing outputs")
    p.add_argument("--dask-scheduler", metavar="ADDRESS", default=None,
                   help="run on a Dask distributed cluster (e.g. tcp://host:8786); the "
                        "workers must see the same file paths")
    _add_estimation_options(p)

    p = sub.add_parser("info", help="curvature statistics of an annotated file",
                       description="Print geometry and, for an annotated PLY, statistics of "
                                   "each curvature field over the valid vertices.")
    p.add_argument("file")
    return parser


def _las_bbox_diagonal(path):
    """Bounding-box diagonal from a LAS/LAZ header (for ``--radius 2%`` on tiled runs)."""
    from .las import open_las

    with open_las(path) as reader:
        lo = np.asarray(reader.header.mins, float)
        hi = np.asarray(reader.header.maxs, float)
    return float(np.linalg.norm(hi - lo))


def _check_las_output(in_path, out_path):
    """Before any work on a LAS/LAZ output: refuse an input that already has curvature
    dimensions, and say when the output gets another LAS version than the input (1.0)."""
    las = io.las_module(in_path)
    las.check_annotatable(in_path)
    version_in, version_out = las.output_version(in_path)
    if version_out != version_in:
        print(f"meshcurv: note: {in_path} is LAS {version_in}, which laspy cannot write; "
              f"{out_path} will be LAS {version_out} with the same point format and "
              "dimensions", file=sys.stderr)


def _cmd_annotate_tiled(args, options):
    """``annotate --tile-size/--dask-scheduler``: hand the LAS/LAZ file to annotate_tiled."""
    las_ext = (".las", ".laz")
    for path, what in ((args.input, "input"), (args.output, "output")):
        if io.file_extension(path) not in las_ext:
            raise CommandError(f"{path}: --tile-size and --dask-scheduler need a .las or .laz "
                               f"{what} (for many mesh files use: meshcurv batch "
                               "--dask-scheduler)", 2)
    if args.preview is not None:
        raise CommandError("--preview is not available with --tile-size/--dask-scheduler "
                           "(the cloud is never in memory as a whole)", 2)
    if options.neighborhood == "kring":
        raise CommandError("--neighborhood kring needs mesh faces; a LAS/LAZ cloud uses ball", 2)
    if options.normals != "auto":
        raise CommandError("--normals: tiled runs use the file's normals when it has them and "
                           "estimate them otherwise (--normals auto)", 2)
    if not os.path.isfile(args.input):
        raise io.MeshFileError(f"{args.input}: no such file")
    _check_las_output(args.input, args.output)
    try:
        from .tiled import TileError, annotate_tiled
    except ImportError as exc:
        raise CommandError(f"--tile-size/--dask-scheduler need dask.distributed and laspy "
                           f"(pip install 'meshcurv[dask,las]'): {exc}", 2) from None
    radius = _radius_in_model_units(options.radius, lambda: _las_bbox_diagonal(args.input))
    with contextlib.ExitStack() as stack:
        # connect first: an unreachable scheduler then leaves no work folder behind
        client = (None if args.dask_scheduler is None
                  else stack.enter_context(dask_client(args.dask_scheduler)))
        try:
            report = annotate_tiled(args.input, args.output, radius=radius,
                                    tile_size=args.tile_size, scheduler=client,
                                    progress=bool(args.progress or sys.stderr.isatty()),
                                    n_directions=int(options.directions),
                                    neighborhood=options.neighborhood,
                                    orientation=("mst" if options.viewpoint is None
                                                 else options.viewpoint))
        except TileError as exc:
            raise CommandError(f"{io.first_line(exc)} (finished tiles are kept "
                               f"in {args.output}.meshcurv-work; re-run to resume)") from None
        except KeyboardInterrupt:
            work = f"{args.output}.meshcurv-work"
            print("meshcurv: interrupted" + (f"; finished tiles are kept in {work}, re-run to "
                                             "resume" if os.path.isdir(work) else ""),
                  file=sys.stderr)
            return 130
    print(f"{args.output}: {report.n_points} points in {report.n_tiles} tiles of side "
          f"{report.tile_size:.6g} (model units), radius {report.radius:.6g} (model units), "
          f"{report.seconds:.1f} s")
    return 0


def _cmd_annotate(args):
    options = _options_from(args)
    _check_options(options)
    if args.tile_size is not None or args.dask_scheduler is not None:
        return _cmd_annotate_tiled(args, options)
    if io.file_extension(args.output) not in io.WRITERS:
        raise CommandError(f"{args.output}: output must be one of "
                           f"{', '.join(sorted(io.WRITERS))}", 2)
    if args.preview is not None and io.file_extension(args.preview) != ".png":
        raise CommandError(f"{args.preview}: --preview must be a .png file", 2)
    las_ext = (".las", ".laz")
    if io.file_extension(args.output) in las_ext and io.file_extension(args.input) not in las_ext:
        raise CommandError(f"{args.output}: LAS/LAZ output needs a LAS/LAZ input (its points "
                           "are copied with added curvature fields); write .ply", 2)
    try:
        io.check_distinct(args.input, args.output)
    except io.MeshFileError as exc:
        raise CommandError(str(exc), 2) from None
    if io.file_extension(args.output) in las_ext and os.path.isfile(args.input):
        _check_las_output(args.input, args.output)
    s = annotate_file(args.input, args.output, options, preview=args.preview,
                      progress=args.progress)
    if s["n_nonfinite"]:
        print(f"meshcurv: warning: {s['n_nonfinite']} vertices have non-finite coordinates; "
              "their curvature is NaN", file=sys.stderr)
    print(f"{s['output']}: {s['n_valid']} of {s['n_vertices']} vertices estimated, radius "
          f"{s['radius']:.6g} (model units), {s['seconds']:.1f} s")
    if args.preview:
        print(f"{args.preview}: preview coloured by shape index")
    return 0


def _cmd_batch(args):
    options = _options_from(args)
    _check_options(options)
    if args.jobs < 1:
        raise CommandError("--jobs must be at least 1", 2)
    try:
        results = run_batch(args.inputs, args.out_dir, options, jobs=args.jobs,
                            overwrite=args.overwrite, scheduler=args.dask_scheduler)
    except BatchInterrupted as exc:
        print(f"meshcurv: interrupted; {exc.done} of {exc.total} files done, rerun to resume",
              file=sys.stderr)
        return 130
    counts = {s: sum(r["status"] == s for r in results) for s in ("ok", "skipped", "failed")}
    print(f"meshcurv batch: {counts['ok']} annotated, {counts['skipped']} skipped (output "
          f"exists), {counts['failed']} failed, in {args.out_dir}")
    for r in results:
        if r["status"] == "failed":
            print(f"  FAILED {_failure_text(r)}", file=sys.stderr)
    return 1 if counts["failed"] else 0


def _cmd_info(args):
    print(info_text(args.file))
    return 0


_COMMANDS = {"annotate": _cmd_annotate, "batch": _cmd_batch, "info": _cmd_info}


def main(argv=None):
    """Entry point of the ``meshcurv`` console script; returns the exit code."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command in ("annotate", "batch"):
        from .fit import fused

        if not fused.cache_is_warm():
            print("meshcurv: compiling the numba kernels (first run after installing, about "
                  "30 s; cached afterwards)", file=sys.stderr)
    try:
        return _COMMANDS[args.command](args)
    except CommandError as exc:
        print(f"meshcurv: error: {exc}", file=sys.stderr)
        return exc.code
    except (io.MeshFileError, ValueError, OSError) as exc:
        print(f"meshcurv: error: {io.first_line(exc)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("meshcurv: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
