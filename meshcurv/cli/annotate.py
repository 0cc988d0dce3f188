"""``meshcurv annotate`` for one file: options, radius parsing, the annotation and its PNG preview.

:func:`annotate_file` reads a mesh or point cloud, estimates principal curvatures and writes the
annotated file (atomically); :func:`write_preview` renders a PNG coloured by shape index.
"""

import os
import time
import warnings
from dataclasses import dataclass

import numpy as np

from .. import io, shape
from ..options import check_options

__all__ = ["CommandError", "AnnotateOptions", "parse_radius", "parse_radius_list",
           "is_radius_list", "is_auto_radius", "radius_in_model_units", "radius_suffixes",
           "check_annotate_options", "orientation_for", "orientation_line", "annotate_file",
           "write_preview"]


class CommandError(Exception):
    """An expected error with a one-line message and an exit code."""

    def __init__(self, message, code=1):
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class AnnotateOptions:
    """Estimation and output options shared by ``annotate`` and ``batch`` (picklable).

    radius : str or None, "2%" (of the bbox diagonal) or "0.05" (model units), or a comma-
        separated list of them ("0.5,1,2": every radius, fields named per radius, see
        :func:`radius_suffixes`), or "auto" (each vertex its own radius, written as the field
        ``radius_used``); None = default
    directions : int, planes through the normal (2 x directions circle fits)
    neighborhood : "auto" | "kring" | "ball"
    normals : "auto" (file normals for point clouds that have them, else estimated) |
        "file" (require normals in the file) | "estimate" (ignore file normals)
    quality : field written to ``quality`` and coloured
    colormap : MeshLab colour map name, see :data:`meshcurv.shape.COLORMAPS`
    viewpoint : (3,) tuple or None, orient estimated point-cloud normals towards this point
        (a scanner position) instead of the default (:func:`orientation_for`)
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


def parse_radius_list(text):
    """Parse a radius option that may list several radii: ``"0.5,2%"`` -> [(0.5, False),
    (2.0, True)]; one radius without a comma -> [(value, percent)].

    Raises ValueError (one line) for an empty item, an item :func:`parse_radius` refuses, or
    a radius listed twice (0.5 and 5e-1 are the same radius: their fields would have the
    same names).
    """
    items = str(text).split(",")
    if len(items) > 1 and not all(item.strip() for item in items):
        raise ValueError(f"radius list has an empty item, got {text!r}")
    radii = [parse_radius(item) for item in items]
    suffixes = [io.radius_suffix(value, percent) for value, percent in radii]
    for i, suffix in enumerate(suffixes):
        if suffix in suffixes[:i]:
            raise ValueError(f"radius list names the radius {items[i].strip()} twice, got "
                             f"{text!r}")
    return radii


def is_radius_list(spec):
    """Whether the radius option ``spec`` (str or None) lists several radii."""
    return spec is not None and "," in str(spec)


def is_auto_radius(spec):
    """Whether the radius option ``spec`` (str or None) asks for the per-vertex scale."""
    return spec is not None and str(spec).strip().lower() == "auto"


def radius_in_model_units(spec, diagonal):
    """Absolute radius for ``spec`` ("2%", "0.05" or None = the estimator's default), or the
    list of them for a list ("0.5,2%"), or "auto" (per-vertex scale); ``diagonal()`` gives the
    bounding-box diagonal a percentage refers to."""
    if spec is None:
        return None
    if is_auto_radius(spec):
        return "auto"
    radii = parse_radius_list(spec)
    diag = diagonal() if any(percent for _, percent in radii) else None
    absolute = [value / 100.0 * diag if percent else value for value, percent in radii]
    return absolute if is_radius_list(spec) else absolute[0]


def radius_suffixes(spec):
    """The suffix naming each radius's fields in the output for a list ``spec`` ("0.5,1,2%"
    -> ["_r0p5", "_r1", "_r2pct"], see :func:`meshcurv.io.radius_suffix`); None for one
    radius, whose fields keep their plain names (``k1``)."""
    if not is_radius_list(spec):
        return None
    return [io.radius_suffix(value, percent) for value, percent in parse_radius_list(spec)]


def orientation_for(input_path, options):
    """The estimator's ``orientation`` for this input: the ``--viewpoint`` if given; else "+z"
    for LAS/LAZ (airborne scans are seen from above: every normal up, as PDAL and CloudCompare
    do), else "mst" (one sign per connected piece: outward if closed, towards +z if open)."""
    if options.viewpoint is not None:
        return options.viewpoint
    return "+z" if io.las.is_las(input_path) else "mst"


def orientation_line(note, input_path, options):
    """The one line telling the user how the normals got their sign: ``note`` is
    ``CurvatureResult.orientation`` of the run on ``input_path`` with ``options``."""
    if note.startswith("as given"):
        return "meshcurv: normals taken from the file as they are" + note[len("as given"):]
    if note.startswith("oriented like the faces") or options.viewpoint is not None:
        return f"meshcurv: normals {note}"
    why = "LAS input; " if orientation_for(input_path, options) == "+z" else ""
    return f"meshcurv: normals {note} ({why}--viewpoint to change)"


def check_annotate_options(options):
    """Raise CommandError(code 2) for option values no file can fix."""
    try:
        if options.radius is not None and not is_auto_radius(options.radius):
            parse_radius_list(options.radius)
        if options.quality not in shape.FIELDS:
            raise ValueError(f"--quality must be one of {', '.join(shape.FIELDS)}")
        if options.colormap.lower() not in (c.lower() for c in shape.COLORMAPS):
            raise ValueError(f"--colormap must be one of {', '.join(shape.COLORMAPS)}")
        check_options(n_directions=options.directions, neighborhood=options.neighborhood,
                      orientation=orientation_for("", options))
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

    With a list of radii (``options.radius`` "0.5,1,2"), one estimate per radius (one ball
    search over the largest), each radius's fields named with its suffix
    (:func:`radius_suffixes`); the normals, quality, colour and preview are the first radius's.

    Returns a dict of summary values (``n_vertices, n_faces, n_valid, radius, seconds`` and
    ``orientation``, the result's note on how the normals got their sign; ``not_carried``,
    one line each on what of the input the output cannot hold (:attr:`MeshData.notes`);
    ``radii``,
    ``n_valid_per_radius`` and ``suffixes`` list every radius, ``suffixes`` None for one
    radius; ``n_valid``, ``radius`` and ``orientation`` are the first radius's).
    Raises :class:`meshcurv.io.MeshFileError` or ValueError (message names the file) for bad
    input; no output file is left behind then.
    """
    from ..api import no_estimate_reason, principal_curvatures

    t0 = time.perf_counter()
    io.check_distinct(input_path, output_path)
    if preview is not None:
        io.check_distinct(input_path, preview)
    data = io.read(input_path)
    n_finite = int(np.isfinite(data.vertices).all(axis=1).sum())
    if n_finite < 4:
        raise io.MeshFileError(f"{input_path}: too few points ({n_finite}) for a curvature "
                               "estimate")
    radius = radius_in_model_units(options.radius, lambda: io.bbox_diagonal(data.vertices))
    suffixes = radius_suffixes(options.radius)
    try:
        results = principal_curvatures(
            data.vertices, None if data.is_point_cloud else data.faces,
            normals=_normals_for(data, options.normals), radius=radius,
            n_directions=int(options.directions), neighborhood=options.neighborhood,
            orientation=orientation_for(input_path, options), progress=progress)
    except ValueError as exc:
        raise io.MeshFileError(f"{input_path}: {exc}") from exc
    if suffixes is None:
        results = [results]
    n_valid = [int(res.valid.sum()) for res in results]
    for res, count in zip(results, n_valid):
        if count == 0:
            at = f" at radius {res.radius:.6g}" if suffixes is not None else ""
            raise io.MeshFileError(f"{input_path}: no vertex got a curvature estimate{at} "
                                   f"({len(data.vertices)} vertices): "
                                   f"{no_estimate_reason(res, n_finite, '--radius')}")
    result = results[0]
    if suffixes is None:
        io.write(output_path, data, result, quality=options.quality, colormap=options.colormap)
    else:
        io.write(output_path, data, results, quality=options.quality,
                 colormap=options.colormap, suffixes=suffixes)
    if preview is not None:
        try:
            write_preview(preview, data, result)
        except BaseException:
            os.remove(output_path)  # all or nothing
            raise
    return {"input": os.fspath(input_path), "output": os.fspath(output_path),
            # a LAS/LAZ output copies every dimension of its LAS/LAZ input
            "not_carried": [] if io.las.is_las(output_path) else list(data.notes),
            "n_vertices": len(data.vertices),
            "n_faces": 0 if data.is_point_cloud else len(data.faces),
            "n_valid": n_valid[0], "n_nonfinite": len(data.vertices) - n_finite,
            "radius": result.radius, "orientation": result.orientation,
            "radii": [res.radius for res in results], "n_valid_per_radius": n_valid,
            "suffixes": suffixes, "radius_used": _radius_range(result),
            "seconds": time.perf_counter() - t0}


def _radius_range(result):
    """(smallest, largest) ``radius_used`` of the valid rows, None where every row has the
    one radius ``result.radius`` (or none is valid)."""
    if result.radius_used is None:
        return None
    used = np.asarray(result.radius_used, dtype=np.float64)
    used = used[np.isfinite(used)]
    if not len(used) or np.all(used == result.radius):
        return None
    return float(used.min()), float(used.max())


def write_preview(path, data, result, elev=30.0, azim=-60.0):
    """Render a PNG of the surface coloured by shape index (matplotlib, Agg), atomically.

    Meshes are drawn as shaded triangles, point clouds as points; invalid vertices are grey.
    ``elev``, ``azim``: camera angles in degrees (matplotlib's ``view_init``).
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

    v = data.vertices
    si = np.where(result.valid, result.shape_index, np.nan)
    lo, hi = np.nanmin(v, axis=0), np.nanmax(v, axis=0)
    fig = plt.figure(figsize=(7, 6), dpi=110)
    ax = fig.add_subplot(projection="3d")
    ax.view_init(elev=elev, azim=azim)
    if not data.is_point_cloud:
        _draw_faces(ax, v, data.faces, si, elev, azim)
    else:
        _draw_points(ax, v, si)
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_zlim(lo[2], hi[2])
    ax.set_box_aspect(np.maximum(hi - lo, 1e-9 * max(float(np.max(hi - lo)), 1.0)))
    ax.set_axis_off()
    _shape_index_bar(fig, ax)
    name = os.path.basename(data.path) if data.path else "surface"
    ax.set_title(f"{name}: shape index, radius {result.radius:.4g}")
    try:
        io.atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", bbox_inches="tight"))
    finally:
        plt.close(fig)


def _draw_faces(ax, v, faces, si, elev, azim):
    """Triangles with finite corners, coloured by the mean shape index ``si`` (n,) of their
    corners and Lambert-shaded by a light towards the camera (angles in degrees)."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    e, a = np.radians(elev), np.radians(azim)
    light = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
    f = faces[np.isfinite(v[faces]).all(axis=(1, 2))]
    tri = v[f]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    fn /= np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-300)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # faces with no valid corner
        face_si = np.nanmean(si[f], axis=1)
    rgb = shape.colorize(face_si, "shape_index").astype(float) / 255.0
    rgb *= (0.35 + 0.65 * np.abs(fn @ light))[:, None]
    ax.add_collection3d(Poly3DCollection(tri, facecolors=rgb, edgecolors="none", linewidths=0))


def _draw_points(ax, v, si, most=200_000):
    """The finite points of ``v`` (n, 3) coloured by shape index ``si`` (n,); at most ``most``
    of them (a fixed random sample)."""
    keep = np.flatnonzero(np.isfinite(v).all(axis=1))
    if len(keep) > most:
        keep = np.sort(np.random.default_rng(0).choice(keep, most, replace=False))
    rgb = shape.colorize(si[keep], "shape_index").astype(float) / 255.0
    ax.scatter(v[keep, 0], v[keep, 1], v[keep, 2], c=rgb, s=2, depthshade=True, linewidths=0)


def _shape_index_bar(fig, ax):
    """The colour bar of the shape index on [-1, 1], MeshLab's Turbo ramp, named ticks."""
    import matplotlib.pyplot as plt
    from matplotlib.colors import LinearSegmentedColormap, Normalize

    lut = shape.colormap_table("turbo") / 255.0
    sm = plt.cm.ScalarMappable(norm=Normalize(-1, 1),
                               cmap=LinearSegmentedColormap.from_list("meshlab_turbo", lut))
    bar = fig.colorbar(sm, ax=ax, shrink=0.6, pad=0.02)
    bar.set_ticks([-1, -0.5, 0, 0.5, 1])
    bar.set_ticklabels(["cup -1", "rut -0.5", "saddle 0", "ridge 0.5", "cap +1"])
    bar.set_label("shape index (outward normals; grey: no estimate)")
