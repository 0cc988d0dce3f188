"""The ``meshcurv`` command: annotate files with principal curvatures, in batches, and inspect them.

Subcommands ``annotate``, ``batch`` and ``info``; run ``meshcurv --help``. Exit codes: 0 success,
1 a file could not be processed (or, for ``batch``, at least one failed), 2 command-line error.
Expected errors print one line ``meshcurv: error: ...`` on stderr and leave no output file.

This module holds the parser and the subcommands' glue; the work is in :mod:`.annotate` (one
file), :mod:`.batch` (many files, crash-isolated workers), :mod:`.tiles` (tiled LAS/LAZ runs)
and :mod:`.info`.
"""

import argparse
import os
import sys

import numpy as np

from .. import io, shape
from .annotate import AnnotateOptions, CommandError, annotate_file, check_annotate_options, \
    orientation_line, radius_suffixes
from .batch import BatchInterrupted, failure_text, run_batch
from .info import info_text
from .tiles import annotate_tiled_command, check_las_output

__all__ = ["main", "build_parser", "AnnotateOptions", "annotate_file", "run_batch", "info_text"]

_DESCRIPTION = """\
Principal curvatures of meshes and point clouds by CGA circle fits (Seibert et al.).

Units: k1, k2, mean and curvedness in 1/model units, gaussian in 1/model units^2, shape index
without unit in [-1, 1] (+1 cap, +0.5 ridge, 0 saddle, -0.5 rut, -1 cup).
Sign: for OUTWARD normals, convex positive: a sphere of radius r gives k1 = k2 = +1/r, mean
+1/r, shape index +1; k1 >= k2 always. Meshes take the orientation of their faces
(counter-clockwise seen from outside); point clouds use their normals or estimate and orient
them (flip the cloud's normals to flip every sign).
Radius: in model units (--radius 0.05) or in percent of the bounding-box diagonal (--radius 2%),
as in MeshLab; default: the radius whose ball holds about 100 points (smaller where the
sampling is coarse for the shape, so that a ball stays on a local patch: a low-poly torus);
with it (and with auto), where the data are clean and finely sampled, each row moves towards a
quartic fitted over the vertex's 3-ring (a cloud point's 36 nearest) as far as that fit is
measurably the more accurate (field jet_share); a radius given keeps the circle fits alone.
A list (--radius 0.5,1,2)
estimates at every radius in one pass and names each radius's fields with a suffix: k1_r0p5,
k1_r1, k1_r2 ("." written "p", "-" "m", "%" "pct": k1_r2pct), so that the names stay
identifiers in PDAL, laspy and Python; normals, quality and colour are the first radius's.
--radius auto: each vertex takes the radius (0.7 to 2.8 times the default) that minimises its
estimated error (noise and bias); clean data and inputs coarse for their shape keep the
default radius; the field radius_used (model units) says which.
Vertices are never reordered, merged or dropped (STL corners are merged by position on reading);
vertices without an estimate have NaN curvature, valid = 0, quality 0 and a grey colour.

Exit codes: 0 success, 1 a file could not be processed, 2 command-line error."""


_RADIUS_HELP = ("neighborhood radius: a number in model units (0.05) or a percentage of the "
                "bounding-box diagonal (2%%); default: the radius whose ball holds ~100 points. "
                "A comma-separated list (0.5,1,2) writes the fields of every radius, named "
                "k1_r0p5, k1_r1, k1_r2 ...; auto: a radius per vertex (field radius_used)")


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
                        "estimated (PCA over the neighborhood, oriented by the faces for "
                        "meshes, by --viewpoint, +z or a spanning tree for clouds); "
                        "file: require the file's normals; estimate: ignore them")
    g.add_argument("--viewpoint", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                   help="orient estimated point-cloud normals towards this point (the scanner "
                        "position, model units). Default: towards +z for LAS/LAZ input (seen "
                        "from above); other clouds along a spanning tree, each connected piece "
                        "outward if it is closed, towards +z if it is open")
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
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="meshcurv", description=_DESCRIPTION,
        formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"meshcurv {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    _add_annotate_parser(sub)
    _add_batch_parser(sub)
    p = sub.add_parser("info", help="curvature statistics of an annotated file",
                       description="Print geometry and, for an annotated PLY, statistics of "
                                   "each curvature field over the valid vertices.")
    p.add_argument("file")
    return parser


def _add_annotate_parser(sub):
    """The ``annotate`` subcommand."""
    readable = ", ".join(sorted(io.READERS))
    p = sub.add_parser(
        "annotate", help="write a PLY (or LAS/LAZ) with per-vertex curvature fields",
        description=_DESCRIPTION + f"\n\nReads {readable}.\nWrites (atomically; the output "
        "directory is created) a binary little-endian PLY with float64\nvertex properties "
        "k1 k2 mean gaussian shape_index curvedness, valid (uint8),\nd1x d1y d1z d2x d2y d2z "
        "(unit principal directions), n_neighbors n_samples (int32), residual\n(each named "
        "scalar_<field>, as CloudCompare loads it: scalar_k1 ...), nx ny nz, quality\n(the "
        "--quality field, 0 where invalid) and red green blue (uint8, the --colormap\nramp "
        "over it), plus the faces; the input's other vertex properties are kept (its own\n"
        "colour and quality as scalar_red scalar_green scalar_blue scalar_quality).\n"
        "A .las/.laz output (from a .las/.laz input) keeps "
        "every point record and adds\nk1 .. d2z as extra-bytes dimensions; with "
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
                        "of a few radii and estimate them as Dask tasks; the result is written "
                        "in input order (default with --dask-scheduler: about 10^6 points per "
                        "tile). Needs the dask and las extras")
    g.add_argument("--dask-scheduler", metavar="ADDRESS", default=None,
                   help="run the tiles on this Dask scheduler (tcp://host:8786; workers must "
                        "see the input and output paths); without it --tile-size starts a "
                        "local cluster")
    _add_estimation_options(p)


def _add_batch_parser(sub):
    """The ``batch`` subcommand."""
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
    p.add_argument("--jobs", "-j", type=int, default=1, help="parallel processes (default 1), each with cores / JOBS "
                   "numba threads (at least 1; NUMBA_NUM_THREADS, if set, is each one's count)")
    p.add_argument("--overwrite", action="store_true", help="recompute existing outputs")
    p.add_argument("--dask-scheduler", metavar="ADDRESS", default=None,
                   help="run on a Dask distributed cluster (e.g. tcp://host:8786); the "
                        "workers must see the same file paths")
    _add_estimation_options(p)


def _cmd_annotate(args):
    options = _options_from(args)
    check_annotate_options(options)
    if args.tile_size is not None or args.dask_scheduler is not None:
        return annotate_tiled_command(args, options)
    if io.file_extension(args.output) not in io.WRITERS:
        raise CommandError(f"{args.output}: output must be one of "
                           f"{', '.join(sorted(io.WRITERS))}", 2)
    if args.preview is not None and io.file_extension(args.preview) != ".png":
        raise CommandError(f"{args.preview}: --preview must be a .png file", 2)
    if io.las.is_las(args.output) and not io.las.is_las(args.input):
        raise CommandError(f"{args.output}: LAS/LAZ output needs a LAS/LAZ input (its points "
                           "are copied with added curvature fields); write .ply", 2)
    try:
        io.check_distinct(args.input, args.output)
    except io.MeshFileError as exc:
        raise CommandError(str(exc), 2) from None
    if io.las.is_las(args.output):
        suffixes = radius_suffixes(options.radius)
        try:  # a radius too long for LAS names is the command line's error
            io.las.new_dimension_names(suffixes)
        except ValueError as exc:
            raise CommandError(str(exc), 2) from None
        if os.path.isfile(args.input):
            check_las_output(args.input, args.output, suffixes)
    s = annotate_file(args.input, args.output, options, preview=args.preview,
                      progress=args.progress)
    if s["n_nonfinite"]:
        print(f"meshcurv: warning: {s['n_nonfinite']} vertices have non-finite coordinates; "
              "their curvature is NaN", file=sys.stderr)
    for note in s["not_carried"]:
        print(f"meshcurv: warning: {args.input}: {note}", file=sys.stderr)
    print(_summary_line(s))
    print(orientation_line(s["orientation"], args.input, options))
    if args.preview:
        print(f"{args.preview}: preview coloured by shape index")
    return 0


def _summary_line(s):
    """The line ``annotate`` prints for the summary ``s`` of :func:`annotate_file`."""
    if s["suffixes"] is None:
        used = s.get("radius_used")
        radius = (f"radius {s['radius']:.6g} (model units)" if used is None else
                  f"radius per vertex {used[0]:.6g} .. {used[1]:.6g} (model units; field "
                  f"radius_used)")
        return (f"{s['output']}: {s['n_valid']} of {s['n_vertices']} vertices estimated, "
                f"{radius}, {s['seconds']:.1f} s")
    per_radius = [f"{n} at radius {r:.6g} (*{suffix})" for n, r, suffix in
                  zip(s["n_valid_per_radius"], s["radii"], s["suffixes"])]
    return (f"{s['output']}: of {s['n_vertices']} vertices, estimated {', '.join(per_radius)} "
            f"(model units; fields k1{s['suffixes'][0]} ...), {s['seconds']:.1f} s")


def _cmd_batch(args):
    options = _options_from(args)
    check_annotate_options(options)
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
            print(f"  FAILED {failure_text(r)}", file=sys.stderr)
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
        from ..fit import fused

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
