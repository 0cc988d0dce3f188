"""Annotated PLY files from and into a MeshSet: every curvature field, full precision.

MeshLab's PLY reader keeps no extra vertex property (only normals, ``quality`` and colour), and
``ms.save_current_mesh`` writes the filter's custom attributes only when each is asked for by
name (``__ca_vs__k1=True``, ...). These two functions do it in one call, in the layout that
``meshcurv annotate`` writes (:func:`meshcurv.io.write_annotated`): ``scalar_k1 ...
scalar_d2z`` float64, which plyfile / Open3D read exactly and CloudCompare loads as scalar fields.
"""

import os

import numpy as np

from meshcurv import io, shape

from .attributes import has_attribute, store_point, store_scalar

__all__ = ["save_curvature_mesh", "load_curvature_mesh"]

# Scalar attributes carried between MeshSet and file, besides shape.FIELDS, valid and status;
# the filter does not compute them, files written by meshcurv annotate have them.
_DIAGNOSTICS = {"n_neighbors": np.int32, "n_samples": np.int32, "residual": np.float64}


def _check_ply(path, what):
    if os.path.splitext(os.fspath(path))[1].lower() != ".ply":
        raise ValueError(f"{what}: {path} is not a .ply file")


def save_curvature_mesh(ms, path):
    """Write the current mesh of ``ms`` with its curvature attributes to the PLY ``path``.

    Writes (binary little-endian, atomically) the vertices and triangles, MeshLab's vertex
    normals, the custom attributes of :func:`compute_curvature_cga_per_vertex` as
    ``scalar_k1 scalar_k2 scalar_mean scalar_gaussian scalar_shape_index scalar_curvedness``
    (float64, NaN where invalid), ``scalar_valid`` (uint8), ``scalar_d1x .. scalar_d2z``
    (float64), ``scalar_status`` (uint8), ``scalar_outlier_score``, ``scalar_radius_used``
    (float64, model units), ``scalar_mls_share`` and ``scalar_jet_share`` when the mesh has
    them,
    ``scalar_n_neighbors scalar_n_samples scalar_residual`` when the mesh has them
    (a mesh read by :func:`load_curvature_mesh`), the vertex quality as ``quality`` and the
    vertex colour as ``red green blue``. Values are written bit for bit. Textures, face
    attributes and other custom attributes are not written (use ``ms.save_current_mesh`` for
    those).

    Raises ValueError when ``path`` is not a .ply file or the mesh has no curvature attributes.

    Examples
    --------
    >>> import pymeshlab, meshcurv.filters
    >>> ms = pymeshlab.MeshSet()
    >>> ms.create_torus(hradius=2.0, vradius=0.5)                          # doctest: +SKIP
    >>> _ = ms.compute_curvature_cga_per_vertex(radius=pymeshlab.PercentageValue(4))  # doctest: +SKIP
    >>> meshcurv.filters.save_curvature_mesh(ms, "torus_curvature.ply")    # doctest: +SKIP
    """
    _check_ply(path, "save_curvature_mesh")
    mesh = ms.current_mesh()
    scalar = mesh.vertex_custom_scalar_attribute_array
    point = mesh.vertex_custom_point_attribute_matrix
    missing = [f for f in shape.FIELDS + ("valid",) if not has_attribute(scalar, f)]
    missing += [f for f in ("d1", "d2") if not has_attribute(point, f)]
    if missing:
        raise ValueError("save_curvature_mesh: the current mesh has no curvature attribute "
                         f"{', '.join(missing)}; run ms.compute_curvature_cga_per_vertex(...) "
                         "first")
    normals = mesh.vertex_normal_matrix()
    fields = {c: normals[:, i] for i, c in enumerate(("nx", "ny", "nz"))}
    for f in shape.FIELDS:
        fields[f] = scalar(f)
    fields["valid"] = (scalar("valid") > 0).astype(np.uint8)
    if has_attribute(scalar, "status"):  # meshes filtered by earlier versions have none
        fields["status"] = scalar("status").astype(np.uint8)
    for name in ("d1", "d2"):
        values = point(name)
        for i, c in enumerate("xyz"):
            fields[name + c] = values[:, i]
    for f in ("outlier_score", "radius_used", "mls_share", "jet_share"):
        if has_attribute(scalar, f):
            fields[f] = scalar(f)
    for f, dtype in _DIAGNOSTICS.items():
        if has_attribute(scalar, f):
            fields[f] = scalar(f).astype(dtype)
    if mesh.has_vertex_scalar():
        fields["quality"] = mesh.vertex_scalar_array()
    if mesh.has_vertex_color():
        # MeshLab keeps 8-bit colour and hands it out as c / 255
        rgb = np.rint(mesh.vertex_color_matrix()[:, :3] * 255.0).astype(np.uint8)
        for i, c in enumerate(("red", "green", "blue")):
            fields[c] = rgb[:, i]
    faces = mesh.face_matrix() if mesh.face_number() else None
    io.write_ply(path, mesh.vertex_matrix(), faces,
                 {io.ply_property(k): v for k, v in fields.items()})


def load_curvature_mesh(ms, path):
    """Load the annotated PLY ``path`` into ``ms`` as a new current mesh, with its fields.

    MeshLab reads the geometry, normals, quality and colour (``ms.load_new_mesh``); the
    curvature fields, which MeshLab's reader drops, are read from the same file (plyfile) and
    added as custom attributes, exactly as :func:`compute_curvature_cga_per_vertex` leaves
    them: scalar ``k1 k2 mean gaussian shape_index curvedness valid`` (and ``n_neighbors
    n_samples residual`` when the file has them), point ``d1 d2``; float64, bit for bit. So
    MeshLab expressions (``ms.compute_selection_by_condition_per_vertex(condselect="k1 > 1")``)
    and :func:`save_curvature_mesh` work on the loaded mesh. Files of ``meshcurv annotate``
    (``scalar_k1`` or, older, plain ``k1``) and of :func:`save_curvature_mesh` are accepted.

    Raises ValueError when the file is not an annotated PLY (no k1, k2 fields), or
    :class:`meshcurv.io.MeshFileError` when it cannot be read.
    """
    _check_ply(path, "load_curvature_mesh")
    data = io.read(path)
    if "k1" not in data.fields or "k2" not in data.fields:
        raise ValueError(f"load_curvature_mesh: {path} is not annotated (no k1, k2 vertex "
                         "properties); load it with ms.load_new_mesh and run "
                         "ms.compute_curvature_cga_per_vertex")
    ms.load_new_mesh(os.fspath(path))
    n = ms.current_mesh().vertex_number()
    if n != len(data.vertices):
        raise ValueError(f"load_curvature_mesh: {path}: MeshLab read {n} vertices, the file "
                         f"has {len(data.vertices)}")
    for f in shape.FIELDS + ("valid", "status", "outlier_score", "radius_used", "mls_share",
                             "jet_share") + \
            tuple(_DIAGNOSTICS):
        if f in data.fields:
            store_scalar(ms, f, np.asarray(data.fields[f], dtype=np.float64))
    for name in ("d1", "d2"):
        cols = [name + c for c in "xyz"]
        if all(c in data.fields for c in cols):
            store_point(ms, name, np.column_stack([data.fields[c] for c in cols]))
