"""``meshcurv annotate --tile-size/--dask-scheduler``: the checks of a tiled LAS/LAZ run and the
call of :func:`meshcurv.tiled.annotate_tiled`."""

import contextlib
import os
import sys

import numpy as np

from .. import io
from .annotate import (CommandError, is_auto_radius, is_radius_list, orientation_for,
                       orientation_line, radius_in_model_units)
from .batch import dask_client

__all__ = ["annotate_tiled_command", "check_las_output"]


def _las_bbox_diagonal(path):
    """Bounding-box diagonal from a LAS/LAZ header (for ``--radius 2%`` on tiled runs)."""
    from ..io.las import open_las

    with open_las(path) as reader:
        lo = np.asarray(reader.header.mins, float)
        hi = np.asarray(reader.header.maxs, float)
    return float(np.linalg.norm(hi - lo))


def check_las_output(in_path, out_path, suffixes=None):
    """Before any work on a LAS/LAZ output: refuse an input that already has the curvature
    dimensions to be added (named with ``suffixes`` for several radii, see
    :func:`meshcurv.io.las.check_annotatable`), and say when the output gets another LAS
    version than the input (1.0)."""
    las = io.las_module(in_path)
    with las.open_las(in_path) as reader:  # one header read for both checks
        header = reader.header
    las.check_annotatable(in_path, header=header, suffixes=suffixes)
    version_in, version_out = las.output_version(header)
    if version_out != version_in:
        print(f"meshcurv: note: {in_path} is LAS {version_in}, which laspy cannot write; "
              f"{out_path} will be LAS {version_out} with the same point format and "
              "dimensions", file=sys.stderr)


def _check_tiled_arguments(args, options):
    """Raise CommandError (exit 2) for what a tiled run cannot do, before any file is read."""
    for path, what in ((args.input, "input"), (args.output, "output")):
        if not io.las.is_las(path):
            raise CommandError(f"{path}: --tile-size and --dask-scheduler need a .las or .laz "
                               f"{what} (for many mesh files use: meshcurv batch "
                               "--dask-scheduler)", 2)
    if args.preview is not None:
        raise CommandError("--preview is not available with --tile-size/--dask-scheduler "
                           "(the cloud is never in memory as a whole)", 2)
    if options.neighborhood == "kring":
        raise CommandError("--neighborhood kring needs mesh faces; a LAS/LAZ cloud uses ball", 2)
    if is_radius_list(options.radius):
        raise CommandError("--tile-size and --dask-scheduler take one --radius, not a list "
                           "(annotate without them for several radii, or once per radius)", 2)
    if is_auto_radius(options.radius):
        raise CommandError("--radius auto is not available with --tile-size/--dask-scheduler "
                           "(the tiles' halo is made for one radius); give a radius", 2)
    if options.normals != "auto":
        raise CommandError("--normals: tiled runs use the file's normals when it has them and "
                           "estimate them otherwise (--normals auto)", 2)


def annotate_tiled_command(args, options):
    """``annotate --tile-size/--dask-scheduler``: hand the LAS/LAZ file to annotate_tiled.

    ``args``: the parsed command line; ``options``: its :class:`AnnotateOptions`, checked.
    Returns the exit code (130 after Ctrl-C); raises CommandError or MeshFileError.
    """
    _check_tiled_arguments(args, options)
    if not os.path.isfile(args.input):
        raise io.MeshFileError(f"{args.input}: no such file")
    check_las_output(args.input, args.output)
    try:
        from ..tiled import TileError, annotate_tiled
    except ImportError as exc:
        raise CommandError(f"--tile-size/--dask-scheduler need dask.distributed and laspy "
                           f"(pip install 'meshcurv[dask,las]'): {exc}", 2) from None
    radius = radius_in_model_units(options.radius, lambda: _las_bbox_diagonal(args.input))
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
                                    orientation=orientation_for(args.input, options))
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
    if report.orientation is not None:
        print(orientation_line(report.orientation, args.input, options))
    return 0

