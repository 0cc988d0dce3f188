"""PLY: read meshes and point clouds (ASCII or binary, every vertex property), write binary PLY
and the curvature-annotated PLY.

The annotated PLY (:func:`write_annotated`) is binary little-endian with named vertex
properties: ``x y z nx ny nz`` (float64); the fields ``k1 k2 mean gaussian shape_index
curvedness`` (float64, NaN where invalid), ``valid`` and ``status`` (uint8), ``d1x d1y d1z d2x d2y d2z``
(float64), ``n_neighbors n_samples`` (int32) and ``residual`` (float64), each named
``scalar_<field>`` in the file (``scalar_k1``: CloudCompare's spelling, the only one it loads as
a scalar field); then ``quality`` (float64, the chosen field with 0 where invalid) and
``red green blue`` (uint8), plus the ``face`` element. plyfile and Open3D read every property at
full precision (by its file name, ``scalar_k1``); :func:`read_ply` drops the prefix again.
CloudCompare loads the ``scalar_`` fields in single precision; MeshLab and pymeshlab keep only
normals, ``quality`` and colour (see :mod:`meshcurv.filters` for the fields in pymeshlab).

A file annotated at several radii (:func:`write_annotated` with a list of results) holds every
field from ``k1`` to ``residual`` once per radius, named with the radius's suffix
(:func:`meshcurv.io.data.radius_suffix`: ``k1_r0p5`` at radius 0.5, ``k1_r2pct`` at 2 %, stored
as ``scalar_k1_r0p5``), and the normals, ``quality`` and colour of the first radius.

plyfile is imported when a file is read or written, not with this module.
"""

import os

import numpy as np

from .. import shape
from ..result import CURVATURE_FIELDS, curvature_fields
from .atomic import atomic_write, check_distinct
from .data import MeshData, MeshFileError, file_extension, split_radius_suffix
from .parse import triangulate

__all__ = ["ANNOTATED_FIELDS", "PLY_PREFIX", "ply_property", "ply_field_names", "read_ply",
           "write_ply", "write_annotated", "readers", "writers"]

# Vertex properties of an annotated PLY, besides geometry and colour, in file order.
ANNOTATED_FIELDS = CURVATURE_FIELDS + ("n_neighbors", "n_samples", "residual", "quality")
_GEOMETRY = ("x", "y", "z", "nx", "ny", "nz")
_COLOR = ("red", "green", "blue", "alpha")

# PLY spelling of the annotated fields. CloudCompare loads a vertex property as a scalar field
# only if its name contains "scal" (and strips the "scalar_" it writes itself, showing "k1");
# MeshLab keeps no extra vertex property whatever its name. So every annotated field is written
# as scalar_<field>, except quality, which MeshLab and pymeshlab read under that name.
PLY_PREFIX = "scalar_"


def _is_prefixed(field):
    """Whether ``field`` is written ``scalar_<field>``: a field of :data:`ANNOTATED_FIELDS`
    except ``quality``, with or without a radius suffix (``k1_r0p5``)."""
    base = split_radius_suffix(field)[0]
    return base in ANNOTATED_FIELDS and base != "quality"


def ply_property(field):
    """PLY vertex property name of an annotated field: ``scalar_<field>`` for the fields of
    :data:`ANNOTATED_FIELDS` except ``quality`` (also with a radius suffix, ``k1_r0p5``); any
    other name unchanged.

    >>> ply_property("k1"), ply_property("k1_r0p5"), ply_property("quality")
    ('scalar_k1', 'scalar_k1_r0p5', 'quality')
    >>> ply_property("intensity")
    'intensity'
    """
    return PLY_PREFIX + field if _is_prefixed(field) else field


def ply_field_names(properties):
    """Field name of each PLY vertex property, ``{property: field}``: ``scalar_k1`` -> ``k1``
    for the annotated fields (so files written before the prefix, with plain ``k1``, read the
    same); other names unchanged, and both kept as they are when a file has both spellings.

    >>> ply_field_names(["x", "scalar_k1", "intensity"])
    {'x': 'x', 'scalar_k1': 'k1', 'intensity': 'intensity'}
    """
    properties = tuple(properties)
    out = {}
    for p in properties:
        field = p[len(PLY_PREFIX):] if p.startswith(PLY_PREFIX) else p
        renamed = field != p and _is_prefixed(field)
        out[p] = field if renamed and field not in properties else p
    return out


# ---------------------------------------------------------------------------------- reading

# Bytes of one value of each PLY scalar type (binary encoding).
_PLY_SIZES = {"char": 1, "int8": 1, "uchar": 1, "uint8": 1, "short": 2, "int16": 2,
              "ushort": 2, "uint16": 2, "int": 4, "int32": 4, "uint": 4, "uint32": 4,
              "float": 4, "float32": 4, "double": 8, "float64": 8}


def _ply_header(fh):
    """Scan a PLY header: (text, [(element, count, smallest record in bytes)]), the file left
    at the first data byte. Only what bounds the data is checked here; plyfile checks the rest.
    """
    if fh.readline().strip() != b"ply":
        raise ValueError("no 'ply' line at the start: not a PLY file")
    text, elements = True, []
    while True:
        line = fh.readline()
        if not line:
            raise ValueError("the header has no 'end_header' line")
        words = line.split()
        if not words:
            continue
        if words[0] == b"end_header":
            return text, elements
        if words[0] == b"format" and len(words) > 1:
            text = words[1] == b"ascii"
        elif words[0] == b"element" and len(words) == 3:
            try:
                count = int(words[2])
            except ValueError:
                raise ValueError(f"element {words[1].decode('latin-1')!r} has the count "
                                 f"{words[2].decode('latin-1')!r}, not an integer") from None
            if count < 0:
                raise ValueError(f"element {words[1].decode('latin-1')!r} has a negative "
                                 f"count ({count})")
            elements.append([words[1].decode("latin-1"), count, 0])
        elif words[0] == b"property" and elements and len(words) >= 3:
            # a list costs at least its length field; ASCII at least one digit and a separator
            size = _PLY_SIZES.get(words[2 if words[1] == b"list" else 1].decode("latin-1"), 1)
            elements[-1][2] += 2 if text else size


def _read_checked(path):
    """plyfile's PlyData of ``path``, after checking that the element counts of the header
    match the data: ValueError for a file too short for them (before anything is allocated
    for it) or with data beyond them."""
    from plyfile import PlyData

    size = os.path.getsize(path)
    with open(path, "rb") as fh:
        text, elements = _ply_header(fh)
        start = fh.tell()
        room = size - start
        for name, count, record in elements:
            need = count * record
            if need > room:
                raise ValueError(f"the header declares {count} {name!r} elements, more than "
                                 f"the {size - start} bytes of data can hold (truncated file "
                                 f"or corrupt header)")
            room -= need
        if text:  # one line per element record; plyfile stops after the declared counts
            # bytes.splitlines splits at \n, \r\n and \r: one entry per record line
            beyond = len(fh.read().strip().splitlines()) > sum(e[1] for e in elements)
        fh.seek(0)
        ply = PlyData.read(fh)
        if not text:  # plyfile leaves a binary file at the end of the declared data
            beyond = bool(fh.read().strip())
        if beyond:
            raise ValueError("data beyond the element counts of the header (corrupt header "
                             "or a concatenated file)")
    return ply


def _vertex_arrays(vert):
    """``(vertices (n, 3) float64, normals (n, 3) float64 or None, fields {name: (n,)}))`` of
    the vertex element's structured array ``vert``; fields (colour and quality included) keep
    their dtype, list properties are dropped."""
    props = vert.dtype.names or ()
    if not all(c in props for c in "xyz"):
        raise ValueError("vertex element lacks x, y, z")
    vertices = np.column_stack([np.asarray(vert[c], dtype=np.float64) for c in "xyz"])
    normals = None
    if all(c in props for c in ("nx", "ny", "nz")):
        normals = np.column_stack([np.asarray(vert[c], dtype=np.float64)
                                   for c in ("nx", "ny", "nz")])
    field_names = ply_field_names(props)
    # copies: the file is memory-mapped and closed now
    fields = {field_names[p]: np.array(vert[p]) for p in props
              if p not in _GEOMETRY and vert[p].dtype != object}  # no lists
    return vertices, normals, fields


def _face_array(fdata, n_vertices):
    """(m, 3) int64 triangles of the face element's structured array ``fdata`` (polygons
    fan-triangulated), or None when it has no vertex index list or no faces."""
    key = next((k for k in ("vertex_indices", "vertex_index")
                if k in (fdata.dtype.names or ())), None)
    if key is None or not len(fdata):
        return None
    col = fdata[key]
    if col.dtype != object and col.ndim == 2 and col.shape[1] == 3:
        raw = np.asarray(col)
    elif col.dtype == object and {len(p) for p in col} == {3}:
        raw = np.stack(col)
    else:
        raw = None
        faces = triangulate(col)
    if raw is not None:
        if raw.dtype.kind == "f" and not (np.isfinite(raw).all()
                                          and (raw == np.round(raw)).all()):
            raise ValueError("face indices that are not integers")
        faces = raw.astype(np.int64)
    if faces.size and (faces.min() < 0 or faces.max() >= n_vertices):
        raise ValueError(f"face indices outside 0..{n_vertices - 1}")
    return faces


def read_ply(path):
    """Read a PLY mesh or point cloud (ASCII or binary) with all vertex properties.

    Faces are read from the ``face`` element (``vertex_indices`` or ``vertex_index``);
    polygons are fan-triangulated. ``nx ny nz`` become ``normals``; every other vertex property
    except ``x y z`` (colour and quality included) goes to ``fields`` unchanged (same dtype),
    the annotated fields under their own names (``scalar_k1`` as ``k1``, see
    :func:`ply_field_names`).

    Element counts must match the data: a file too short for the counts of its header, or
    with data beyond them, is refused before anything is allocated for it.
    """
    ply = _read_checked(path)
    names = [e.name for e in ply.elements]
    if "vertex" not in names:
        raise ValueError("no 'vertex' element")
    vertices, normals, fields = _vertex_arrays(ply["vertex"].data)
    faces = _face_array(ply["face"].data, len(vertices)) if "face" in names else None
    return MeshData(vertices=vertices, faces=faces, normals=normals, fields=fields, path=path)


# ---------------------------------------------------------------------------------- writing

def write_ply(path, vertices, faces=None, fields=None):
    """Write a binary little-endian PLY atomically.

    Parameters
    ----------
    path : str
    vertices : (n, 3) float, written as float64 ``x y z``
    faces : (m, 3) int, optional, written as ``vertex_indices`` (uchar count, int32 indices)
    fields : dict name -> (n,) array, optional
        Extra vertex properties in the given order and dtype (float64, float32, int32, uint8,
        ...); they are read back bit for bit.
    """
    from plyfile import PlyData, PlyElement

    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be (n, 3), got {v.shape}")
    fields = dict(fields or {})
    dtype = [(c, "<f8") for c in "xyz"]
    for name, arr in fields.items():
        arr = np.asarray(arr)
        if arr.shape != (len(v),):
            raise ValueError(f"field {name!r} must have shape ({len(v)},), got {arr.shape}")
        dtype.append((name, arr.dtype.newbyteorder("<").str))
    table = np.empty(len(v), dtype=dtype)
    for i, c in enumerate("xyz"):
        table[c] = v[:, i]
    for name, arr in fields.items():
        table[name] = arr
    elements = [PlyElement.describe(table, "vertex")]
    if faces is not None:
        f = np.asarray(faces, dtype=np.int64)
        ftable = np.empty(len(f), dtype=[("vertex_indices", "<i4", (3,))])
        ftable["vertex_indices"] = f
        elements.append(PlyElement.describe(ftable, "face"))
    ply = PlyData(elements, text=False, byte_order="<",
                  comments=["meshcurv: principal curvatures, outward normals, convex positive"])
    atomic_write(path, ply.write)


def _radius_fields(result):
    """The fields of one radius, ``k1`` .. ``residual``, in file order, by field name."""
    fields = curvature_fields(result)
    fields["n_neighbors"] = np.asarray(result.n_neighbors, dtype=np.int32)
    fields["n_samples"] = np.asarray(result.n_samples, dtype=np.int32)
    fields["residual"] = np.asarray(result.residual, dtype=np.float64)
    return fields


def _annotated_fields(data, results, suffixes, quality, colormap, clamp):
    """The vertex properties of the annotated PLY besides ``x y z``, in file order, by field
    name: the input's other fields, normals, the fields of each result of ``results`` named
    with its suffix of ``suffixes``, then quality and colour (see the module docstring); the
    normals, quality and colour are the first result's."""
    first = results[0]
    values = curvature_fields(first)
    # an annotated input's curvature (at any radius) is replaced, never kept beside the new one
    ours = {k for k in data.fields if _is_prefixed(ply_field_names([k])[k])}
    fields = {}
    for k, v in data.fields.items():
        if k in _GEOMETRY or k in ours:
            continue
        if k in _COLOR or k == "quality":
            # the input's own colour and quality make way for the ramp, kept under the name
            # CloudCompare loads (as LAS colours are); an annotated input's are a ramp of ours
            k = PLY_PREFIX + k
            if ours or k in data.fields:
                continue
        fields[k] = v
    fields.update({"nx": first.normals[:, 0], "ny": first.normals[:, 1],
                   "nz": first.normals[:, 2]})
    for result, suffix in zip(results, suffixes):
        fields.update({k + suffix: v for k, v in _radius_fields(result).items()})
    fields["quality"] = np.where(first.valid, values[quality], 0.0)
    rgb = shape.colorize(np.where(first.valid, values[quality], np.nan), quality, colormap, clamp)
    for i, c in enumerate(("red", "green", "blue")):
        fields[c] = rgb[:, i]
    return fields


def write_annotated(path, data, result, quality="mean", colormap="Turbo", clamp=2.0,
                    suffixes=None):
    """Write ``data`` with the curvature ``result`` as an annotated binary PLY (atomic).

    Parameters
    ----------
    path : str, must end in .ply
    data : MeshData, the geometry the result was computed on
    result : CurvatureResult, one row per vertex of ``data``; or a list of them, one per radius
        (``principal_curvatures(..., radius=[r1, r2, ...])``), with ``suffixes``
    quality : str, default "mean"
        Field (one of :data:`meshcurv.shape.FIELDS`) copied into ``quality`` and used for the
        colour; invalid vertices get quality 0 and grey (the named fields keep NaN).
    colormap, clamp : colour ramp, see :func:`meshcurv.shape.colorize`
    suffixes : list of str, one per result of a list, e.g. ``["_r0p5", "_r1"]``
        (:func:`meshcurv.io.data.radius_suffix`): each result's fields are written as
        ``<field><suffix>``; the normals, quality and colour are the first result's.

    The curvature fields are named ``scalar_<field>`` in the file (``scalar_k1``, see
    :func:`ply_property`), the name under which CloudCompare loads them as scalar fields;
    :func:`read_ply` gives them back as ``fields["k1"]`` (``fields["k1_r0p5"]``). Other
    per-vertex properties of the input (``data.fields``) are kept, except annotated fields
    (with or without a radius suffix), which are replaced; the input's own colour and
    ``quality`` are kept as ``scalar_red`` ... ``scalar_quality`` (not those of an annotated
    input: they are a ramp of an earlier run).
    """
    if file_extension(path) != ".ply":
        raise MeshFileError(f"{path}: annotated output must be a .ply file")
    if data.path:
        check_distinct(data.path, path)
    results, suffixes = _results_and_suffixes(result, suffixes)
    n = len(data.vertices)
    for res in results:
        if len(res.k1) != n:
            raise ValueError(f"result has {len(res.k1)} rows for {n} vertices")
    if quality not in shape.FIELDS:
        raise ValueError(f"quality must be one of {', '.join(shape.FIELDS)}, got {quality!r}")
    fields = _annotated_fields(data, results, suffixes, quality, colormap, clamp)
    write_ply(path, data.vertices, None if data.is_point_cloud else data.faces,
              {ply_property(k): v for k, v in fields.items()})


def _results_and_suffixes(result, suffixes):
    """``(results, suffixes)`` as lists of the same length: ``([result], [""])`` for one
    result; ValueError for a list without one distinct suffix per result."""
    if suffixes is None:
        if isinstance(result, (list, tuple)):
            raise ValueError("a list of results needs one radius suffix per result")
        return [result], [""]
    results, suffixes = list(result), list(suffixes)
    if not results or len(suffixes) != len(results) or len(set(suffixes)) != len(suffixes):
        raise ValueError(f"{len(results)} results need as many distinct suffixes, got "
                         f"{suffixes!r}")
    return results, suffixes


readers = {".ply": read_ply}
writers = {".ply": write_annotated}
