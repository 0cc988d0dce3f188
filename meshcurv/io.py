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

import os
import tempfile
from dataclasses import dataclass, field as dc_field

import numpy as np

from . import shape

__all__ = ["MeshData", "MeshFileError", "READERS", "WRITERS", "register_reader",
           "register_writer", "read", "write", "write_ply", "write_annotated", "atomic_write",
           "check_distinct", "bbox_diagonal", "CURVATURE_FIELDS", "ANNOTATED_FIELDS",
           "curvature_fields", "PLY_PREFIX", "ply_property", "ply_field_names"]

# Per-vertex curvature fields of every annotated file (PLY properties, LAS extra bytes).
CURVATURE_FIELDS = shape.FIELDS + ("valid", "d1x", "d1y", "d1z", "d2x", "d2y", "d2z")
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
    """Fan-triangulate a list of index polygons; vertices are left untouched."""
    tris = []
    for p in polygons:
        p = np.asarray(p, dtype=np.int64)
        if len(p) < 3:
            continue
        tris.append(np.column_stack([np.full(len(p) - 2, p[0]), p[1:-1], p[2:]]))
    if not tris:
        return np.zeros((0, 3), dtype=np.int64)
    return np.concatenate(tris)


def read_ply(path):
    """Read a PLY mesh or point cloud (ASCII or binary) with all vertex properties.

    Faces are read from the ``face`` element (``vertex_indices`` or ``vertex_index``);
    polygons are fan-triangulated. ``nx ny nz`` become ``normals``; every other vertex property
    except ``x y z`` and colour goes to ``fields`` unchanged (same dtype), the annotated fields
    under their own names (``scalar_k1`` as ``k1``, see :func:`ply_field_names`).
    """
    from plyfile import PlyData

    ply = PlyData.read(path)
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
    fields = {field_names[p]: np.asarray(vert[p]) for p in props
              if p not in _GEOMETRY and p not in _COLOR}
    faces = None
    if "face" in names:
        fdata = ply["face"].data
        key = next((k for k in ("vertex_indices", "vertex_index") if k in fdata.dtype.names), None)
        if key is not None and len(fdata):
            col = fdata[key]
            if col.dtype != object and col.ndim == 2 and col.shape[1] == 3:
                faces = np.asarray(col, dtype=np.int64)
            else:
                lens = {len(p) for p in col}
                faces = (np.stack(col).astype(np.int64) if lens == {3} else _triangulate(col))
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


def read_trimesh(path):
    """Read OBJ, OFF or STL through trimesh, in file order (``process=False``).

    Normals are not taken from these files: the estimator's own are used. STL corners are
    merged by exact position (see the module docstring).
    """
    import trimesh

    mesh = trimesh.load(path, process=False, maintain_order=True, force="mesh")
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    if path.lower().endswith(".stl") and len(vertices):
        vertices, faces = _merge_exact(vertices, faces)
    return MeshData(vertices=vertices, faces=faces if len(faces) else None, path=path)


def read_xyz(path):
    """Read a whitespace- or comma-separated text point cloud (.xyz, .pts).

    Columns: 3 = ``x y z``; 6 = ``x y z nx ny nz``; 4 or 7 = ``x y z intensity [r g b]`` (Leica
    PTS; the extra columns are kept in ``fields``). A first line holding a single integer (the
    PTS point count) and ``#`` comments are skipped.
    """
    with open(path, "r", encoding="utf-8", errors="strict") as fh:
        lines = [ln.split("#", 1)[0].replace(",", " ").split() for ln in fh]
    lines = [ln for ln in lines if ln]
    if lines and len(lines[0]) == 1 and lines[0][0].isdigit():
        lines = lines[1:]
    if not lines:
        return MeshData(vertices=np.zeros((0, 3)), path=path)
    ncol = {len(ln) for ln in lines}
    if len(ncol) != 1:
        raise ValueError(f"rows have different numbers of columns: {sorted(ncol)}")
    ncol = ncol.pop()
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


def _las_module(path):
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
    las = _las_module(path)
    try:
        xyz, normals, fields = las.read_las_cloud(path, fields=CURVATURE_FIELDS)
    except las.LasReadError as exc:  # its message already names the file
        raise MeshFileError(first_line(exc)) from exc
    return MeshData(vertices=xyz, normals=normals, fields=fields, path=path)


READERS = {".ply": read_ply, ".obj": read_trimesh, ".off": read_trimesh, ".stl": read_trimesh,
           ".xyz": read_xyz, ".pts": read_xyz, ".las": read_las, ".laz": read_las}


def register_reader(extension, reader):
    """Register ``reader(path) -> MeshData`` for files ending in ``extension`` (e.g. ".las")."""
    READERS[extension.lower()] = reader


def _extension(path):
    return os.path.splitext(str(path))[1].lower()


def read(path):
    """Read a mesh or point cloud; the reader is chosen by extension (see :data:`READERS`).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    MeshData
        ``vertices`` (n, 3) float64 with n >= 1 and at least one finite row.

    Raises
    ------
    MeshFileError
        Missing, unreadable or corrupt file, unsupported extension, no vertices, no finite
        coordinates. The message starts with the file name.

    Examples
    --------
    >>> data = read("examples/torus.ply")              # doctest: +SKIP
    >>> data.vertices.shape, data.faces.shape         # doctest: +SKIP
    ((6400, 3), (12800, 3))
    """
    path = os.fspath(path)
    ext = _extension(path)
    if ext not in READERS:
        raise MeshFileError(f"{path}: unsupported file type {ext or '(no extension)'!r}; "
                            f"readable: {', '.join(sorted(READERS))}")
    if not os.path.isfile(path):
        raise MeshFileError(f"{path}: no such file")
    try:
        data = READERS[ext](path)
    except MeshFileError:
        raise
    except UnicodeDecodeError as exc:  # binary junk where a text header or table belongs
        raise MeshFileError(f"{path}: not a valid {ext[1:].upper()} file (binary data where "
                            f"text was expected at byte {exc.start})") from exc
    except OSError as exc:
        raise MeshFileError(f"{path}: cannot read file ({exc})") from exc
    except Exception as exc:  # parsers raise anything on corrupt input
        raise MeshFileError(f"{path}: not a valid {ext[1:].upper()} file "
                            f"({first_line(exc)})") from exc
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


def _remove_stale_partials(directory, names):
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
    _remove_stale_partials(directory, [name])
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


def curvature_fields(result):
    """The :data:`CURVATURE_FIELDS` of a :class:`~meshcurv.CurvatureResult`, in that order, as
    ``{name: (n,) array}``: float64, ``valid`` uint8 (1 = estimated), ``d1x .. d2z`` the
    components of the principal directions."""
    out = {f: np.asarray(getattr(result, f), dtype=np.float64) for f in shape.FIELDS}
    out["valid"] = np.asarray(result.valid, dtype=np.uint8)
    for name in ("d1", "d2"):
        arr = getattr(result, name)
        for a, c in enumerate("xyz"):
            out[name + c] = arr[:, a]
    return out


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
    if _extension(path) != ".ply":
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
    :data:`meshcurv.las.CURVATURE_FIELDS` (float64, ``valid`` uint8) are added as named
    extra-bytes dimensions, plus NormalX..NormalZ when the input has no normals; see
    :mod:`meshcurv.las`. ``.laz`` output is compressed. LAS has no colour ramp or quality
    property, so ``quality``, ``colormap`` and ``clamp`` are accepted and ignored.
    """
    if _extension(data.path) not in (".las", ".laz"):
        raise MeshFileError(f"{path}: LAS/LAZ output adds fields to the points of a LAS/LAZ "
                            f"input, but the input is {data.path or 'in memory'}; write .ply")
    check_distinct(data.path, path)
    las = _las_module(path)
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
    ext = _extension(path)
    if ext not in WRITERS:
        raise MeshFileError(f"{path}: cannot write {ext or '(no extension)'!r} files; "
                            f"writable: {', '.join(sorted(WRITERS))}")
    return WRITERS[ext](path, data, result, **options)
