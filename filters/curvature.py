"""The pymeshlab filter ``compute_curvature_cga_per_vertex``: CGA principal curvatures in a MeshSet.

A thin adapter: it reads the current mesh, calls :func:`meshcurv.principal_curvatures` and writes
the result back into the same mesh (same id, same vertices, same other attributes) through
MeshLab's own per-vertex attribute and colour filters.
"""

import warnings

import numpy as np
import pymeshlab

from meshcurv import principal_curvatures, shape
from meshcurv.io import bbox_diagonal, usable_normals
from meshcurv.options import check_options
from meshcurv.result import jet_shares, mls_shares

from .attributes import store_point, store_scalar

__all__ = ["compute_curvature_cga_per_vertex", "resolve_radius"]

# Colour of vertices without an estimate, as a MeshLab colour expression (0..255).
_GREY = str(shape.INVALID_COLOR[0])
_MESHLAB_COLORMAPS = {c.lower(): c for c in shape.COLORMAPS}


def _typed_value(single):
    """The shortest decimal that rounds to the single-precision number ``single``."""
    return float(str(np.float32(single)))


def resolve_radius(radius, vertices):
    """Radius in model units from a PercentageValue, a PureValue, a number or None.

    ``PercentageValue(p)`` is p percent of the bounding-box diagonal of the finite vertices
    (:func:`meshcurv.io.bbox_diagonal`, double precision); ``PureValue(r)`` and plain numbers
    are model units; None keeps the estimator's default (the ball holding about 100 points).

    pymeshlab stores PureValue and PercentageValue in single precision (``PureValue(0.45)
    .value()`` is 0.449999988...); they are read back as the shortest decimal that rounds to
    the same single-precision number, i.e. the value that was typed (0.45). Pass a plain float
    for a radius with more than 7 significant digits.
    """
    if radius is None:
        return None
    if isinstance(radius, pymeshlab.PercentageValue):
        value = _typed_value(radius.value()) / 100.0 * bbox_diagonal(vertices)
    elif isinstance(radius, pymeshlab.PureValue):
        value = _typed_value(radius.value())
    elif isinstance(radius, (int, float, np.integer, np.floating)) and not isinstance(radius, bool):
        value = float(radius)
    else:
        raise ValueError("radius must be a pymeshlab.PercentageValue, a pymeshlab.PureValue or a "
                         f"number in model units, got {radius!r}")
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"radius must be positive, got {value}")
    return float(value)


def compute_curvature_cga_per_vertex(self, radius=None, ndirections=8, neighborhood="auto",
                                     quality="mean", colormap="Turbo", clamp=2.0,
                                     normals="auto", slab=0.25):
    """Principal curvatures by CGA circle fits (Seibert et al.) on the current mesh.

    Works on triangle meshes and point clouds. Around each vertex, circles centred on the normal
    line are fitted in ``2 * ndirections`` half normal sections; Euler's model fitted to their
    curvatures gives k1 >= k2 and the principal directions. Sign: outward normals, convex
    positive (a sphere of radius r: k1 = k2 = 1/r, shape index +1). Vertices are never added,
    removed or reordered; the mesh keeps its id, name and other attributes.

    Writes to the current mesh:

    * vertex quality: the ``quality`` field; 0 where there is no estimate
    * vertex colour: ``colormap`` over the ``quality`` field (shape index on [-1, 1], other
      fields clamped at the ``clamp`` / 100 - ``clamp`` percentiles); grey where there is no
      estimate
    * custom scalar attributes ``k1, k2, mean, gaussian, shape_index, curvedness`` (NaN where
      there is no estimate), ``valid`` (1 or 0), ``status``, ``outlier_score``, ``radius_used``,
      ``mls_share`` and ``jet_share`` (:data:`meshcurv.result.CURVATURE_FIELDS`)
    * custom point attributes ``d1, d2``: unit principal directions (NaN where invalid)

    ``ms.save_current_mesh`` writes only quality and colour of these; save them all with
    :func:`meshcurv.filters.save_curvature_mesh` and read such a file back, fields included,
    with :func:`meshcurv.filters.load_curvature_mesh`.

    Running the filter again overwrites these attributes. MeshLab cannot delete or refill an
    attribute from Python, so the new values pass through carrier attributes
    ``meshcurv_tmp_<k>`` that stay on the mesh (and are not saved by ``save_current_mesh``).

    Parameter list:

    radius : PercentageValue | PureValue | float = None
        Neighborhood radius. ``PercentageValue(p)``: p % of the bounding-box diagonal;
        ``PureValue(r)`` or a float: model units; None: the radius whose ball holds about 100
        points (works at any mesh size and sampling). PureValue and PercentageValue hold single
        precision and are read as the decimal typed (see :func:`resolve_radius`).
    ndirections : int = 8
        Normal-section planes per vertex (2 x ndirections circle fits).
    neighborhood : str = 'auto'
        'kring' (mesh-connected vertices within the radius, never crosses thin sheets), 'ball'
        (all points within the radius) or 'auto' (kring for meshes, ball for point clouds).
    quality : str = 'mean'
        Field written to vertex quality and coloured: 'k1', 'k2', 'mean', 'gaussian',
        'shape_index' or 'curvedness'.
    colormap : str = 'Turbo'
        MeshLab colour map: 'RGB', 'Viridis', 'Plasma', 'Cividis', 'Turbo' or 'RdPu'.
    clamp : float = 2.0
        Percent of values clipped at each end of the colour ramp (ignored for shape_index).
    normals : str = 'auto'
        'auto': for point clouds the mesh's own vertex normals when all are non-zero (loaded
        from file or computed by a MeshLab filter), else estimated; for triangle meshes
        estimated as :func:`meshcurv.principal_curvatures` does by default (PCA over the
        neighborhood, oriented by the faces, refined by a local quadric where the data are
        clean). 'mesh': always the mesh's vertex normals. 'estimate': always estimated (as
        above for meshes; PCA over the same ball plus an MST orientation for point clouds).
    slab : float = 0.25
        Half-width of each section plane's slab, as a fraction of the radius.

    Returns
    -------
    dict
        ``radius_used`` (model units), ``n_vertices``, ``n_valid``, ``n_invalid``,
        ``quality_field``, ``color_min``, ``color_max``, ``orientation`` (how the normals got
        their sign, and what was found wrong with given ones: ``CurvatureResult.orientation``)
        and, over the valid vertices, ``<field>_mean``, ``<field>_min``, ``<field>_max`` for
        every field.

    Examples
    --------
    >>> import pymeshlab, meshcurv.filters
    >>> ms = pymeshlab.MeshSet()
    >>> ms.create_torus(hradius=2.0, vradius=0.5)                          # doctest: +SKIP
    >>> out = ms.compute_curvature_cga_per_vertex(radius=pymeshlab.PercentageValue(4),
    ...                                           quality="shape_index")   # doctest: +SKIP
    >>> meshcurv.filters.save_curvature_mesh(ms, "torus_si.ply")           # doctest: +SKIP
    """
    cmap = _check_parameters(quality, colormap, normals, ndirections, neighborhood)
    mesh = self.current_mesh()
    if not mesh.is_compact():
        mesh.compact()  # drops vertices MeshLab already marked deleted; the rest keep order
    v = mesh.vertex_matrix()
    if len(v) == 0:
        raise ValueError("compute_curvature_cga_per_vertex: the current mesh has no vertices")
    f = mesh.face_matrix()
    point_cloud = len(f) == 0
    given = _given_normals(mesh, normals, point_cloud)
    with warnings.catch_warnings():
        # pymeshlab ships an older TBB than numba accepts; numba then falls back to OpenMP
        # but warns about it on its first parallel launch, which is noise for a filter user
        warnings.filterwarnings("ignore", message=".*TBB threading layer.*")
        res = principal_curvatures(v, None if point_cloud else f, normals=given,
                                   radius=resolve_radius(radius, v),
                                   n_directions=int(ndirections), neighborhood=neighborhood,
                                   slab=float(slab))
    fields = {name: getattr(res, name) for name in shape.FIELDS}
    lo, hi = _store_result(self, res, fields, quality, cmap, clamp)
    ok = res.valid
    summary = {"radius_used": float(res.radius), "n_vertices": int(len(v)),
               "n_valid": int(ok.sum()), "n_invalid": int((~ok).sum()),
               "quality_field": quality, "color_min": float(lo), "color_max": float(hi),
               "orientation": res.orientation}
    for name, values in fields.items():
        x = values[ok]
        summary[f"{name}_mean"] = float(x.mean()) if x.size else float("nan")
        summary[f"{name}_min"] = float(x.min()) if x.size else float("nan")
        summary[f"{name}_max"] = float(x.max()) if x.size else float("nan")
    return summary


def _check_parameters(quality, colormap, normals, ndirections, neighborhood):
    """ValueError (one line) for a parameter no mesh can fix, before the mesh is touched;
    returns MeshLab's spelling of ``colormap``. Estimator options: :func:`check_options`."""
    if quality not in shape.FIELDS:
        raise ValueError(f"quality must be one of {', '.join(shape.FIELDS)}, got {quality!r}")
    cmap = _MESHLAB_COLORMAPS.get(str(colormap).lower())
    if cmap is None:
        raise ValueError(f"colormap must be one of {', '.join(shape.COLORMAPS)}, got {colormap!r}")
    if normals not in ("auto", "mesh", "estimate"):
        raise ValueError(f"normals must be 'auto', 'mesh' or 'estimate', got {normals!r}")
    check_options(n_directions=ndirections, neighborhood=neighborhood)
    return cmap


def _given_normals(mesh, normals, point_cloud):
    """The mesh's vertex normals (n, 3) if the ``normals`` parameter takes them, else None."""
    mesh_normals = mesh.vertex_normal_matrix()
    if normals == "mesh":
        if not usable_normals(mesh_normals):
            raise ValueError("normals='mesh' but the current mesh has zero or non-finite "
                             "vertex normals")
        return mesh_normals
    if normals == "auto" and point_cloud and usable_normals(mesh_normals):
        return mesh_normals
    return None


def _store_result(ms, res, fields, quality, cmap, clamp):
    """Write the curvature attributes, quality and colours of ``res`` to the current mesh;
    returns the (lo, hi) range of the colour ramp."""
    for name, values in fields.items():
        store_scalar(ms, name, values)
    store_scalar(ms, "valid", res.valid.astype(np.float64))
    store_scalar(ms, "status", res.status.astype(np.float64))
    store_scalar(ms, "outlier_score", res.outlier_score)
    store_scalar(ms, "radius_used", res.radius_used)
    store_scalar(ms, "mls_share", mls_shares(res))
    store_scalar(ms, "jet_share", jet_shares(res))
    store_point(ms, "d1", res.d1)
    store_point(ms, "d2", res.d2)
    # quality: NaN would break MeshLab's ramps and statistics, so invalid vertices read 0
    ms.compute_scalar_by_function_per_vertex(q=f"({quality} == {quality}) ? {quality} : 0")
    lo, hi = shape.color_range(fields[quality], quality, clamp)
    ms.compute_color_from_scalar_per_vertex(minval=lo, maxval=hi, perc=0, zerosym=False,
                                            colormap=cmap)
    if not res.valid.all():
        ms.compute_color_by_function_per_vertex(
            x=f"valid > 0 ? r : {_GREY}", y=f"valid > 0 ? g : {_GREY}",
            z=f"valid > 0 ? b : {_GREY}", a="a")
    return lo, hi
