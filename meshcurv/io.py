"""Mesh and point-cloud files: read geometry, write and read curvature-annotated binary PLY.

Readers never merge, reorder or drop vertices (one output row per vertex of the file), with one
exception: STL stores unshared triangle corners, which are merged by exact position in order of
first appearance (as MeshLab does on import) so that triangles share vertices.

Readers and writers are looked up by file extension in :data:`READERS` and :data:`WRITERS`;
:func:`register_reader` / :func:`register_writer` add formats.

The annotated PLY (:func:`write_annotated`) is binary little-endian with named vertex
properties: ``x y z nx ny nz`` (float64); the fields ``k1 k2 mean gaussian shape_index
curvedness`` (float64, NaN where invalid), ``valid`` (uint8), ``d1x d1y d1z d2x d2y d2z``
(float64), ``n_neighbors n_samples`` (int32) and ``residual`` (float64), each named
``scalar_<field>`` in the file (``scalar_k1``: CloudCompare's spelling, the only one it loads as
a scalar field); then ``quality`` (float64, the chosen field with 0 where invalid) and
``red green blue`` (uint8), plus the ``face`` element. plyfile and Open3D read every property at
full precision (by its file name, ``scalar_k1``); :func:`read` drops the prefix again.
CloudCompare loads the ``scalar_`` fields in single precision; MeshLab and pymeshlab keep only
normals, ``quality`` and colour (see :mod:`meshcurv.filters` for the fields in pymeshlab).

LAS/LAZ point clouds (optional extra ``las``: laspy + lazrs) are read into memory by
:func:`read_las`; :func:`write_las` copies the input's points unchanged and adds the curvature
fields as named extra-bytes dimensions (:mod:`meshcurv.las`). For clouds larger than memory use
:func:`meshcurv.tiled.annotate_tiled` (``meshcurv annotate --tile-size``).
"""

import contextlib
import errno
import logging
import os
import re
import stat
import tempfile
import warnings
from collections import Counter
from dataclasses import dataclass, field as dc_field

import numpy as np

from . import shape
from .result import CURVATURE_FIELDS, curvature_fields

__all__ = ["MeshData", "MeshFileError", "READERS", "WRITERS", "register_reader",
           "register_writer", "read", "write", "write_ply", "write_annotated", "atomic_write",
           "check_distinct", "bbox_diagonal", "ANNOTATED_FIELDS",
           "PLY_PREFIX", "ply_property", "ply_field_names"]

# Vertex properties of an annotated PLY, besides geometry and colour, in file order.
ANNOTATED_FIELDS = CURVATURE_FIELDS + ("n_neighbors", "n_samples", "residual", "quality")
_GEOMETRY = ("x", "y", "z", "nx", "ny", "nz")
_COLOR = ("red", "green", "blue", "alpha")

# PLY spelling of the annotated fields. CloudCompare loads a vertex property as a scalar field
# only if its name contains "scal" (and strips the "scalar_" it writes itself, showing "k1");
# MeshLab keeps no extra vertex property whatever its name. So every annotated field is written
# as scalar_<field>, except quality, which MeshLab and pymeshlab read under that name.
PLY_PREFIX = "scalar_"


def ply_property(field):
    """PLY vertex property name of an annotated field: ``scalar_<field>`` for the fields of
    :data:`ANNOTATED_FIELDS` except ``quality``; any other name unchanged.

    >>> ply_property("k1"), ply_property("quality"), ply_property("intensity")
    ('scalar_k1', 'quality', 'intensity')
    """
    return PLY_PREFIX + field if field in ANNOTATED_FIELDS and field != "quality" else field


def ply_field_names(properties):
    """Field name of each PLY vertex property, ``{property: field}``: ``scalar_k1`` -> ``k1``
    for the annotated fields (so files written before the prefix, with plain ``k1``, read the
    same); other names unchanged, and both kept as they are when a file has both spellings."""
    properties = tuple(properties)
    out = {}
    for p in properties:
        field = p[len(PLY_PREFIX):] if p.startswith(PLY_PREFIX) else p
        renamed = field != p and field in ANNOTATED_FIELDS and field != "quality"
        out[p] = field if renamed and field not in properties else p
    return out


class MeshFileError(ValueError):
    """A file that cannot be read or written; the message starts with the file name."""


def usable_normals(normals):
    """Whether ``normals`` ((n, 3) or None) is a full set of finite, non-zero normals, fit to
    hand to the estimator as given normals (e.g. from a file or a MeshLab mesh)."""
    return bool(normals is not None and np.isfinite(normals).all()
                and (np.linalg.norm(normals, axis=1) > 1e-12).all())


def first_line(exc):
    """The first line of an exception's message (its type name when it has none)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


@dataclass
class MeshData:
    """Geometry of a mesh or point cloud as read from a file; one row per vertex, file order.

    vertices : (n, 3) float64, model units
    faces : (m, 3) int64, or None for a point cloud
    normals : (n, 3) float64 from the file, or None
    fields : dict of other per-vertex properties, name -> (n,) array (PLY only; e.g. the
        curvature fields of an annotated file)
    path : the file it came from
    """

    vertices: np.ndarray
    faces: np.ndarray = None
    normals: np.ndarray = None
    fields: dict = dc_field(default_factory=dict)
    path: str = ""

    @property
    def is_point_cloud(self):
        """True when there are no faces."""
        return self.faces is None or len(self.faces) == 0


def bbox_diagonal(vertices):
    """Length of the bounding-box diagonal of the finite rows of (n, 3) ``vertices``.

    The reference length of percentage radii (``2%``), as in MeshLab's ``PercentageValue``.
    """
    v = np.asarray(vertices, dtype=np.float64)
    v = v[np.isfinite(v).all(axis=1)]
    if len(v) == 0:
        return 0.0
    return float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))


# ---------------------------------------------------------------------------------- readers

def _triangulate(polygons):
    """Fan-triangulate index polygons (sequences of ints) into an (m, 3) int64 array.

    Polygons with fewer than 3 corners are dropped; vertices are left untouched.
    """
    tris = []
    for p in polygons:
        p = [int(i) for i in p]
        tris.extend((p[0], p[j], p[j + 1]) for j in range(1, len(p) - 1))
    return np.array(tris, dtype=np.int64).reshape(-1, 3)


def _read_text(path, what):
    """The file as text (latin-1: never fails on odd bytes in comments); ValueError on NUL
    bytes, which no text format holds."""
    with open(path, "rb") as fh:
        raw = fh.read()
    nul = raw.find(b"\0")
    if nul >= 0:
        raise ValueError(f"binary data where {what} text was expected (byte {nul} is NUL)")
    return raw.decode("latin-1")


def _parse_coordinates(rows, what):
    """(n, 3) float64 from the first three number strings of each row; ValueError naming the
    first row that does not parse."""
    try:
        return np.array([r[:3] for r in rows], dtype=np.float64).reshape(-1, 3)
    except ValueError:
        for k, r in enumerate(rows):
            try:
                [float(t) for t in r[:3]]
            except ValueError:
                raise ValueError(f"{what} {k + 1}: {' '.join(r[:3])!r} is not three "
                                 f"numbers") from None
        raise


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


def read_ply(path):
    """Read a PLY mesh or point cloud (ASCII or binary) with all vertex properties.

    Faces are read from the ``face`` element (``vertex_indices`` or ``vertex_index``);
    polygons are fan-triangulated. ``nx ny nz`` become ``normals``; every other vertex property
    except ``x y z`` and colour goes to ``fields`` unchanged (same dtype), the annotated fields
    under their own names (``scalar_k1`` as ``k1``, see :func:`ply_field_names`).

    Element counts must match the data: a file too short for the counts of its header, or
    with data beyond them, is refused before anything is allocated for it.
    """
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
            data = fh.read().replace(b"\r\n", b"\n").replace(b"\r", b"\n").strip()
            beyond = (data.count(b"\n") + 1 if data else 0) > sum(e[1] for e in elements)
        fh.seek(0)
        ply = PlyData.read(fh)
        if not text:  # plyfile leaves a binary file at the end of the declared data
            beyond = bool(fh.read().strip())
        if beyond:
            raise ValueError("data beyond the element counts of the header (corrupt header "
                             "or a concatenated file)")
    names = [e.name for e in ply.elements]
    if "vertex" not in names:
        raise ValueError("no 'vertex' element")
    vert = ply["vertex"].data
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
              if p not in _GEOMETRY and p not in _COLOR}
    if any(f.dtype == object for f in fields.values()):
        fields = {p: f for p, f in fields.items() if f.dtype != object}  # list properties
    faces = None
    if "face" in names:
        fdata = ply["face"].data
        key = next((k for k in ("vertex_indices", "vertex_index")
                    if k in (fdata.dtype.names or ())), None)
        if key is not None and len(fdata):
            col = fdata[key]
            if col.dtype != object and col.ndim == 2 and col.shape[1] == 3:
                raw = np.asarray(col)
            elif col.dtype == object and {len(p) for p in col} == {3}:
                raw = np.stack(col)
            else:
                raw = None
                faces = _triangulate(col)
            if raw is not None:
                if raw.dtype.kind == "f" and not (np.isfinite(raw).all()
                                                  and (raw == np.round(raw)).all()):
                    raise ValueError("face indices that are not integers")
                faces = raw.astype(np.int64)
            if faces.size and (faces.min() < 0 or faces.max() >= len(vertices)):
                raise ValueError(f"face indices outside 0..{len(vertices) - 1}")
    return MeshData(vertices=vertices, faces=faces, normals=normals, fields=fields, path=path)


def _merge_exact(vertices, faces):
    """Merge vertices with identical coordinates, keeping the order of first appearance."""
    _, first, inverse = np.unique(vertices, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first, kind="stable")
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return vertices[first[order]], rank[inverse.ravel()][faces]


def read_obj(path):
    """Read a Wavefront OBJ mesh: one row per ``v`` line, in file order.

    Faces (``f``) may use ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn`` corners and negative
    (relative) indices; polygons are fan-triangulated. Texture coordinates and normals are
    ignored, so vertices are never split by them (unlike trimesh's loader); lines, points,
    groups and materials are ignored too.
    """
    text = _read_text(path, "OBJ").replace("\\\r\n", " ").replace("\\\n", " ")
    rows, polygons = [], []
    for lineno, line in enumerate(text.splitlines(), 1):
        if "#" in line:
            line = line.split("#", 1)[0]
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            if len(parts) < 4:
                raise ValueError(f"line {lineno}: a vertex needs x y z")
            rows.append(parts[1:4])
        elif parts[0] == "f":
            corners = []
            for token in parts[1:]:
                try:
                    i = int(token.split("/", 1)[0])
                except ValueError:
                    raise ValueError(f"line {lineno}: {token!r} is not a vertex index") from None
                if i == 0:
                    raise ValueError(f"line {lineno}: vertex index 0 (OBJ counts from 1)")
                if i < 0:  # relative to the vertices read so far
                    if -i > len(rows):
                        raise ValueError(f"line {lineno}: relative index {i} but only "
                                         f"{len(rows)} vertices before it")
                    i += len(rows) + 1
                corners.append(i - 1)
            polygons.append(corners)
    vertices = _parse_coordinates(rows, "vertex")
    if all(len(p) == 3 for p in polygons):
        faces = np.array(polygons, dtype=np.int64).reshape(-1, 3)
    else:
        faces = _triangulate(polygons)
    if faces.size and faces.max() >= len(vertices):
        raise ValueError(f"a face uses vertex {faces.max() + 1} of {len(vertices)}")
    return MeshData(vertices=vertices, faces=faces if len(faces) else None, path=path)


_OFF_KEYWORD = re.compile(r"(ST)?C?N?(4)?(n)?OFF")


def read_off(path):
    """Read an ASCII OFF mesh (also COFF, NOFF, STOFF ...: colours, normals and texture
    coordinates are ignored), one row per vertex line, in file order.

    The counts of the header must match the data: exactly one line per declared vertex and
    face. Polygons are fan-triangulated.
    """
    text = _read_text(path, "OFF")
    lines = []
    for line in text.splitlines():
        if "#" in line:
            line = line.split("#", 1)[0]
        parts = line.split()
        if parts:
            lines.append(parts)
    if not lines:
        raise ValueError("empty file")
    head = lines[0]
    match = _OFF_KEYWORD.fullmatch(head[0])
    if match is None:
        raise ValueError(f"starts with {head[0][:20]!r}, not OFF")
    if match.group(2) or match.group(3):
        raise ValueError(f"{head[0]}: only 3-D OFF files are supported")
    counts, rest = head[1:], lines[1:]
    if counts and counts[0].upper() == "BINARY":
        raise ValueError("binary OFF is not supported; save it as ASCII OFF or PLY")
    if not counts:
        if not rest:
            raise ValueError("no vertex and face counts after the OFF line")
        counts, rest = rest[0], rest[1:]
    try:
        nv, nf = int(counts[0]), int(counts[1])
    except (ValueError, IndexError):
        raise ValueError(f"the counts line {' '.join(counts)[:40]!r} is not 'vertices faces "
                         "edges'") from None
    if nv < 0 or nf < 0:
        raise ValueError(f"negative counts ({nv} vertices, {nf} faces)")
    if len(rest) != nv + nf:
        raise ValueError(f"the header declares {nv} vertices and {nf} faces, but "
                         f"{len(rest)} lines follow instead of {nv + nf} (truncated file or "
                         f"wrong counts)")
    vrows = rest[:nv]
    for k, r in enumerate(vrows):
        if len(r) < 3:
            raise ValueError(f"vertex {k}: {' '.join(r)!r} is not x y z")
    vertices = _parse_coordinates(vrows, "vertex")
    frows = rest[nv:]
    if all(len(r) == 4 and r[0] == "3" for r in frows):  # triangles without colour: at once
        try:
            faces = np.array([r[1:] for r in frows], dtype=np.int64).reshape(-1, 3)
        except ValueError:
            faces = None
        if faces is not None and (not faces.size or (faces.min() >= 0 and faces.max() < nv)):
            return MeshData(vertices=vertices, faces=faces if len(faces) else None, path=path)
    polygons = []
    for k, r in enumerate(frows):
        try:
            n = int(r[0])
            corners = [int(t) for t in r[1:n + 1]]
        except ValueError:
            raise ValueError(f"face {k}: {' '.join(r)[:40]!r} is not 'n i1 .. in'") from None
        if n < 0 or len(corners) < n or len(r) > n + 5:  # at most 4 colour values after
            raise ValueError(f"face {k}: {' '.join(r)[:40]!r} is not 'n i1 .. in "
                             "[colour]'")
        if corners and (min(corners) < 0 or max(corners) >= nv):
            raise ValueError(f"face {k}: vertex indices outside 0..{nv - 1}")
        polygons.append(corners)
    faces = _triangulate(polygons)
    return MeshData(vertices=vertices, faces=faces if len(faces) else None, path=path)


_STL_FACET = re.compile(
    rb"facet\s+normal\s+\S+\s+\S+\s+\S+\s+outer\s+loop\s+"
    rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)\s+vertex\s+(\S+)\s+(\S+)\s+(\S+)\s+"
    rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)\s+endloop\s+endfacet", re.IGNORECASE)


def _stl_corners(raw):
    """(3 m, 3) float64 triangle corners of a binary or ASCII STL, in file order."""
    if len(raw) >= 84:
        m = int(np.frombuffer(raw, "<u4", 1, 80)[0])
        if len(raw) == 84 + 50 * m:  # binary, whatever the header text says
            record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)),
                               ("attribute", "<u2")])
            tris = np.frombuffer(raw, record, m, 84)["corners"]
            return tris.reshape(-1, 3).astype(np.float64)
    if raw.lstrip()[:5].lower() != b"solid" or b"\0" in raw:  # SolidWorks: binary "solid.."
        if len(raw) < 84:
            raise ValueError(f"{len(raw)} bytes: too short for a binary STL, and not ASCII "
                             "(no 'solid' line)")
        raise ValueError(f"the binary header declares {m} triangles ({84 + 50 * m} bytes), "
                         f"but the file has {len(raw)} bytes (truncated or corrupt)")
    corners = _STL_FACET.findall(raw)
    rest = _STL_FACET.sub(b"\n", raw)
    words = Counter()
    for line in rest.splitlines():
        word = line.split()[:1]
        if word and word[0].lower() not in (b"solid", b"endsolid"):
            raise ValueError(f"incomplete or malformed ASCII facet near "
                             f"{line.strip()[:40].decode('latin-1')!r}")
        words.update(w.lower() for w in word)
    if words[b"solid"] != words[b"endsolid"]:
        raise ValueError("ASCII file without its 'endsolid' line (truncated)")
    try:
        return np.array(corners, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        bad = next(t for c in corners for t in c if not _is_number(t))
        raise ValueError(f"ASCII vertex coordinate {bad[:20].decode('latin-1')!r} is not "
                         "a number") from None


def _is_number(token):
    try:
        float(token)
    except ValueError:
        return False
    return True


def read_stl(path):
    """Read a binary or ASCII STL mesh.

    STL stores three unshared corners per triangle; they are merged by exact position in order
    of first appearance (see the module docstring). Facet normals are ignored. A binary file
    must be exactly as long as its triangle count says; an ASCII file must hold only complete
    facets.
    """
    with open(path, "rb") as fh:
        raw = fh.read()
    try:
        corners = _stl_corners(raw)
    except ValueError as exc:
        raise MeshFileError(f"{path}: corrupt STL: {exc}") from None
    faces = np.arange(len(corners), dtype=np.int64).reshape(-1, 3)
    if len(corners):
        corners, faces = _merge_exact(corners, faces)
    return MeshData(vertices=corners, faces=faces if len(faces) else None, path=path)


def read_xyz(path):
    """Read a whitespace- or comma-separated text point cloud (.xyz, .pts).

    Columns: 3 = ``x y z``; 6 = ``x y z nx ny nz``; 4 or 7 = ``x y z intensity [r g b]`` (Leica
    PTS; the extra columns are kept in ``fields``). A first line holding a single integer is
    the point count (PTS) and must match the number of rows; ``#`` comments are skipped.
    """
    with open(path, "r", encoding="utf-8", errors="strict") as fh:
        lines = [ln.split("#", 1)[0].replace(",", " ").split() for ln in fh]
    lines = [ln for ln in lines if ln]
    if lines and len(lines[0]) == 1 and lines[0][0].isdigit():
        declared = int(lines[0][0])
        lines = lines[1:]
        if declared != len(lines):
            raise ValueError(f"the first line declares {declared} points, but {len(lines)} "
                             "rows follow (truncated file or wrong count)")
    if not lines:
        return MeshData(vertices=np.zeros((0, 3)), path=path)
    widths = Counter(len(ln) for ln in lines)
    if len(widths) != 1:
        usual = widths.most_common(1)[0][0]
        odd = next(k for k, ln in enumerate(lines) if len(ln) != usual)
        raise ValueError(f"rows have different numbers of columns: row {odd + 1} has "
                         f"{len(lines[odd])}, {widths[usual]} of {len(lines)} rows have {usual}")
    ncol = len(lines[0])
    if ncol not in (3, 4, 6, 7):
        raise ValueError(f"expected 3 (x y z), 6 (x y z nx ny nz), 4 or 7 (PTS) columns, "
                         f"got {ncol}")
    table = np.array(lines, dtype=np.float64)
    data = MeshData(vertices=np.ascontiguousarray(table[:, :3]), path=path)
    if ncol == 6:
        data.normals = np.ascontiguousarray(table[:, 3:6])
    elif ncol >= 4:
        data.fields["intensity"] = table[:, 3]
        if ncol == 7:
            for i, c in enumerate(("red", "green", "blue")):
                data.fields[c] = table[:, 4 + i]
    return data


def las_module(path):
    """:mod:`meshcurv.las`, or a MeshFileError naming ``path`` when laspy is not installed."""
    try:
        import laspy  # noqa: F401  (las.py imports it lazily; fail here with a useful message)
    except ImportError:
        raise MeshFileError(f"{path}: LAS/LAZ files need laspy and lazrs "
                            "(pip install 'meshcurv[las]')") from None
    from . import las

    return las


def read_las(path):
    """Read a LAS/LAZ point cloud (laspy; LAZ through lazrs) into memory, in file order.

    ``vertices`` are the scaled x, y, z (model units); ``normals`` come from NormalX..NormalZ
    (or nx.., normal_x..) extra dimensions when the file has them; ``fields`` holds the
    :data:`CURVATURE_FIELDS` extra dimensions of an annotated file. Clouds larger than memory
    go through :func:`meshcurv.tiled.annotate_tiled` instead.
    """
    las = las_module(path)
    try:
        xyz, normals, fields = las.read_las_cloud(path, fields=CURVATURE_FIELDS)
    except las.LasReadError as exc:  # its message already names the file
        raise MeshFileError(first_line(exc)) from exc
    return MeshData(vertices=xyz, normals=normals, fields=fields, path=path)


READERS = {".ply": read_ply, ".obj": read_obj, ".off": read_off, ".stl": read_stl,
           ".xyz": read_xyz, ".pts": read_xyz, ".las": read_las, ".laz": read_las}


def register_reader(extension, reader):
    """Register ``reader(path) -> MeshData`` for files ending in ``extension`` (e.g. ".las")."""
    READERS[extension.lower()] = reader


def file_extension(path):
    return os.path.splitext(str(path))[1].lower()


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


@contextlib.contextmanager
def _quiet_libraries():
    """Silence warnings and the loggers of the parsing libraries while a file is read: their
    complaints about a corrupt file become the reader's one-line MeshFileError instead."""
    loggers = [logging.getLogger(name) for name in ("trimesh", "plyfile", "laspy")]
    levels = [lg.level for lg in loggers]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for lg in loggers:  # the level, not ``disabled``: it also holds for child loggers
            lg.setLevel(logging.CRITICAL + 1)
        try:
            yield
        finally:
            for lg, level in zip(loggers, levels):
                lg.setLevel(level)


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
        with _quiet_libraries():
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


# ---------------------------------------------------------------------------------- writers

def check_distinct(input_path, output_path):
    """Raise MeshFileError if ``output_path`` names the same file as ``input_path``."""
    same = os.path.realpath(input_path) == os.path.realpath(output_path)
    if not same and os.path.exists(output_path) and os.path.exists(input_path):
        same = os.path.samefile(input_path, output_path)
    if same:
        raise MeshFileError(f"{output_path}: refusing to overwrite the input file")


# The process's umask, read once (reading it means setting it, which is not thread-safe):
# finished files get the usual permissions 0666 & ~umask instead of mkstemp's 0600.
_UMASK = os.umask(0)
os.umask(_UMASK)

# Suffix of the temporary files of :func:`atomic_write`, named
# ``.<name>.<host>.<pid>.<random>.part`` so that a later write can tell a stale one (its process
# on this host is gone) from one a concurrent run is still writing.
PARTIAL_SUFFIX = ".part"
_HOST = None


def _host_tag():
    """This host's name as one dot-free token of a temporary file name."""
    global _HOST
    if _HOST is None:
        import re
        import socket

        _HOST = re.sub(r"[^A-Za-z0-9_-]", "-", socket.gethostname()) or "localhost"
    return _HOST


def _pid_alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # EPERM: alive, another user's
        return True
    return True


def remove_stale_partials(directory, names):
    """Remove the temporary files of :func:`atomic_write` for the targets ``names`` (basenames)
    in ``directory`` whose writing process, on this host, is no longer alive; returns the paths
    removed. A live process's file (another run writing the same target) is never touched;
    files of other hosts (a shared folder) and of other naming schemes are left alone."""
    if os.name != "posix":  # os.kill(pid, 0) is no liveness test on Windows
        return []
    names = set(names)
    host = _host_tag()
    removed = []
    try:
        entries = os.listdir(directory)
    except OSError:
        return []
    for entry in entries:
        if not (entry.startswith(".") and entry.endswith(PARTIAL_SUFFIX)):
            continue
        parts = entry[1:-len(PARTIAL_SUFFIX)].rsplit(".", 3)
        if len(parts) != 4 or parts[0] not in names or parts[1] != host \
                or not parts[2].isdigit():
            continue
        pid = int(parts[2])
        if pid == os.getpid() or _pid_alive(pid):
            continue
        path = os.path.join(directory, entry)
        try:
            os.remove(path)
            removed.append(path)
        except OSError:  # removed by a concurrent run, or not ours to remove
            pass
    return removed


def atomic_write(path, write_fn):
    """Call ``write_fn(tmp_path)`` on a temporary file next to ``path``, then rename it.

    Readers never see a partial file: on success the temporary file replaces ``path`` in one
    ``os.replace``; on any failure it is removed and the exception propagates. The folder of
    ``path`` is created if missing. Safe to call from several threads and processes at once.

    The temporary file is ``.<name>.<host>.<pid>.<random>.part``; one left by a killed process
    (nothing can remove it then) is removed by the next write of the same ``path`` from this
    host, once no process of that pid is alive.
    """
    path = os.fspath(path)
    directory = os.path.dirname(os.path.abspath(path))
    os.makedirs(directory, exist_ok=True)
    name = os.path.basename(path)
    remove_stale_partials(directory, [name])
    fd, tmp = tempfile.mkstemp(dir=directory, prefix=f".{name}.{_host_tag()}.{os.getpid()}.",
                               suffix=PARTIAL_SUFFIX)
    os.close(fd)
    try:
        write_fn(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise


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


def write_annotated(path, data, result, quality="mean", colormap="Turbo", clamp=2.0):
    """Write ``data`` with the curvature ``result`` as an annotated binary PLY (atomic).

    Parameters
    ----------
    path : str, must end in .ply
    data : MeshData, the geometry the result was computed on
    result : CurvatureResult, one row per vertex of ``data``
    quality : str, default "mean"
        Field (one of :data:`meshcurv.shape.FIELDS`) copied into ``quality`` and used for the
        colour; invalid vertices get quality 0 and grey (the named fields keep NaN).
    colormap, clamp : colour ramp, see :func:`meshcurv.shape.colorize`

    The curvature fields are named ``scalar_<field>`` in the file (``scalar_k1``, see
    :func:`ply_property`), the name under which CloudCompare loads them as scalar fields;
    :func:`read` gives them back as ``fields["k1"]``. Other per-vertex properties of the input
    PLY (``data.fields``) are kept unless an annotated field has the same name.
    """
    if file_extension(path) != ".ply":
        raise MeshFileError(f"{path}: annotated output must be a .ply file")
    if data.path:
        check_distinct(data.path, path)
    n = len(data.vertices)
    if len(result.k1) != n:
        raise ValueError(f"result has {len(result.k1)} rows for {n} vertices")
    if quality not in shape.FIELDS:
        raise ValueError(f"quality must be one of {', '.join(shape.FIELDS)}, got {quality!r}")
    values = curvature_fields(result)
    ours = (set(_GEOMETRY) | set(_COLOR) | set(ANNOTATED_FIELDS)
            | {ply_property(f) for f in ANNOTATED_FIELDS})
    fields = {k: v for k, v in data.fields.items() if k not in ours}
    fields.update({"nx": result.normals[:, 0], "ny": result.normals[:, 1],
                   "nz": result.normals[:, 2]})
    fields.update(values)
    fields["n_neighbors"] = np.asarray(result.n_neighbors, dtype=np.int32)
    fields["n_samples"] = np.asarray(result.n_samples, dtype=np.int32)
    fields["residual"] = np.asarray(result.residual, dtype=np.float64)
    fields["quality"] = np.where(result.valid, values[quality], 0.0)
    rgb = shape.colorize(np.where(result.valid, values[quality], np.nan), quality, colormap, clamp)
    for i, c in enumerate(("red", "green", "blue")):
        fields[c] = rgb[:, i]
    write_ply(path, data.vertices, None if data.is_point_cloud else data.faces,
              {ply_property(k): v for k, v in fields.items()})


def write_las(path, data, result, quality=None, colormap=None, clamp=None):
    """Write the LAS/LAZ input of ``data`` with the curvature ``result`` to ``path`` (atomic).

    Every point record of the input is copied unchanged and the fields of
    :data:`meshcurv.result.CURVATURE_FIELDS` (float64, ``valid`` uint8) are added as named
    extra-bytes dimensions, plus NormalX..NormalZ when the input has no normals; see
    :mod:`meshcurv.las`. ``.laz`` output is compressed. LAS has no colour ramp or quality
    property, so ``quality``, ``colormap`` and ``clamp`` are accepted and ignored.
    """
    if file_extension(data.path) not in (".las", ".laz"):
        raise MeshFileError(f"{path}: LAS/LAZ output adds fields to the points of a LAS/LAZ "
                            f"input, but the input is {data.path or 'in memory'}; write .ply")
    check_distinct(data.path, path)
    las = las_module(path)
    try:
        las.write_las_curvature(data.path, path, result)
    except las.LasReadError as exc:
        raise MeshFileError(first_line(exc)) from exc


WRITERS = {".ply": write_annotated, ".las": write_las, ".laz": write_las}


def register_writer(extension, writer):
    """Register ``writer(path, data, result, quality=, colormap=, clamp=)`` for ``extension``."""
    WRITERS[extension.lower()] = writer


def write(path, data, result, **options):
    """Write an annotated file; the writer is chosen by extension (see :data:`WRITERS`)."""
    ext = file_extension(path)
    if ext not in WRITERS:
        raise MeshFileError(f"{path}: cannot write {ext or '(no extension)'!r} files; "
                            f"writable: {', '.join(sorted(WRITERS))}")
    return WRITERS[ext](path, data, result, **options)
