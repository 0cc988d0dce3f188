"""Analytic test surfaces with exact normals, principal curvatures and directions.

Every generator returns a :class:`Surface`: a triangle mesh (faces counter-clockwise seen from
the side the normals point to), the exact outward unit normals, exact ``k1 >= k2`` (convex
positive) and unit principal directions, and ``border_distance``, the distance of each vertex
to the border of the parameter domain (inf on closed surfaces), so tests can skip the border.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay

__all__ = ["Surface", "paraboloid", "monkey_saddle", "egg_crate", "bump", "saddle",
           "scan_terrain", "sphere", "ellipsoid", "ellipsoid_at", "cylinder", "torus",
           "torus_at", "goursat_function", "goursat_at", "implicit_curvature", "project_to_implicit",
           "add_normal_noise", "orient_faces"]


@dataclass
class Surface:
    """Sampled analytic surface; all arrays have one row per vertex.

    vertices (n, 3), faces (m, 3) int64, normals (n, 3), k1 (n,), k2 (n,), d1 (n, 3), d2 (n, 3)
    (NaN at umbilics, where directions are undefined), border_distance (n,).
    """

    name: str
    vertices: np.ndarray
    faces: np.ndarray
    normals: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    border_distance: np.ndarray

    @property
    def diagonal(self):
        """Bounding-box diagonal, model units."""
        return float(np.linalg.norm(np.ptp(self.vertices, axis=0)))


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def orient_faces(vertices, faces, normals):
    """Faces (m, 3) with every triangle wound counter-clockwise seen from the side ``normals``
    ((n, 3), e.g. the exact ones) point to: triangles that disagree are flipped (a copy)."""
    fn = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                  vertices[faces[:, 2]] - vertices[faces[:, 0]])
    flip = np.einsum("ij,ij->i", fn, normals[faces].sum(axis=1)) < 0
    faces = faces.copy()
    faces[flip] = faces[flip][:, ::-1]
    return faces


def _grid_faces(nu, nv, wrap_u=False, wrap_v=False):
    """Two triangles per cell of an nu x nv vertex grid (index i * nv + j), optionally wrapped."""
    iu = np.arange(nu if wrap_u else nu - 1)
    jv = np.arange(nv if wrap_v else nv - 1)
    i, j = np.meshgrid(iu, jv, indexing="ij")
    i, j = i.ravel(), j.ravel()
    a = i * nv + j
    b = ((i + 1) % nu) * nv + j
    c = ((i + 1) % nu) * nv + (j + 1) % nv
    d = i * nv + (j + 1) % nv
    return np.concatenate([np.column_stack([a, b, c]), np.column_stack([a, c, d])]).astype(np.int64)


def _monge(name, x, y, f, fx, fy, fxx, fxy, fyy, normal_sign, faces, border):
    """Exact differential geometry of the graph z = f(x, y).

    With X_x = (1, 0, fx), X_y = (0, 1, fy) and the chosen unit normal N = s (-fx, -fy, 1) / W,
    the convex-positive shape operator is I^-1 (-II) with II_ij = X_ij . N.
    """
    w = np.sqrt(1 + fx * fx + fy * fy)
    normals = normal_sign * np.column_stack([-fx, -fy, np.ones_like(x)]) / w[:, None]
    e, f1, g = 1 + fx * fx, fx * fy, 1 + fy * fy
    l, m, nn = (-normal_sign * c / w for c in (fxx, fxy, fyy))
    det = e * g - f1 * f1
    # S = I^-1 II' = [[s11, s12], [s21, s22]]
    s11 = (g * l - f1 * m) / det
    s12 = (g * m - f1 * nn) / det
    s21 = (e * m - f1 * l) / det
    s22 = (e * nn - f1 * m) / det
    half_tr = 0.5 * (s11 + s22)
    disc = np.sqrt(np.maximum(half_tr ** 2 - (s11 * s22 - s12 * s21), 0.0))
    k1, k2 = half_tr + disc, half_tr - disc

    def direction(k):
        # eigenvector of S for eigenvalue k: either row of (S - k I) rotated by 90 degrees
        a = np.column_stack([s12, k - s11])
        b = np.column_stack([k - s22, s21])
        pick = np.linalg.norm(a, axis=1) >= np.linalg.norm(b, axis=1)
        ab = np.where(pick[:, None], a, b)
        t = ab[:, :1] * np.column_stack([np.ones_like(x), np.zeros_like(x), fx]) \
            + ab[:, 1:] * np.column_stack([np.zeros_like(x), np.ones_like(x), fy])
        with np.errstate(invalid="ignore"):
            t = _unit(t)
        t[disc <= 1e-12 * np.maximum(1.0, np.abs(half_tr))] = np.nan
        return t

    d1 = direction(k1)
    d2 = np.cross(normals, d1)
    vertices = np.column_stack([x, y, f])
    faces = orient_faces(vertices, faces, normals)
    return Surface(name, vertices, faces, normals, k1, k2, d1, d2, border)


def _xy_samples(extent, sampling, spacing, n, seed):
    """Regular grid (with its faces; ``spacing`` a number, or (along x, along y)) or uniform
    random points (Delaunay faces) on [-e, e]^2."""
    if sampling == "regular":
        tx, ty = (np.linspace(-extent, extent, int(round(2 * extent / d)) + 1)
                  for d in np.broadcast_to(np.asarray(spacing, dtype=np.float64), 2))
        x, y = (a.ravel() for a in np.meshgrid(tx, ty, indexing="ij"))
        faces = _grid_faces(len(tx), len(ty))
    elif sampling == "random":
        rng = np.random.default_rng(seed)
        x, y = rng.uniform(-extent, extent, (2, n))
        faces = Delaunay(np.column_stack([x, y])).simplices.astype(np.int64)
    else:
        raise ValueError(f"sampling must be 'regular' or 'random', got {sampling!r}")
    border = extent - np.maximum(np.abs(x), np.abs(y))
    return x, y, faces, border


def paraboloid(sampling="regular", a=0.2, b=0.1, extent=10.0, spacing=0.1, n=40000, seed=0):
    """The paper's Table 2 surface z = a x^2 + b y^2 on [-extent, extent]^2.

    Normals point out of the bowl (downward at the apex), so k1 = 2a, k2 = 2b > 0 there.

    Examples
    --------
    >>> s = paraboloid(spacing=1.0)
    >>> s.vertices.shape, round(float(s.k1[220]), 12), round(float(s.k2[220]), 12)
    ((441, 3), 0.4, 0.2)
    """
    x, y, faces, border = _xy_samples(extent, sampling, spacing, n, seed)
    z0 = np.zeros_like(x)
    return _monge("paraboloid", x, y, a * x * x + b * y * y, 2 * a * x, 2 * b * y,
                  2 * a + z0, z0, 2 * b + z0, -1.0, faces, border)


def monkey_saddle(sampling="regular", extent=0.5, spacing=0.01, n=10000, seed=0):
    """Monkey saddle z = x^3 - 3 x y^2 on [-extent, extent]^2, upward normals (flat at 0)."""
    x, y, faces, border = _xy_samples(extent, sampling, spacing, n, seed)
    return _monge("monkey_saddle", x, y, x ** 3 - 3 * x * y * y, 3 * x * x - 3 * y * y,
                  -6 * x * y, 6 * x, -6 * y, -6 * x, 1.0, faces, border)


def egg_crate(sampling="regular", amplitude=0.3, extent=3.0, spacing=0.05, n=20000, seed=0):
    """Egg crate z = amplitude sin x sin y on [-extent, extent]^2, upward normals: bumps, dips
    and saddles side by side, curvature varying everywhere (|k| up to ``amplitude``)."""
    x, y, faces, border = _xy_samples(extent, sampling, spacing, n, seed)
    sx, cx, sy, cy = np.sin(x), np.cos(x), np.sin(y), np.cos(y)
    a = amplitude
    return _monge("egg_crate", x, y, a * sx * sy, a * cx * sy, a * sx * cy, -a * sx * sy,
                  a * cx * cy, -a * sx * sy, 1.0, faces, border)


def bump(sampling="regular", amplitude=0.5, width=0.6, extent=2.0, spacing=0.04, n=20000,
         seed=0):
    """Gaussian bump z = amplitude exp(-(x^2 + y^2) / (2 width^2)) on [-extent, extent]^2,
    upward normals: a cap (k1 = k2 = amplitude / width^2 on top), a ring of saddles and a flat
    rim, curvature varying on the scale of ``width``. ``spacing`` (x, y) gives a grid finer
    one way than the other (a scanner's lines).

    Examples
    --------
    >>> s = bump(spacing=(0.5, 1.0))
    >>> s.vertices.shape, round(float(s.k1[22]), 6), round(float(s.k2[22]), 6)   # the top
    ((45, 3), 1.388889, 1.388889)
    """
    x, y, faces, border = _xy_samples(extent, sampling, spacing, n, seed)
    w2 = width * width
    g = amplitude * np.exp(-(x * x + y * y) / (2 * w2))
    return _monge("bump", x, y, g, -x / w2 * g, -y / w2 * g, (x * x / w2 - 1) / w2 * g,
                  x * y / (w2 * w2) * g, (y * y / w2 - 1) / w2 * g, 1.0, faces, border)


def saddle(sampling="regular", a=0.25, extent=2.0, spacing=0.05, n=20000, seed=0):
    """Hyperbolic paraboloid z = a (x^2 - y^2) on [-extent, extent]^2, upward normals: k1 = 2a,
    k2 = -2a at the origin, Gaussian curvature negative everywhere."""
    x, y, faces, border = _xy_samples(extent, sampling, spacing, n, seed)
    z0 = np.zeros_like(x)
    return _monge("saddle", x, y, a * (x * x - y * y), 2 * a * x, -2 * a * y, 2 * a + z0, z0,
                  -2 * a + z0, 1.0, faces, border)


def scan_terrain(spacing=(0.05, 0.25), jitter=0.0, wavelength=4 * np.pi, amplitude=0.1,
                 extent=10.0, seed=0):
    """Terrain z = 0.03 x^2 - 0.02 y^2 + amplitude sin(2 pi x / wavelength) on
    [-extent, extent]^2, sampled as an airborne scanner sweeps it: a point every
    ``spacing[0]`` along x on lines ``spacing[1]`` apart in y, each coordinate moved by
    Gaussian ``jitter`` times its spacing. Upward normals (convex positive under them);
    Delaunay faces of the (x, y) samples.

    Examples
    --------
    >>> s = scan_terrain((1.0, 2.0), extent=2.0)
    >>> s.vertices.shape, bool(np.all(s.normals[:, 2] > 0))
    ((15, 3), True)
    """
    rng = np.random.default_rng(seed)
    xs = np.arange(-extent, extent + 1e-9 * spacing[0], spacing[0])
    ys = np.arange(-extent, extent + 1e-9 * spacing[1], spacing[1])
    x, y = (a.ravel() for a in np.meshgrid(xs, ys, indexing="ij"))
    x = x + rng.normal(scale=jitter * spacing[0], size=x.shape)
    y = y + rng.normal(scale=jitter * spacing[1], size=y.shape)
    w = 2 * np.pi / wavelength
    z0 = np.zeros_like(x)
    faces = Delaunay(np.column_stack([x, y])).simplices.astype(np.int64)
    border = extent - np.maximum(np.abs(x), np.abs(y))
    return _monge("terrain", x, y, 0.03 * x * x - 0.02 * y * y + amplitude * np.sin(w * x),
                  0.06 * x + amplitude * w * np.cos(w * x), -0.04 * y,
                  0.06 - amplitude * w * w * np.sin(w * x), z0, -0.04 + z0, 1.0, faces, border)


def sphere(radius=1.0, subdivisions=5, sampling="regular", n=10000, seed=0):
    """Sphere of the given radius: an icosphere, or ``n`` uniform random points (hull faces).

    k1 = k2 = 1 / radius everywhere; directions are undefined (NaN).
    """
    if sampling == "regular":
        import trimesh

        ico = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
        unit = np.asarray(ico.vertices, dtype=np.float64)
        unit = _unit(unit)
        faces = np.asarray(ico.faces, dtype=np.int64)
    elif sampling == "random":
        from scipy.spatial import ConvexHull

        rng = np.random.default_rng(seed)
        unit = _unit(rng.normal(size=(n, 3)))
        faces = ConvexHull(unit).simplices.astype(np.int64)
    else:
        raise ValueError(f"sampling must be 'regular' or 'random', got {sampling!r}")
    v = radius * unit
    k = np.full(len(v), 1.0 / radius)
    nan3 = np.full((len(v), 3), np.nan)
    return Surface("sphere", v, orient_faces(v, faces, unit), unit, k, k.copy(), nan3,
                   nan3.copy(), np.full(len(v), np.inf))


def ellipsoid(semi_axes=(2.0, 1.5, 1.0), subdivisions=5, sampling="regular", n=10000, seed=0):
    """Ellipsoid x^2/a^2 + y^2/b^2 + z^2/c^2 = 1: the points of a unit icosphere (or ``n``
    uniform random points of the unit sphere, hull faces) scaled by the semi-axes (a, b, c),
    so the sampling is denser where the ellipsoid is narrower.

    Exact outward normals, k1 >= k2 > 0 and directions from the implicit function
    (:func:`implicit_curvature`); at the end of an axis the curvatures are the axis over the
    squares of the other two (e.g. a/b^2 and a/c^2 at (a, 0, 0)).

    Examples
    --------
    >>> s = ellipsoid(subdivisions=1)
    >>> s.vertices.shape, bool(np.all(s.k1 >= s.k2)), float(s.k1.max()) <= 2 / 1.0 ** 2
    ((42, 3), True, True)
    >>> r = ellipsoid((0.5, 0.5, 0.5), subdivisions=1)     # a sphere: k = 1 / 0.5 everywhere
    >>> bool(np.allclose(r.k1, 2.0) and np.allclose(r.k2, 2.0))
    True
    """
    axes = np.asarray(semi_axes, dtype=np.float64)
    unit = sphere(1.0, subdivisions, sampling, n, seed)
    v = unit.vertices * axes
    normals, k1, k2, d1, d2 = implicit_curvature(*_ellipsoid_function(v, axes)[1:])
    return Surface("ellipsoid", v, orient_faces(v, unit.faces, normals), normals, k1, k2, d1,
                   d2, np.full(len(v), np.inf))


def ellipsoid_at(points, semi_axes=(2.0, 1.5, 1.0)):
    """Exact geometry of the ellipsoid of ``semi_axes`` (:func:`ellipsoid`) at its points
    nearest ``points`` (n, 3) (:func:`project_to_implicit` onto x^2/a^2 + y^2/b^2 + z^2/c^2 =
    1): a :class:`Surface` without faces holding the projected points.

    Examples
    --------
    >>> s = ellipsoid_at([[2.1, 0.0, 0.0]])          # the end of the a axis: a/b^2, a/c^2
    >>> s.vertices[0].tolist(), round(float(s.k1[0]), 12), round(float(s.k2[0]), 12)
    ([2.0, 0.0, 0.0], 2.0, 0.888888888889)
    """
    axes = np.asarray(semi_axes, dtype=np.float64)
    v = project_to_implicit(points, lambda x: _ellipsoid_function(x, axes))
    normals, k1, k2, d1, d2 = implicit_curvature(*_ellipsoid_function(v, axes)[1:])
    return Surface("ellipsoid", v, np.zeros((0, 3), np.int64), normals, k1, k2, d1, d2,
                   np.full(len(v), np.inf))


def _ellipsoid_function(x, axes):
    """The implicit function x^2/a^2 + y^2/b^2 + z^2/c^2 - 1 of the ellipsoid of semi-axes
    ``axes`` at the points ``x`` (n, 3): its values (n,), gradients (n, 3), Hessians (n, 3,
    3)."""
    hess = np.broadcast_to(np.diag(2 / axes ** 2), (len(x), 3, 3))
    return np.sum(x * x / axes ** 2, axis=1) - 1.0, 2 * x / axes ** 2, hess


def cylinder(radius=1.0, height=4.0, n_around=200, n_along=None):
    """Open cylinder around the z axis: k1 = 1 / radius around, k2 = 0 along the axis."""
    if n_along is None:
        n_along = int(round(height / (2 * np.pi * radius / n_around))) + 1
    u = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    z = np.linspace(-height / 2, height / 2, n_along)
    uu, zz = (a.ravel() for a in np.meshgrid(u, z, indexing="ij"))
    normals = np.column_stack([np.cos(uu), np.sin(uu), np.zeros_like(uu)])
    v = np.column_stack([radius * normals[:, :2], zz])
    d1 = np.column_stack([-np.sin(uu), np.cos(uu), np.zeros_like(uu)])
    d2 = np.cross(normals, d1)
    faces = orient_faces(v, _grid_faces(n_around, n_along, wrap_u=True), normals)
    return Surface("cylinder", v, faces, normals, np.full(len(v), 1.0 / radius),
                   np.zeros(len(v)), d1, d2, height / 2 - np.abs(zz))


def torus(major=2.0, minor=0.5, n_major=240, n_minor=60):
    """Torus around the z axis; angle v around the tube is 0 on the outer equator.

    k1 = 1 / minor (around the tube), k2 = cos v / (major + minor cos v) (around the axis).
    """
    u = np.linspace(0, 2 * np.pi, n_major, endpoint=False)
    w = np.linspace(0, 2 * np.pi, n_minor, endpoint=False)
    uu, ww = (a.ravel() for a in np.meshgrid(u, w, indexing="ij"))
    normals = np.column_stack([np.cos(ww) * np.cos(uu), np.cos(ww) * np.sin(uu), np.sin(ww)])
    ring = major + minor * np.cos(ww)
    v = np.column_stack([ring * np.cos(uu), ring * np.sin(uu), minor * np.sin(ww)])
    d1 = np.column_stack([-np.sin(ww) * np.cos(uu), -np.sin(ww) * np.sin(uu), np.cos(ww)])
    d2 = np.cross(normals, d1)
    faces = orient_faces(v, _grid_faces(n_major, n_minor, wrap_u=True, wrap_v=True), normals)
    return Surface("torus", v, faces, normals, np.full(len(v), 1.0 / minor),
                   np.cos(ww) / ring, d1, d2, np.full(len(v), np.inf))


def torus_at(points, major=6.0, minor=2.0):
    """Exact geometry of the torus around the z axis at the points of it nearest ``points``.

    ``points`` (n, 3) near the torus (e.g. samples written to a few digits, or noisy ones) are
    projected onto it along the line through the tube's centre circle; the returned
    :class:`Surface` (no faces, ``border_distance`` inf) holds the projected points and, as in
    :func:`torus`, k1 = 1 / minor and k2 = cos v / (major + minor cos v), v the angle around
    the tube (0 on the outer equator).

    Examples
    --------
    >>> s = torus_at([[8.0, 0.0, 0.0], [0.0, 4.1, 0.0], [6.0, 0.0, 2.0]])
    >>> s.vertices[1].tolist(), s.k1.tolist(), s.k2.round(6).tolist()
    ([0.0, 4.0, 0.0], [0.5, 0.5, 0.5], [0.125, -0.25, 0.0])
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    rho = np.hypot(p[:, 0], p[:, 1])
    around = np.column_stack([p[:, 0] / rho, p[:, 1] / rho, np.zeros(len(p))])
    normals = _unit(p - major * around)
    cos_v, sin_v = np.einsum("ij,ij->i", normals, around), normals[:, 2]
    v = major * around + minor * normals
    d1 = -sin_v[:, None] * around + cos_v[:, None] * np.array([0.0, 0.0, 1.0])
    d2 = np.cross(normals, d1)
    return Surface("torus", v, np.zeros((0, 3), np.int64), normals, np.full(len(p), 1.0 / minor),
                   cos_v / (major + minor * cos_v), d1, d2, np.full(len(p), np.inf))


def implicit_curvature(gradient, hessian):
    """Exact normals, principal curvatures and directions of an implicit surface F = 0.

    The shape operator is ``P Hess(F) P / |grad F|`` with P the projector onto the tangent
    plane; with the normal ``grad F / |grad F|`` (outward where F grows outward) it is convex
    positive. Directions are NaN at umbilics.

    Parameters
    ----------
    gradient : (n, 3) float, grad F at points of F = 0
    hessian : (n, 3, 3) float, Hess F there

    Returns
    -------
    normals (n, 3), k1 (n,), k2 (n,), d1 (n, 3), d2 (n, 3); k1 >= k2, (d1, d2, normals)
    right-handed.

    Examples
    --------
    Unit sphere F = |x|^2 - 1 at (0, 0, 1): grad 2x, Hess 2 I.

    >>> n, k1, k2, d1, d2 = implicit_curvature([[0.0, 0.0, 2.0]], [2.0 * np.eye(3)])
    >>> n.tolist(), k1.tolist(), k2.tolist(), bool(np.isnan(d1).all())
    ([[0.0, 0.0, 1.0]], [1.0], [1.0], True)
    """
    g = np.asarray(gradient, dtype=np.float64).reshape(-1, 3)
    h = np.asarray(hessian, dtype=np.float64).reshape(-1, 3, 3)
    norm = np.linalg.norm(g, axis=1)
    normals = g / norm[:, None]
    # a tangent basis (t1, t2): any axis not near the normal, made orthogonal to it
    axis = np.where((np.abs(normals[:, 0]) < 0.9)[:, None], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    t1 = _unit(axis - np.einsum("ij,ij->i", axis, normals)[:, None] * normals)
    t2 = np.cross(normals, t1)

    def form(a, b):
        return np.einsum("ni,nij,nj->n", a, h, b) / norm

    s11, s12, s22 = form(t1, t1), form(t1, t2), form(t2, t2)
    half_tr = 0.5 * (s11 + s22)
    disc = np.hypot(0.5 * (s11 - s22), s12)
    k1, k2 = half_tr + disc, half_tr - disc
    theta = 0.5 * np.arctan2(2 * s12, s11 - s22)
    d1 = np.cos(theta)[:, None] * t1 + np.sin(theta)[:, None] * t2
    d1[disc <= 1e-12 * np.maximum(1.0, np.abs(half_tr))] = np.nan
    return normals, k1, k2, d1, np.cross(normals, d1)


def project_to_implicit(points, function, steps=50):
    """Points (n, 3) moved onto F = 0 by Newton steps along grad F (for points near the
    surface, e.g. samples written to a few digits or noisy ones). ``function(points)`` returns
    (F (n,), grad F (n, 3), Hess F (n, 3, 3)), like :func:`goursat_function`."""
    x = np.array(points, dtype=np.float64).reshape(-1, 3)
    for _ in range(steps):
        f, g, _ = function(x)
        step = (f / np.einsum("ij,ij->i", g, g))[:, None] * g
        x -= step
        if np.all(np.abs(step) <= 1e-15 * (1.0 + np.abs(x))):
            break
    return x


def goursat_function(points, a=0.03, b=-2.0, c=-8.0):
    """Goursat's surface F = a (x^4 + y^4 + z^4) + b (x^2 + y^2 + z^2) + c (default: the
    benchmark surface of Lachaud et al. 2023, about [-9.66, 9.66]^3; F > 0 outside).

    Returns F (n,), grad F (n, 3), Hess F (n, 3, 3) at ``points`` (n, 3).
    """
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    f = a * np.sum(p ** 4, axis=1) + b * np.sum(p ** 2, axis=1) + c
    g = 4 * a * p ** 3 + 2 * b * p
    h = np.zeros((len(p), 3, 3))
    h[:, [0, 1, 2], [0, 1, 2]] = 12 * a * p ** 2 + 2 * b
    return f, g, h


def goursat_at(points, a=0.03, b=-2.0, c=-8.0):
    """Exact geometry of Goursat's surface (:func:`goursat_function`) at the points of it
    nearest ``points`` (n, 3): a :class:`Surface` without faces holding the projected points.

    Examples
    --------
    On the x axis the surface is umbilic: k = 2 b / |4 a x^3 + 2 b x| (concave, b < 0).

    >>> s = goursat_at([[8.4, 0.0, 0.0]])
    >>> x = s.vertices[0, 0]
    >>> bool(np.isclose(s.k1[0], -4 / (0.12 * x ** 3 - 4 * x))), bool(s.k1[0] == s.k2[0])
    (True, True)
    """
    def function(x):
        return goursat_function(x, a, b, c)

    v = project_to_implicit(points, function)
    normals, k1, k2, d1, d2 = implicit_curvature(*function(v)[1:])
    return Surface("goursat", v, np.zeros((0, 3), np.int64), normals, k1, k2, d1, d2,
                   np.full(len(v), np.inf))


def add_normal_noise(surface, sigma_fraction, seed=0):
    """Copy of ``surface`` with Gaussian noise along the exact normals.

    ``sigma_fraction`` is the standard deviation as a fraction of the bounding-box diagonal
    (0.003 = 0.3 %). Exact curvature fields are kept as the ground truth.
    """
    rng = np.random.default_rng(seed)
    sigma = sigma_fraction * surface.diagonal
    v = surface.vertices + rng.normal(scale=sigma, size=(len(surface.vertices), 1)) * surface.normals
    return Surface(surface.name, v, surface.faces, surface.normals, surface.k1, surface.k2,
                   surface.d1, surface.d2, surface.border_distance)
