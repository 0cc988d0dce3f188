"""One neighborhood radius for a whole input from the sampling density, a noise estimate and a
bias probe (a function for users and scripts; ``radius="auto"`` of the estimator is the
per-vertex scale of :mod:`meshcurv.scale`, which measures noise and bias at every vertex).

The mean curvature error of the estimator at radius R is modelled as noise plus bias,

    E(R) = N(R) + B(R),    N(R) = C sigma / (sqrt(rho) R^3),    B(R) = beta R^2

- N: a height noise sigma (along the normal) on a surface sampled with density rho (points per
  unit area), averaged over the ~ pi rho R^2 points of the ball (least squares of
  h = kappa r^2 / 2 over a disc: var(kappa) = 4 sigma^2 / (N var(r^2)), var(r^2) = R^4 / 12).
  sigma and rho come from local quadric fits (:func:`estimate_sampling`); C was measured.
- B: the circle model's error where curvature varies (zero on a sphere, where every normal
  section is a circle). beta is measured on the data: the estimator runs at two radii
  R_a < R_b on a sample of vertices; the mean change of (k1, k2) between them, less the part the
  noise model explains (nested least-squares estimates differ by sqrt(N_a^2 - N_b^2)), is
  beta (R_b^2 - R_a^2).

:func:`auto_radius` returns the minimiser of E, R = (3 C sigma / (2 beta sqrt(rho)))^(1/5),
never smaller than a ball of ``min_points`` points and never larger than ``max_angle / kappa``
(the ball stays a small cap of the curvature it measures) or ``max_fraction`` of the
bounding-box diagonal. With no measurable bias (a sphere) that upper bound is the answer; on
clean data (sigma ~ 0) the lower one.

C depends on the weights of the circle fits; measured with meshcurv (PCA normals) on unit
icospheres of 2562 and 10242 vertices with 0.1 % and 0.3 % noise, R = 0.3 .. 0.6:
mean (|dk1| + |dk2|) / 2 = C sigma / (sqrt(rho) R^3) with C = 5.2 .. 5.7 for
``weighting="none"`` and C = 13.7 .. 17 for ``weighting="distance"`` (weights (1 - r^2/R^2)^4
leave fewer effective points, so the same radius averages less noise away).

Usage, with the options of the estimate it is for (``min_points`` is here the smallest
ball)::

    radius = auto_radius(vertices, faces, normals=normals, weighting=weighting, slab=slab,
                         n_directions=n_directions, orientation=orientation, ...)
    res = principal_curvatures(vertices, faces, normals=normals, radius=radius, ...)
"""

import numpy as np
from scipy.spatial import cKDTree

from . import pipeline
from .inputs import as_arrays
from .neighbors import default_radius, power_of_two_scale, typical_extent
from .options import resolve_plan

__all__ = ["auto_radius", "estimate_sampling", "NOISE_GAIN"]

# Curvature error per unit sigma / (sqrt(rho) R^3) for each circle-fit weighting, measured
# (module docstring).
# "auto" weighting turns to equal weights where the data are noisy, so it has their gain.
NOISE_GAIN = {"none": 5.6, "distance": 15.5, "auto": 5.6}


def _sample(n, size, seed):
    if n <= size:
        return np.arange(n)
    return np.sort(np.random.default_rng(seed).choice(n, size, replace=False))


def estimate_sampling(vertices, k=24, sample=2000, seed=0):
    """Sampling density and normal noise of a point set, from local quadric fits.

    At each of up to ``sample`` vertices the ``k`` nearest neighbors (itself included) are put
    in their PCA frame and a quadric ``h = a + b u + c v + d u^2 + e uv + f v^2`` is fitted; the
    RMS residual, corrected for the 6 fitted parameters, estimates the noise along the normal
    (a quadric absorbs the curvature, so a clean smooth surface gives ~0).

    Parameters
    ----------
    vertices : (n, 3) float, model units (NaN rows ignored)
    k : int, neighbors per fit (>= 10)
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
    # k-d tree distances whose squares overflow come back inf (and index n): far points
    far = ~np.isfinite(dist[:, -1])
    dist, nb = dist[~far], nb[~far]
    if len(nb) == 0:
        return float("nan"), float("nan")
    with np.errstate(divide="ignore", under="ignore"):      # duplicates: d_k = 0
        density = float(np.median(k / (np.pi * np.maximum(dist[:, -1], 1e-300) ** 2)))
    with np.errstate(over="ignore", invalid="ignore"):
        q = v[nb] - v[nb].mean(axis=1, keepdims=True)                # (s, k, 3)
    # neighborhoods too large for the quadric's moments in float64 (a far point's): left out
    sane = np.all(np.abs(q) < 1e60, axis=(1, 2))   # design moments: 4th powers
    idx, q = idx[~far][sane], q[sane]
    if len(q) == 0:
        return density, float("nan")
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


def _pilot(v, faces, normals, finite, sample, seed, settings):
    """The pilot estimate ``radius -> CurvatureResult`` on a sample of the (used, finite)
    vertices, with the caller's ``settings`` (PCA normals unless they say otherwise)."""
    if faces is not None:
        used = np.unique(np.asarray(faces, dtype=np.int64).ravel())
        pool = used[finite[used]]
    else:
        pool = np.flatnonzero(finite)
    query = pool[_sample(len(pool), sample, seed + 1)]
    pilot = dict(normal_estimation="pca")
    pilot.update(settings)
    plan = resolve_plan(faces is not None, normals is not None, **pilot)

    def estimate(radius):
        return pipeline.run(v, faces, normals, float(radius), query, plan)
    return estimate


def _balanced_radius(gain, sigma, density, beta, r_min, r_max):
    """The radius where noise and bias errors balance, d/dR (C sigma / (sqrt(rho) R^3) +
    beta R^2) = 0, within [r_min, r_max]."""
    if beta > 0 and sigma > 0:
        radius = (3 * gain * sigma / (2 * beta * np.sqrt(density))) ** 0.2
    elif beta > 0:
        radius = r_min
    else:
        radius = r_max
    return float(min(max(radius, r_min), r_max))


def auto_radius(vertices, faces=None, normals=None, *, weighting="none", min_points=40,
                max_angle=0.7, max_fraction=0.25, tolerance=0.05, probe_ratio=1.6, sample=2000,
                seed=0, details=False, **settings):
    """Neighborhood radius for :func:`meshcurv.principal_curvatures` that balances noise and
    bias (module docstring), chosen per mesh.

    Parameters
    ----------
    vertices : (n, 3) float or trimesh.Trimesh, model units
    faces : (m, 3) int, optional (used for the pilot estimates, as the estimator would)
    normals : (n, 3) float, optional, outward normals passed to the pilot estimates
    weighting : {"none", "distance", "auto"}, default "none"
        Circle-fit weights the radius is chosen for (and used by the pilot estimates); distance
        weights need a ~1.4x larger ball for the same noise error (``NOISE_GAIN``).
    min_points : int, default 40
        Smallest ball, in expected points.
    max_angle : float, default 0.7
        Largest radius as a multiple of 1 / kappa, kappa the median curvedness
        sqrt((k1^2 + k2^2) / 2) of a sample of vertices (radians of arc on a sphere).
    max_fraction : float, default 0.25
        Largest radius as a fraction of the bounding-box diagonal.
    tolerance : float, default 0.05
        Noise error (fraction of kappa) of the smaller bias probe R_a; keeps the probe out of
        the noise.
    probe_ratio : float, default 1.6
        R_b / R_a of the bias probe.
    sample : int, default 2000
        Vertices used for the noise estimate and the pilot curvature estimates.
    details : bool
        Also return a dict with density, sigma, kappa, beta, the probe radii and the bounds.
    settings : keyword options passed to the pilot ``principal_curvatures`` calls
        (``normal_estimation``, ``slab``, ``n_directions``, ...; default PCA normals).

    Returns
    -------
    radius : float, model units (and the details dict if asked)

    Examples
    --------
    >>> from meshcurv import surfaces
    >>> s = surfaces.sphere(1.0, 4)
    >>> r = auto_radius(surfaces.add_normal_noise(s, 0.003).vertices, s.faces)
    >>> bool(0.6 < r <= 0.7)      # no bias on a sphere: the largest ball, 0.7 / kappa
    True
    """
    v, faces, normals = as_arrays(vertices, faces, normals)
    if not (0 < tolerance and 0 < max_angle and 0 < max_fraction and probe_ratio > 1):
        raise ValueError("tolerance, max_angle, max_fraction must be positive, probe_ratio > 1")
    if weighting not in NOISE_GAIN:
        raise ValueError(f"weighting must be one of {sorted(NOISE_GAIN)}, got {weighting!r}")
    gain = NOISE_GAIN[weighting]
    s = power_of_two_scale(typical_extent(v, sample, seed))
    if s != 1.0:
        # a cloud too large (small) to square its lengths in float64: measured on coordinates
        # scaled by a power of two (exact), the radius scaled back
        if not isinstance(settings.get("orientation", "mst"), str):
            settings["orientation"] = np.asarray(settings["orientation"], dtype=np.float64) * s
        with np.errstate(over="ignore"):
            out = auto_radius(v * s, faces, normals, weighting=weighting, min_points=min_points,
                              max_angle=max_angle, max_fraction=max_fraction,
                              tolerance=tolerance, probe_ratio=probe_ratio, sample=sample,
                              seed=seed, details=details, **settings)
        if details:
            return out[0] / s, out[1]
        return out / s
    finite = np.isfinite(v).all(axis=1)
    density, sigma = (estimate_sampling(v[finite], sample=sample, seed=seed)
                      if finite.sum() >= 24 else (np.nan, np.nan))
    if not (np.isfinite(density) and density > 0 and np.isfinite(sigma)):
        # too few (distinct) points for the noise estimate: the sampling-only default
        radius = default_radius(v, faces=faces)
        return (radius, dict(density=np.nan, sigma=np.nan, kappa=np.nan, beta=np.nan,
                             r_min=radius, r_max=radius, probes=())) if details else radius
    with np.errstate(over="ignore", invalid="ignore"):        # far points: inf
        diag = float(np.linalg.norm(np.ptp(v[finite], axis=0)))
    r_min = np.sqrt(min_points / (np.pi * density))
    estimate = _pilot(v, faces, normals, finite, sample, seed, dict(settings, weighting=weighting))

    def noise(radius):
        return gain * sigma / (np.sqrt(density) * radius ** 3)

    # typical curvature -> upper bound of the radius
    kappa = float(np.nanmedian(estimate(r_min).curvedness))
    r_max = max_fraction * diag
    if np.isfinite(kappa) and kappa > 0:
        r_max = min(r_max, max_angle / kappa)
    r_max = max(r_min, r_max)
    # bias probe at R_a (noise error ~ tolerance kappa) and R_b = probe_ratio R_a
    r_a = r_min
    if np.isfinite(kappa) and kappa > 0:
        r_a = (gain * sigma / (tolerance * kappa * np.sqrt(density))) ** (1 / 3)
    r_a = max(r_min, min(r_a, r_max / probe_ratio))
    r_b = probe_ratio * r_a
    a, b = estimate(r_a), estimate(r_b)
    with np.errstate(invalid="ignore"):
        change = float(np.nanmean(0.5 * (np.abs(a.k1 - b.k1) + np.abs(a.k2 - b.k2))))
    # the noise part of the change of nested least-squares estimates: sqrt(N_a^2 - N_b^2)
    bias = np.sqrt(max(change ** 2 - max(noise(r_a) ** 2 - noise(r_b) ** 2, 0.0), 0.0))
    beta = bias / (r_b ** 2 - r_a ** 2) if np.isfinite(bias) else 0.0
    # the larger probe averages more noise away: a better typical curvature for the bound
    kappa_b = float(np.nanmedian(b.curvedness))
    if np.isfinite(kappa_b) and kappa_b > 0:
        kappa = kappa_b
        r_max = max(r_min, min(max_fraction * diag, max_angle / kappa))
    radius = _balanced_radius(gain, sigma, density, beta, r_min, r_max)
    if details:
        return radius, dict(density=density, sigma=sigma, kappa=kappa, beta=beta, r_min=r_min,
                            r_max=r_max, probes=(r_a, r_b), change=change)
    return radius
