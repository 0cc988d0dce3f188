"""Mesh and point-cloud files: read geometry, write and read curvature-annotated files.

Readers never merge, reorder or drop vertices (one output row per vertex of the file), with one
exception: STL stores unshared triangle corners, which are merged by exact position in order of
first appearance (as MeshLab does on import) so that triangles share vertices.

One module per format, each ending with its tables ``readers = {".ply": read_ply}`` and
``writers = {".ply": write_annotated}``; this module (the dispatcher) imports those tables into
:data:`READERS` and :data:`WRITERS`, where :func:`read` and :func:`write` look the reader and
writer up by file extension; :func:`register_reader` / :func:`register_writer` add formats.
Format modules never import this one.

==========  ===========================================================================
module      holds
==========  ===========================================================================
data        MeshData, MeshFileError and small helpers shared by every format
atomic      atomic_write (temporary file, then rename), check_distinct, stale temporaries
parse       fan triangulation and text parsing shared by the readers
ply         PLY reader, binary PLY writer, the curvature-annotated PLY (see its docstring)
obj, off    Wavefront OBJ and ASCII OFF readers
stl         binary and ASCII STL reader
xyz         text point clouds (.xyz, Leica .pts)
las         LAS/LAZ (optional extra ``las``: laspy + lazrs), chunked reading and the
            curvature fields as extra-bytes dimensions (:mod:`meshcurv.io.las`)
==========  ===========================================================================

LAS/LAZ point clouds are read into memory by :func:`read_las`; :func:`write_las` copies the
input's points unchanged and adds the curvature fields. For clouds larger than memory use
:func:`meshcurv.tiled.annotate_tiled` (``meshcurv annotate --tile-size``).
"""

import errno
import os
import stat

import numpy as np

from . import data as _data
from . import las, obj, off, ply, stl, xyz
from .atomic import PARTIAL_SUFFIX, atomic_write, check_distinct, remove_stale_partials
from .data import (MeshData, MeshFileError, bbox_diagonal, file_extension, first_line,
                   radius_suffix, split_radius_suffix, suffix_radius_text, usable_normals)
from .las import read_las, write_las
from .obj import read_obj
from .off import read_off
from .ply import (ANNOTATED_FIELDS, PLY_PREFIX, ply_field_names, ply_property, read_ply,
                  write_annotated, write_ply)
from .stl import read_stl
from .xyz import read_xyz

__all__ = ["MeshData", "MeshFileError", "READERS", "WRITERS", "register_reader",
           "register_writer", "read", "write", "write_ply", "write_annotated", "atomic_write",
           "check_distinct", "bbox_diagonal", "ANNOTATED_FIELDS",
           "PLY_PREFIX", "ply_property", "ply_field_names", "radius_suffix",
           "split_radius_suffix", "suffix_radius_text"]

# Reader and writer of each file extension (".ply"), from the tables of the format modules.
READERS = {**ply.readers, **obj.readers, **off.readers, **stl.readers, **xyz.readers,
           **las.readers}
WRITERS = {**ply.writers, **las.writers}


def register_reader(extension, reader):
    """Register ``reader(path) -> MeshData`` for files ending in ``extension`` (e.g. ".las")."""
    READERS[extension.lower()] = reader


def register_writer(extension, writer):
    """Register ``writer(path, data, result, quality=, colormap=, clamp=)`` for ``extension``
    (and ``suffixes=`` to write several radii, see :func:`write`)."""
    WRITERS[extension.lower()] = writer


def las_module(path):
    """:mod:`meshcurv.io.las`, or a MeshFileError naming ``path`` when laspy is not installed."""
    las.require_laspy(path)
    return las


_FILE_KINDS = ((stat.S_ISFIFO, "FIFO"), (stat.S_ISSOCK, "socket"),
               (stat.S_ISCHR, "character device"), (stat.S_ISBLK, "block device"))


def _check_readable_file(path):
    """MeshFileError saying why ``path`` is not a regular file one can open; never opens it
    (opening a FIFO would block)."""
    try:
        st = os.stat(path)
    except FileNotFoundError:
        if os.path.islink(path):
            raise MeshFileError(f"{path}: broken symbolic link (its target "
                                f"{os.readlink(path)!r} does not exist)") from None
        raise MeshFileError(f"{path}: no such file") from None
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise MeshFileError(f"{path}: symbolic link loop (the link points, through "
                                "other links, back to itself)") from None
        raise MeshFileError(f"{path}: cannot read file ({exc.strerror or exc})") from None
    if stat.S_ISDIR(st.st_mode):
        raise MeshFileError(f"{path}: is a directory, not a mesh or point-cloud file")
    if not stat.S_ISREG(st.st_mode):
        kind = next((name for test, name in _FILE_KINDS if test(st.st_mode)), "special file")
        raise MeshFileError(f"{path}: is not a regular file ({kind})")


def read(path):
    """Read a mesh or point cloud; the reader is chosen by extension (see :data:`READERS`).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    MeshData
        ``vertices`` (n, 3) float64 with n >= 1 and at least one finite row, one row per
        vertex of the file in file order; ``faces`` (m, 3) int64 indices into them, or None.

    Raises
    ------
    MeshFileError
        Missing, unreadable or corrupt file (counts of a header that do not match the data
        included), not a regular file, unsupported extension, no vertices, no finite
        coordinates. The message is one line and starts with the file name.

    Examples
    --------
    >>> data = read("examples/torus.ply")              # doctest: +SKIP
    >>> data.vertices.shape, data.faces.shape         # doctest: +SKIP
    ((6400, 3), (12800, 3))
    """
    path = os.fspath(path)
    ext = file_extension(path)
    _check_readable_file(path)
    if ext not in READERS:
        raise MeshFileError(f"{path}: unsupported file type {ext or '(no extension)'!r}; "
                            f"readable: {', '.join(sorted(READERS))}")
    fmt = ext[1:].upper()
    try:
        with _data.quiet_libraries():
            data = READERS[ext](path)
    except MeshFileError as exc:
        raise MeshFileError(first_line(exc)) from exc
    except UnicodeDecodeError as exc:  # binary junk where a text header or table belongs
        raise MeshFileError(f"{path}: not a valid {fmt} file (binary data where "
                            f"text was expected at byte {exc.start})") from exc
    except MemoryError as exc:
        raise MeshFileError(f"{path}: too large to read into memory "
                            f"({os.path.getsize(path)} bytes)") from exc
    except OSError as exc:
        raise MeshFileError(f"{path}: cannot read file ({exc.strerror or exc})") from exc
    except Exception as exc:  # parsers raise anything on corrupt input
        raise MeshFileError(f"{path}: not a valid {fmt} file "
                            f"({first_line(exc)})") from exc
    except BaseException as exc:  # a panic of a Rust parser (lazrs) is not an Exception
        if type(exc).__name__ != "PanicException":
            raise
        raise MeshFileError(f"{path}: not a valid {fmt} file (the decoder failed: "
                            f"{first_line(exc)})") from exc
    data.path = path
    if len(data.vertices) == 0:
        raise MeshFileError(f"{path}: the file holds no vertices")
    if not np.isfinite(data.vertices).all(axis=1).any():
        raise MeshFileError(f"{path}: no vertex has finite coordinates")
    return data


def write(path, data, result, **options):
    """Write an annotated file; the writer is chosen by extension (see :data:`WRITERS`).

    Parameters
    ----------
    path : str, the output; .ply (:func:`write_annotated`) or .las/.laz (:func:`write_las`,
        for a LAS/LAZ input only)
    data : MeshData, the geometry ``result`` was computed on (``data.path`` is never replaced)
    result : CurvatureResult, one row per vertex of ``data``; or a list of them, one per
        radius, with the option ``suffixes`` naming each radius's fields (``["_r0p5", "_r1"]``,
        see :func:`radius_suffix`)
    **options : ``quality``, ``colormap``, ``clamp``, ``suffixes`` of :func:`write_annotated`

    Raises MeshFileError (message starting with ``path``) for an extension without a writer.
    """
    ext = file_extension(path)
    if ext not in WRITERS:
        raise MeshFileError(f"{path}: cannot write {ext or '(no extension)'!r} files; "
                            f"writable: {', '.join(sorted(WRITERS))}")
    return WRITERS[ext](path, data, result, **options)
