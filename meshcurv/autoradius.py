"""Automatic neighbourhood radius from the sampling density and an estimate of the noise.

The circle fits average noise over the ball: a height noise sigma (along the normal) on a
surface sampled with density rho (points per unit area) gives a curvature error of about

    s(R) = C * sigma / (sqrt(rho) * R^3)          (C ~ 6, measured; see below)

(least squares of h = kappa r^2 / 2 over ~ pi rho R^2 points spread over the disc: the variance
of kappa is 4 sigma^2 / (N var(r^2)) with var(r^2) = R^4 / 12). A larger ball averages more
noise away but blurs where curvature changes. :func:`auto_radius` takes the smallest radius whose
noise error is at most ``tolerance`` times the typical curvature of the surface, never smaller
than a ball of ``min_points`` points and never larger than ``max_angle / kappa`` (the ball must
stay a small cap of the curvature it measures) or ``max_fraction`` of the bounding-box diagonal.
The typical curvature comes from meshcurv itself on a sample of vertices, iterated from the
smallest radius up (a noise-dominated estimate only makes the next radius larger).

C was measured with meshcurv (unweighted fits, PCA normals) on a noisy icosphere:
mean (|dk1| + |dk2|) / 2 = 5.6 sigma / (sqrt(rho) R^3) within 5 % for R = 0.25 .. 0.7.
"""

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["auto_radius", "estimate_sampling", "NOISE_GAIN"]

# Curvature error per unit sigma / (sqrt(rho) R^3), measured (module docstring).
NOISE_GAIN = 5.6


def _sample(n, size, seed):
    if n <= size:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size, replace=False))


def estimate_sampling(vertices, k=24, sample=2000, seed=0):
    """Sampling density and normal noise of a point set, from local quadric fits.

    At each of up to ``sample`` vertices the ``k`` nearest neighbours (itself included) are put
    in their PCA frame and a quadric ``h = a + b u + c v + d u^2 + e uv + f v^2`` is fitted; the
    RMS residual, corrected for the 6 fitted parameters, estimates the noise along the normal
    (a quadric absorbs the curvature, so a clean smooth surface gives ~0).

    Parameters
    ----------
    vertices : (n, 3) float, model units (NaN rows ignored)
    k : int, neighbours per fit (>= 10)
    sample : int, vertices used (chosen at random with ``seed``)

    Returns
    -------
    density : float, points per unit area (median of k / (pi d_k^2))
    sigma : float, noise standard deviation along the normal, model units (median over the fits)

    Examples
    --------
    >>> from meshcurv import surfaces
    >>> s = surfaces.add_normal_noise(surfaces.sphere(1.0, 5), 0.003)
    >>> rho, sigma = estimate_sampling(s.vertices)
    >>> bool(abs(sigma / (0.003 * s.diagonal) - 1) < 0.2)
    True
    """
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be an (n, 3) array, got shape {v.shape}")
    v = v[np.isfinite(v).all(axis=1)]
    k = int(k)
    if k < 10:
        raise ValueError(f"k must be at least 10, got {k}")
    if len(v) < k:
        raise ValueError(f"need at least {k} finite vertices, got {len(v)}")
    tree = cKDTree(v)
    idx = _sample(len(v), sample, seed)
    dist, nb = tree.query(v[idx], k)
    density = float(np.median(k / (np.pi * np.maximum(dist[:, -1], 1e-300) ** 2)))
    q = v[nb] - v[nb].mean(axis=1, keepdims=True)                # (s, k, 3)
    _, _, vt = np.linalg.svd(q, full_matrices=False)             # rows of vt: PCA axes
    u, w, h = (np.einsum("skj,sj->sk", q, vt[:, i]) for i in range(3))
    design = np.stack([np.ones_like(u), u, w, u * u, u * w, w * w], axis=-1)
    # batched least squares through the normal equations (6 x 6 per point)
    a = np.einsum("ski,skj->sij", design, design)
    b = np.einsum("ski,sk->si", design, h)
    ok = np.linalg.cond(a) < 1e12
    coef = np.zeros((len(idx), 6))
    coef[ok] = np.linalg.solve(a[ok], b[ok][..., None])[..., 0]
    resid = h - np.einsum("ski,si->sk", design, coef)
    rms = np.sqrt(np.sum(resid ** 2, axis=1) / (k - 6))
    sigma = float(np.median(rms[ok])) if ok.any() else 0.0
    return density, sigma


def auto_radius(vertices, faces=None, *, tolerance=0.05, min_points=40, max_angle=0.7,
                max_fraction=0.1, sample=2000, seed=0, details=False, **settings):
    """Neighbourhood radius for :func:`meshcurv.principal_curvatures`, from sampling and noise.

    Parameters
    ----------
    vertices : (n, 3) float or trimesh.Trimesh, model units
    faces : (m, 3) int, optional (used for the pilot estimates, as the estimator would)
    tolerance : float, default 0.05
        Allowed noise error of the curvature, as a fraction of the surface's typical
        curvature (the median curvedness sqrt((k1^2 + k2^2) / 2) of a sample of vertices).
    min_points : int, default 40
        Smallest ball, in expected points (the clean-data radius).
    max_angle : float, default 0.7
        Largest radius as a multiple of 1 / typical curvature (radians of arc on a sphere).
    max_fraction : float, default 0.1
        Largest radius as a fraction of the bounding-box diagonal.
    sample : int, default 2000
        Vertices used for the noise estimate and the pilot curvature estimates.
    details : bool
        Also return a dict with density, sigma, kappa and the radii tried.
    settings : keyword options passed to the pilot ``principal_curvatures`` calls.

    Returns
    -------
    radius : float, model units (and the details dict if asked)

    Examples
    --------
    >>> from meshcurv import surfaces
    >>> s = surfaces.sphere(1.0, 4)
    >>> r_clean = auto_radius(s.vertices, s.faces)
    >>> r_noisy = auto_radius(surfaces.add_normal_noise(s, 0.003).vertices, s.faces)
    >>> bool(r_noisy > 1.5 * r_clean)
    True
    """
    from .estimator import principal_curvatures

    if hasattr(vertices, "vertices") and hasattr(vertices, "faces"):
        faces = vertices.faces if faces is None else faces
        vertices = vertices.vertices
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must be an (n, 3) array, got shape {v.shape}")
    if not (0 < tolerance and 0 < max_angle and 0 < max_fraction):
        raise ValueError("tolerance, max_angle and max_fraction must be positive")
    finite = np.isfinite(v).all(axis=1)
    density, sigma = estimate_sampling(v[finite], sample=sample, seed=seed)
    diag = float(np.linalg.norm(np.ptp(v[finite], axis=0)))
    r_min = np.sqrt(min_points / (np.pi * density))
    r_max = max(r_min, max_fraction * diag)
    if faces is not None:
        used = np.unique(np.asarray(faces, dtype=np.int64).ravel())
        pool = used[finite[used]]
    else:
        pool = np.flatnonzero(finite)
    query = pool[_sample(len(pool), sample, seed + 1)]
    pilot = dict(weighting="none", normal_estimation="pca")
    pilot.update(settings)
    radius, tried, kappa = r_min, [], np.nan
    for _ in range(8):
        res = principal_curvatures(v, faces, radius=radius, query=query, **pilot)
        kappa = float(np.nanmedian(res.curvedness)) if np.isfinite(res.k1).any() else np.nan
        tried.append((radius, kappa))
        if not np.isfinite(kappa) or kappa <= 0:
            new = r_max
        else:
            # smallest R with NOISE_GAIN sigma / (sqrt(rho) R^3) <= tolerance kappa
            r_noise = (NOISE_GAIN * sigma / (tolerance * kappa * np.sqrt(density))) ** (1 / 3)
            new = min(max(r_min, r_noise), max_angle / kappa, r_max)
        if abs(new - radius) <= 0.02 * radius:
            radius = new
            break
        radius = new
    radius = float(radius)
    if details:
        return radius, dict(density=density, sigma=sigma, kappa=kappa, r_min=r_min, r_max=r_max,
                            tried=tried)
    return radius
