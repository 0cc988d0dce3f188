"""LAS/LAZ point clouds: chunked reading and curvature fields written as LAS extra-bytes dimensions.

laspy (LAZ through lazrs; the optional extra ``las``) is imported when a file is read or written,
not with this module: without it, :func:`read_las` and :func:`write_las` raise a MeshFileError
saying what to install. For clouds larger than memory use :func:`meshcurv.tiled.annotate_tiled`
(``meshcurv annotate --tile-size``), which streams the file through :func:`iter_las_chunks` and
:func:`annotate_las`.

Reading and writing go through laspy (LAZ through the lazrs backend) and stream the file in
chunks, so files larger than memory are fine. The written file keeps every dimension of the input
unchanged (raw integer X, Y, Z, intensity, classification, existing extra bytes, ...) and adds one
named extra-bytes dimension per curvature field, readable by name in laspy, PDAL, CloudCompare and
LAStools:

====================  =======  ======================================================
name                  type     meaning
====================  =======  ======================================================
k1, k2                float64  principal curvatures, 1 / model units, k1 >= k2, convex positive
mean, gaussian        float64  (k1 + k2) / 2 and k1 * k2
shape_index           float64  in [-1, 1], +1 for a convex cap
curvedness            float64  sqrt((k1^2 + k2^2) / 2)
valid                 uint8    1 where an estimate was possible, else 0 (curvatures are NaN)
status                uint8    why there is no estimate: meshcurv.result.Status (0 = OK)
d1x d1y d1z           float64  unit direction of k1 (model axes)
d2x d2y d2z           float64  unit direction of k2; (d1, d2, normal) is right-handed
NormalX..NormalZ      float64  the unit normal used, only when it was estimated
====================  =======  ======================================================

A file annotated at several radii (``meshcurv annotate --radius 0.5,1,2``) has the fields from
``k1`` to ``d2z`` once per radius, named with the radius's suffix
(:func:`meshcurv.io.data.radius_suffix`: ``k1_r0p5``, ``k1_r2pct``), and the normals of the
first radius. LAS names have at most 32 characters (:data:`NAME_LIMIT`), which bounds the
digits of a radius: a longer name is refused before any work.

Writes are atomic: the output goes to a temporary file in the output's folder and is renamed
over ``out_path`` only when complete, so a failure never leaves a partial file. The input is
never overwritten. The output has the input's LAS version, except for LAS 1.0, which laspy
cannot write: its files are written as LAS 1.2, which has the same header layout and every 1.0
point format (see :func:`output_version`). The extra-bytes VLR that names the added dimensions
is written whatever the version, as laspy does.

>>> pts, nrm = read_las_points("scan.laz")                                # doctest: +SKIP
>>> res = meshcurv.principal_curvatures(pts, radius=0.5, orientation=(0, 0, 100))  # doctest: +SKIP
>>> write_las_curvature("scan.laz", "scan_curv.laz", res)                 # doctest: +SKIP
"""

import copy
import os
import re

import numpy as np

from ..result import CURVATURE_FIELDS, curvature_fields
from .atomic import atomic_write, check_distinct
from .data import MeshData, MeshFileError, file_extension, first_line, split_radius_suffix

__all__ = ["LasReadError", "CURVATURE_FIELDS", "NORMAL_FIELDS", "NAME_LIMIT", "DEFAULT_CHUNK",
           "is_las", "las_point_count", "open_las", "normal_dims", "iter_las_chunks",
           "read_las_points",
           "read_las_cloud", "result_fields", "output_version", "check_paths",
           "new_dimension_names",
           "check_annotatable", "annotate_las", "write_las_curvature", "require_laspy",
           "read_las", "write_las", "readers", "writers"]


NORMAL_FIELDS = ("NormalX", "NormalY", "NormalZ")
# Prefix of the other dimensions of a LAS/LAZ input in its fields (:func:`read_las_cloud`).
PLY_CARRY_PREFIX = "scalar_"
_DESCRIPTIONS = {
    "k1": "max principal curvature", "k2": "min principal curvature",
    "mean": "mean curvature", "gaussian": "Gaussian curvature",
    "shape_index": "shape index, +1 convex cap", "curvedness": "curvedness",
    "valid": "1 if curvature estimated", "status": "why no estimate (0 = estimated)",
}
# Fields written as uint8 whatever the float type of the others.
_INTEGER_FIELDS = ("valid", "status")
# Names under which other tools store normals (PDAL, CloudCompare, ad-hoc scripts).
_NORMAL_NAMES = (("normalx", "normaly", "normalz"), ("normal_x", "normal_y", "normal_z"),
                 ("nx", "ny", "nz"))
DEFAULT_CHUNK = 1_000_000
# Bytes of a dimension's name in the extra-bytes record (LAS 1.4 R15, table 24).
NAME_LIMIT = 32


class LasReadError(OSError):
    """A LAS/LAZ file that cannot be read (missing, truncated, corrupt); the message names it."""


def is_las(path):
    """Whether ``path`` ends in .las or .laz (any case)."""
    return file_extension(path) in (".las", ".laz")


# Bytes of a variable-length record's header (LAS 1.0-1.4): each of the header's declared VLRs
# takes at least this much between the public header and the first point.
_VLR_HEADER_SIZE = 54


def _check_vlr_count(path):
    """Refuse a header whose count of variable-length records cannot fit before its points
    (laspy allocates every declared record before reading any: 1.3 GB for a corrupt count)."""
    with open(path, "rb") as fh:
        head = fh.read(104)
    if len(head) < 104 or head[:4] != b"LASF":
        return  # laspy says what is wrong
    header_size = int.from_bytes(head[94:96], "little")
    point_offset = int.from_bytes(head[96:100], "little")
    n_vlrs = int.from_bytes(head[100:104], "little")
    if header_size + n_vlrs * _VLR_HEADER_SIZE > point_offset:
        raise LasReadError(f"{path}: the header declares {n_vlrs} variable-length records, more "
                           f"than fit before its point data at byte {point_offset} (corrupt "
                           "header)")


def open_las(path):
    """A laspy reader of the LAS/LAZ file ``path`` (a context manager), its header checked
    against the file size when the points are not compressed.

    Raises ValueError when ``path`` is not .las/.laz, FileNotFoundError when it is missing,
    :class:`LasReadError` when laspy cannot read its header or the header declares more
    points or variable-length records than the file holds.
    """
    import laspy

    if not is_las(path):
        raise ValueError(f"{path}: expected a .las or .laz file")
    _check_vlr_count(path)
    try:
        reader = laspy.open(os.fspath(path))
    except FileNotFoundError:
        raise
    except Exception as e:  # laspy/lazrs raise a variety of types for bad headers
        raise LasReadError(f"{path}: not a readable LAS/LAZ file ({type(e).__name__}: {e})") from e
    header = reader.header
    if not header.are_points_compressed:
        # laspy allocates what the header declares: check it against the file before reading
        need = header.offset_to_point_data + header.point_count * header.point_format.size
        size = os.path.getsize(path)
        if need > size:
            reader.close()
            raise LasReadError(f"{path}: the header declares {header.point_count} points "
                               f"({need} bytes), but the file has {size} bytes (truncated or "
                               "corrupt)")
    return reader


def normal_dims(point_format):
    """Names of the three extra dimensions holding normals, or None."""
    names = {n.lower(): n for n in point_format.extra_dimension_names}
    for cand in _NORMAL_NAMES:
        if all(c in names for c in cand):
            return tuple(names[c] for c in cand)
    return None


def output_version(path_or_header):
    """``(input version, output version)`` of an annotated copy of a LAS/LAZ file, as "1.2" ...

    The output keeps the input's version when laspy can write it; otherwise (LAS 1.0) it is
    LAS 1.2, the version laspy prefers for point formats 0-3: the same header layout and the
    same point records (1.4 for other formats).
    """
    import laspy

    header = path_or_header
    if not isinstance(header, laspy.LasHeader):
        with open_las(path_or_header) as reader:
            header = reader.header
    version = str(header.version)
    if version in laspy.supported_versions():
        return version, version
    return version, "1.2" if header.point_format.id <= 3 else "1.4"


def _check_new_dims(path, point_format, names):
    """ValueError when the laspy ``point_format`` of ``path`` already has a dimension of
    ``names`` (case-insensitive), listing at most three of them."""
    existing = {d.lower() for d in point_format.dimension_names}
    clash = [n for n in names if n.lower() in existing]
    if clash:
        listed = ", ".join(clash[:3]) + (f" and {len(clash) - 3} more" if len(clash) > 3 else "")
        raise ValueError(f"{path} already has dimension(s) {listed} (an annotated file?); "
                         "annotate the original file")


def check_annotatable(path, normals=None, header=None, suffixes=None):
    """The dimensions :func:`write_las_curvature` would add to ``path``; checked before any work.

    ``normals`` and ``suffixes`` as in :func:`write_las_curvature` (None: NormalX..NormalZ when
    the file has no normals; one radius); ``header``: the file's laspy header if the caller has
    read it already. Raises ValueError when the file already has one of them (an annotated
    file) or a name is longer than :data:`NAME_LIMIT`, :class:`LasReadError` when the file
    cannot be read.
    """
    if header is None:
        with open_las(path) as reader:
            header = reader.header
    point_format = header.point_format
    if normals is None:
        normals = normal_dims(point_format) is None
    names = new_dimension_names(suffixes, normals)
    _check_new_dims(path, point_format, names)
    return names


def new_dimension_names(suffixes=None, normals=False):
    """The extra-bytes dimensions an annotation adds, in order: :data:`CURVATURE_FIELDS` (once
    per radius, named ``<field><suffix>``, for a list of ``suffixes``), then NormalX..NormalZ
    when ``normals``. ValueError when a name is longer than :data:`NAME_LIMIT`.

    >>> new_dimension_names(["_r0p5", "_r1"])[:2]
    ['k1_r0p5', 'k2_r0p5']
    """
    names = [f + s for s in (suffixes or [""]) for f in CURVATURE_FIELDS]
    names += list(NORMAL_FIELDS) if normals else []
    too_long = [n for n in names if len(n.encode()) > NAME_LIMIT]
    if too_long:
        raise ValueError(f"the LAS dimension name {too_long[0]} is longer than the "
                         f"{NAME_LIMIT} characters LAS allows; write the radius with fewer "
                         "digits")
    return names


def las_point_count(path):
    """Number of points declared in the header of a LAS/LAZ file (int)."""
    with open_las(path) as reader:
        return int(reader.header.point_count)


def iter_las_chunks(path, chunk_size=DEFAULT_CHUNK, start=0, stop=None, with_records=False):
    """Stream a LAS/LAZ file in chunks of points.

    Parameters
    ----------
    path : str, a .las or .laz file
    chunk_size : int, points per chunk
    start, stop : int, the point range to read (default: all points)
    with_records : bool, also yield laspy's raw point record of the chunk

    Yields
    ------
    first : int, index of the chunk's first point in the file
    xyz : (k, 3) float64, scaled coordinates, model units
    normals : (k, 3) float64 or None, when the file has normal dimensions (NormalX.. or nx..)
    record : laspy.ScaleAwarePointRecord, only with ``with_records``

    Raises
    ------
    LasReadError
        The file is truncated or corrupt; the message names the file and the point range.
    """
    with open_las(path) as reader:
        total = int(reader.header.point_count)
        stop = total if stop is None else min(int(stop), total)
        ndims = normal_dims(reader.header.point_format)
        pos = int(start)
        try:
            if pos:
                reader.seek(pos)
        except Exception as e:
            raise LasReadError(f"{path}: cannot seek to point {pos}; the file is truncated or "
                               f"corrupt ({type(e).__name__}: {e})") from e
        while pos < stop:
            want = min(int(chunk_size), stop - pos)
            try:
                rec = reader.read_points(want)
            except Exception as e:
                raise LasReadError(
                    f"{path}: cannot read points {pos}..{pos + want - 1} of {total}; the file is "
                    f"truncated or corrupt ({type(e).__name__}: {e})") from e
            if len(rec) != want:
                raise LasReadError(
                    f"{path}: header declares {total} points but the data ends after "
                    f"{pos + len(rec)}; the file is truncated")
            xyz = np.column_stack([np.asarray(rec.x, dtype=np.float64),
                                   np.asarray(rec.y, dtype=np.float64),
                                   np.asarray(rec.z, dtype=np.float64)])
            nv = None
            if ndims is not None:
                nv = np.column_stack([np.asarray(rec[d], dtype=np.float64) for d in ndims])
            yield (pos, xyz, nv, rec) if with_records else (pos, xyz, nv)
            pos += want


def read_las_points(path, chunk_size=DEFAULT_CHUNK):
    """All points of a LAS/LAZ file in memory.

    Returns
    -------
    xyz : (n, 3) float64, model units, file order
    normals : (n, 3) float64 or None, when the file has normal dimensions
    """
    xyz, nv, _ = read_las_cloud(path, chunk_size, fields=())
    return xyz, nv


def _carried_dims(point_format, skip):
    """``{ply name: (dimension name, element index or None)}`` of the dimensions of
    ``point_format`` not named in ``skip`` (lower case) whose values a PLY property can hold,
    or a float64 one once read (:func:`_ply_ready`): integers of 8 to 64 bits and floats of 32
    or 64. An array of extra bytes ('3f8') gives one property per element,
    ``scalar_<name>_<i>``."""
    carried = {}
    for d in point_format.dimensions:
        if d.name.lower() in skip:
            continue
        base = np.dtype(d.dtype).base if d.dtype is not None else np.dtype(np.uint8)  # bits
        if not (base.kind in "iu" or (base.kind == "f" and base.itemsize in (4, 8))):
            continue
        name = PLY_CARRY_PREFIX + re.sub(r"\s", "_", d.name)
        if d.num_elements == 1:
            carried[name] = (d.name, None)
        else:
            carried.update({f"{name}_{i}": (d.name, i) for i in range(d.num_elements)})
    return carried


def _ply_ready(fields):
    """``fields`` with 64-bit integers (PLY has none) as float64 where that holds every value
    exactly (|v| <= 2^53), and the one-line notes on those it cannot hold, which are left
    out: ``(fields, notes)``."""
    out, lost = {}, []
    for name, values in fields.items():
        if values.dtype.kind in "iu" and values.dtype.itemsize == 8:
            if len(values) and (int(values.max()) > 2 ** 53 or int(values.min()) < -2 ** 53):
                lost.append(name[len(PLY_CARRY_PREFIX):])
                continue
            values = values.astype(np.float64)
        out[name] = values
    notes = [f"64-bit integer dimension {name} holds values beyond 2^53, which no PLY "
             f"property holds exactly: not carried (a LAS/LAZ output keeps it)" for name in lost]
    return out, notes


def read_las_cloud(path, chunk_size=DEFAULT_CHUNK, fields=CURVATURE_FIELDS, carry=False):
    """All points of a LAS/LAZ file in memory, with the extra dimensions named in ``fields``
    (also with a radius suffix: ``k1`` finds ``k1_r0p5`` too).

    Returns
    -------
    xyz : (n, 3) float64, model units, file order
    normals : (n, 3) float64 or None, when the file has normal dimensions
    found : dict name -> (n,) array, the dimensions of ``fields`` the file has (e.g. the
        curvature fields of an annotated file), in their stored type; with ``carry`` also
        each other integer or float dimension (intensity, classification, return numbers, GPS
        time, RGB, extra bytes), as ``scalar_<name>`` (the spelling CloudCompare loads as a
        scalar field; whitespace in a name, which a PLY property cannot hold, as ``_``; an
        array of extra bytes as ``scalar_<name>_0``, ``_1`` ...), in its stored type
    """
    with open_las(path) as reader:
        point_format = reader.header.point_format
    names = list(point_format.extra_dimension_names)
    have = {n.lower(): n for n in names}
    wanted = {f: (have[f.lower()], None) for f in fields if f.lower() in have}
    wanted.update({n: (n, None) for n in names if split_radius_suffix(n)[1]
                   and split_radius_suffix(n)[0] in fields and n not in wanted})
    if carry:
        skip = {"x", "y", "z"} | {n.lower() for n in (normal_dims(point_format) or ())}
        skip |= {dim.lower() for dim, _ in wanted.values()}
        wanted.update(_carried_dims(point_format, skip))
    xyz, nv, found = [], [], {f: [] for f in wanted}
    for _, p, n, rec in iter_las_chunks(path, chunk_size, with_records=True):
        xyz.append(p)
        nv.append(n)
        for f, (dim, i) in wanted.items():
            values = np.asarray(rec[dim])
            found[f].append(values if i is None else values[:, i])
    if not xyz:
        return np.zeros((0, 3)), None, {}
    return (np.concatenate(xyz), (None if nv[0] is None else np.concatenate(nv)),
            {f: np.concatenate(v) for f, v in found.items()})


def result_fields(result, normals=False, float_type="f8"):
    """The extra-bytes fields of a :class:`~meshcurv.CurvatureResult`, as ``{name: (n,) array}``.

    ``normals=True`` adds NormalX, NormalY, NormalZ (write them when they were estimated).
    """
    ft = np.dtype(float_type)
    out = curvature_fields(result)
    if normals:
        for a, name in enumerate(NORMAL_FIELDS):
            out[name] = result.normals[:, a]
    return {k: (v if k in _INTEGER_FIELDS else np.asarray(v, dtype=ft)) for k, v in out.items()}


def _field_types(names, float_type):
    """``[(name, dtype)]`` of the new dimensions: uint8 for ``valid`` and ``status`` (with or
    without a radius suffix), ``float_type`` else."""
    return [(n, np.uint8 if split_radius_suffix(n)[0] in _INTEGER_FIELDS
             else np.dtype(float_type)) for n in names]


def check_paths(in_path, out_path):
    """ValueError unless ``out_path`` is a .las/.laz file; MeshFileError when it is the input."""
    if not is_las(out_path):
        raise ValueError(f"{out_path}: the output must be a .las or .laz file")
    check_distinct(in_path, out_path)


def annotate_las(in_path, out_path, fields_for, names, chunk_size=DEFAULT_CHUNK, float_type="f8"):
    """Copy a LAS/LAZ file chunk by chunk, adding extra-bytes dimensions; atomic. Its records
    (VLRs and extended VLRs) are copied too.

    Parameters
    ----------
    in_path, out_path : str; ``out_path`` ending in .laz is compressed (lazrs)
    fields_for : callable ``(first, count) -> {name: (count,) array}`` giving the new fields of
        points ``first .. first + count - 1`` (file order)
    names : sequence of str, the new dimensions, in the order they are added
    chunk_size : int, points per chunk (bounds the memory)
    float_type : numpy float dtype of the float fields ("f8" or "f4")

    The output has the input's LAS version, or LAS 1.2 for a LAS 1.0 input (see
    :func:`output_version`).

    Raises
    ------
    ValueError
        Output not .las/.laz, output is the input, or the input already has a dimension of
        one of ``names``.
    LasReadError
        The input is truncated or corrupt (nothing is left at ``out_path``).
    """
    import laspy

    check_paths(in_path, out_path)
    with open_las(in_path) as reader:
        header = copy.deepcopy(reader.header)
    _check_new_dims(in_path, header.point_format, names)
    version = output_version(header)[1]
    if version != str(header.version):  # LAS 1.0: laspy writes 1.1 and later only
        header.version = laspy.header.Version.from_str(version)
    header.add_extra_dims([
        laspy.ExtraBytesParams(name=n, type=t,
                               description=_DESCRIPTIONS.get(split_radius_suffix(n)[0], ""))
        for n, t in _field_types(names, float_type)])

    def write(tmp):
        with open(tmp, "wb") as fh, laspy.open(
                fh, mode="w", header=header, closefd=False,
                do_compress=file_extension(out_path) == ".laz") as writer:
            for first, _, _, rec in iter_las_chunks(in_path, chunk_size, with_records=True):
                out = laspy.ScaleAwarePointRecord.zeros(len(rec), header=header)
                _copy_input_dims(rec.array, out.array)
                fields = fields_for(first, len(rec))
                for name in names:
                    out.array[name] = fields[name]
                writer.write_points(out)
            if header.evlrs:
                # the extended records after the points (a LAS 1.4 coordinate system, waveform
                # tables): laspy's writer leaves them out unless asked
                writer.write_evlrs(header.evlrs)

    atomic_write(out_path, write)


def _copy_input_dims(source, target):
    """Copy every dimension of the raw point array ``source`` (n,) into the first dimensions of
    ``target`` (n,), bit for bit: one block copy when ``source`` is a packed record whose fields
    sit at the same offsets in ``target`` (what adding extra bytes to a point format gives),
    else field by field."""
    fields, out = source.dtype.fields, target.dtype.fields
    packed = (sum(source.dtype[n].itemsize for n in source.dtype.names) == source.dtype.itemsize
              and all(n in out and out[n][:2] == fields[n][:2] for n in source.dtype.names)
              and source.flags.c_contiguous and target.flags.c_contiguous)
    if packed and len(source):
        width = source.dtype.itemsize
        target.view(np.uint8).reshape(len(target), -1)[:, :width] = \
            source.view(np.uint8).reshape(len(source), width)
        return
    for name in source.dtype.names:
        target[name] = source[name]


def write_las_curvature(in_path, out_path, result, normals=None, chunk_size=DEFAULT_CHUNK,
                        float_type="f8", suffixes=None):
    """Copy ``in_path`` to ``out_path`` with the curvature fields of ``result`` (a row per point).

    Parameters
    ----------
    in_path, out_path : str, .las or .laz
    result : CurvatureResult with one row per point of ``in_path``, in file order; or a list
        of them, one per radius, with ``suffixes``
    normals : bool, write NormalX..NormalZ (default: when the input has no normals); the
        first result's normals
    suffixes : list of str, one per result of a list (``["_r0p5", "_r1"]``, see
        :func:`meshcurv.io.data.radius_suffix`): each result's fields are named
        ``<field><suffix>``
    """
    check_paths(in_path, out_path)
    results = list(result) if suffixes is not None else [result]
    suffixes = list(suffixes) if suffixes is not None else [""]
    if len(suffixes) != len(results) or len(set(suffixes)) != len(suffixes):
        raise ValueError(f"{len(results)} results need as many distinct suffixes, got "
                         f"{suffixes!r}")
    total = las_point_count(in_path)
    for res in results:
        if len(res) != total:
            raise ValueError(f"result has {len(res)} rows, {in_path} has {total} points")
    names = check_annotatable(in_path, normals, suffixes=suffixes)
    normals = NORMAL_FIELDS[0] in names
    fields = {}
    for i, (res, suffix) in enumerate(zip(results, suffixes)):
        fields.update({k + suffix if k not in NORMAL_FIELDS else k: v for k, v in
                       result_fields(res, normals=normals and i == 0,
                                     float_type=float_type).items()})
    annotate_las(in_path, out_path, lambda a, k: {n: fields[n][a:a + k] for n in names}, names,
                 chunk_size=chunk_size, float_type=float_type)


# ------------------------------------------------------------------ reader and writer of meshcurv.io

def require_laspy(path):
    """Raise a MeshFileError naming ``path`` when laspy is not installed."""
    try:
        import laspy  # noqa: F401  (imported lazily elsewhere; fail here with a useful message)
    except ImportError:
        raise MeshFileError(f"{path}: LAS/LAZ files need laspy and lazrs "
                            "(pip install 'meshcurv[las]')") from None


def read_las(path):
    """Read a LAS/LAZ point cloud (laspy; LAZ through lazrs) into memory, in file order.

    ``vertices`` are the scaled x, y, z ((n, 3) float64, model units); ``normals`` come from
    NormalX..NormalZ (or nx.., normal_x..) extra dimensions when the file has them; ``fields``
    holds the :data:`CURVATURE_FIELDS` extra dimensions of an annotated file (also those of
    each radius, ``k1_r0p5``, see :func:`write_las_curvature`) and the file's other
    dimensions as ``scalar_<name>`` (``scalar_intensity``, ``scalar_classification`` ...: an
    annotated PLY written from it carries them; arrays of extra bytes one property per
    element, 64-bit integers as float64 where exact, else left out and named in ``notes``).
    Clouds larger
    than memory go through :func:`meshcurv.tiled.annotate_tiled` instead.
    """
    require_laspy(path)
    try:
        xyz, normals, fields = read_las_cloud(path, fields=CURVATURE_FIELDS, carry=True)
    except LasReadError as exc:  # its message already names the file
        raise MeshFileError(first_line(exc)) from exc
    fields, notes = _ply_ready(fields)
    return MeshData(vertices=xyz, normals=normals, fields=fields, path=path,
                    notes=tuple(notes))


def write_las(path, data, result, quality=None, colormap=None, clamp=None, suffixes=None):
    """Write the LAS/LAZ input of ``data`` with the curvature ``result`` to ``path`` (atomic).

    Every point record of the input is copied unchanged and the fields of
    :data:`meshcurv.result.CURVATURE_FIELDS` (float64, ``valid`` uint8) are added as named
    extra-bytes dimensions, plus NormalX..NormalZ when the input has no normals (see
    :func:`write_las_curvature`). ``.laz`` output is compressed. LAS has no colour ramp or
    quality property, so ``quality``, ``colormap`` and ``clamp`` are accepted and ignored.
    ``result`` may be a list of results, one per radius, with ``suffixes`` (see
    :func:`write_las_curvature`).
    """
    if not is_las(data.path):
        raise MeshFileError(f"{path}: LAS/LAZ output adds fields to the points of a LAS/LAZ "
                            f"input, but the input is {data.path or 'in memory'}; write .ply")
    check_distinct(data.path, path)
    require_laspy(path)
    try:
        write_las_curvature(data.path, path, result, suffixes=suffixes)
    except LasReadError as exc:
        raise MeshFileError(first_line(exc)) from exc


readers = {".las": read_las, ".laz": read_las}
writers = {".las": write_las, ".laz": write_las}
