"""Custom per-vertex attributes of a pymeshlab mesh: whether one exists, and storing scalar and
point attributes, also over ones that exist (MeshLab cannot refill an attribute from Python)."""

import numpy as np
import pymeshlab

__all__ = ["has_attribute", "store_scalar", "store_point"]


def has_attribute(read, name):
    """Whether the mesh has the custom attribute ``name``; ``read`` is its reader method
    (``mesh.vertex_custom_scalar_attribute_array`` or ``..._point_attribute_matrix``)."""
    try:
        read(name)
        return True
    except pymeshlab.PyMeshLabException:
        return False


def _fresh_name(mesh, stem):
    k = 0
    while has_attribute(mesh.vertex_custom_scalar_attribute_array, f"{stem}_{k}"):
        k += 1
    return f"{stem}_{k}"


def store_scalar(ms, name, values):
    """Set the custom scalar attribute ``name`` of the current mesh to ``values`` (float64).

    MeshLab cannot replace an attribute's data from Python, so when ``name`` exists (the filter
    ran before) the new values go into a carrier attribute that MeshLab's expression filter
    copies over, exactly (double precision).
    """
    mesh = ms.current_mesh()
    values = np.ascontiguousarray(values, dtype=np.float64)
    if not has_attribute(mesh.vertex_custom_scalar_attribute_array, name):
        mesh.add_vertex_custom_scalar_attribute(values, name)
        return
    carrier = _fresh_name(mesh, "meshcurv_tmp")
    mesh.add_vertex_custom_scalar_attribute(values, carrier)
    ms.compute_new_custom_scalar_attribute_per_vertex(name=name, expr=carrier)


def store_point(ms, name, values):
    """Set the custom point attribute ``name`` of the current mesh to (n, 3) ``values``."""
    mesh = ms.current_mesh()
    values = np.ascontiguousarray(values, dtype=np.float64)
    if not has_attribute(mesh.vertex_custom_point_attribute_matrix, name):
        mesh.add_vertex_custom_point_attribute(values, name)
        return
    carriers = []
    for i in range(3):
        carriers.append(_fresh_name(ms.current_mesh(), "meshcurv_tmp"))
        ms.current_mesh().add_vertex_custom_scalar_attribute(values[:, i], carriers[-1])
    ms.compute_new_custom_point_attribute_per_vertex(name=name, x_expr=carriers[0],
                                                     y_expr=carriers[1], z_expr=carriers[2])

