"""The one shape check of the estimator's inputs (vertices, faces, normals)."""

import numpy as np

__all__ = ["as_arrays"]


def as_arrays(vertices, faces=None, normals=None):
    """``(v, f, nv)``: the estimator's inputs validated and converted.

    ``v`` (n, 3) float64 contiguous; ``f`` (m, 3) int64 with indices in 0..n-1, or None (also
    for an empty face list: the points are then a cloud); ``nv`` (n, 3) float64, or None. A
    trimesh.Trimesh supplies vertices and faces, a trimesh.PointCloud its points (a
    trimesh.Scene is refused: it is no one surface). Raises ValueError (one line) for wrong
    shapes, complex numbers, non-integer faces and face indices out of range.
    """
    if hasattr(vertices, "geometry") and hasattr(vertices, "graph"):
        count = len(vertices.geometry)
        raise ValueError(f"a trimesh.Scene is no one surface (it holds {count} "
                         f"geometr{'y' if count == 1 else 'ies'}): pass scene.to_geometry() "
                         f"(one mesh, transforms applied) or one of scene.geometry.values()")
    if hasattr(vertices, "vertices") and hasattr(vertices, "faces"):
        if faces is None:
            faces = vertices.faces
        vertices = vertices.vertices
    elif hasattr(vertices, "vertices"):          # a trimesh.PointCloud: its points
        vertices = vertices.vertices
    v = _real(vertices, "vertices")
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be an (n, 3) array, got shape {v.shape}")
    v = np.ascontiguousarray(v)
    f = None
    if faces is not None:
        f = np.asarray(faces)
        if f.size == 0:
            f = np.zeros((0, 3), dtype=np.int64)
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"faces must be an (m, 3) integer array, got shape {f.shape}")
        if not np.issubdtype(f.dtype, np.integer):
            if not np.all(np.mod(f, 1) == 0):
                raise ValueError("faces must hold integer vertex indices")
        f = f.astype(np.int64, copy=False)
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(
                f"faces index vertices 0..{len(v) - 1}, found indices {f.min()}..{f.max()}")
        if f.size == 0:
            f = None            # no faces (trimesh.Trimesh(vertices=points)): a point cloud
    nv = None
    if normals is not None:
        nv = _real(normals, "normals")
        if nv.shape != v.shape:
            raise ValueError(f"normals must have the shape of vertices {v.shape}, got {nv.shape}")
    return v, f, nv


def _real(values, name):
    """``values`` as float64; complex ones refused (numpy would drop their imaginary part)."""
    a = np.asarray(values)
    if np.iscomplexobj(a):
        raise ValueError(f"{name} must be real numbers, got {a.dtype}")
    return np.asarray(a, dtype=np.float64)
