"""Options of :func:`meshcurv.principal_curvatures`: the one table of their constraints.

The API, the command line, the pymeshlab filter and tiled runs check options here, before any
work starts (and without loading the compiled kernels).
"""

from dataclasses import dataclass, fields, replace
from typing import NamedTuple

import numpy as np

__all__ = ["Options", "OPTION_NAMES", "CHOICES", "ORIENTATIONS", "MAX_DIRECTIONS",
           "check_options", "Plan", "resolve_plan"]

# Research switches of the estimator: the fields of Options, in order.
SWITCH_NAMES = ("slab", "min_points", "min_spread", "weighting", "circle_normalization",
                "section_blend", "robust", "half_frequency", "bias_correction",
                "normal_estimation", "refine_normals", "orientation", "normal_fit",
                "normal_constraints", "robust_points", "sparse_retry", "coarse_fit",
                "area_weights", "ring_jet")
# Every option of principal_curvatures besides the data (vertices, faces, normals) and the
# call's own arguments (options, query, progress): its three public knobs and the switches.
OPTION_NAMES = ("radius", "n_directions", "neighborhood") + SWITCH_NAMES

# Options that take one of a few names.
CHOICES = {"neighborhood": ("auto", "kring", "ball"),
           "normal_estimation": ("auto", "faces", "pca"),
           "weighting": ("auto", "distance", "none"),
           "circle_normalization": ("tangent", "unit"),
           "normal_fit": ("auto", "sphere", "quadric"),
           "normal_constraints": ("auto", "off"),
           "coarse_fit": ("mls", "circles")}

# The named values of ``orientation`` (besides a (3,) viewpoint).
ORIENTATIONS = ("mst", "+z")

# Most planes through the normal (``n_directions``). Each kernel thread holds 2 x that many
# half-set accumulators and the robust step sorts the 2 x n_directions circle fits by insertion
# (quadratic); beyond 64 planes (2.8 degrees apart) the slabs of half-width 0.25 radius overlap
# so much that more planes add no information.
MAX_DIRECTIONS = 64


# Ranges of the numeric switches (low exclusive for slab, inclusive otherwise): a slab of
# half-width 0 holds no point and one wider than the ball holds the whole ball (every
# half-set sees every direction); a half-set cannot reach beyond the ball (min_spread <= 1).
# (name, low, high, whether low itself is allowed)
_RANGES = (("slab", 0.0, 1.0, False), ("min_points", 1.0, np.inf, True),
           ("min_spread", 0.0, 1.0, True))


def _check_in_range(name, value, low, high, low_allowed):
    """ValueError (one line) unless ``value`` is a real number in ``[low, high]`` (``(low,
    high]`` unless ``low_allowed``)."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        x = np.nan
    above = x >= low if low_allowed else x > low
    if isinstance(value, (bool, np.bool_, str)) or not (above and x <= high):
        side = "[" if low_allowed else "("
        raise ValueError(f"{name} must be a number in {side}{low:g}, {high:g}], got {value!r}")


def check_options(**options):
    """Check option names and values of :func:`meshcurv.principal_curvatures` without running it.

    Raises ValueError (one line) for an unknown name or a value out of its range; returns
    ``orientation``: "mst", "+z" or a (3,) float64 viewpoint.

    >>> check_options(n_directions=8, orientation=(0, 0, 10))
    array([ 0.,  0., 10.])
    >>> check_options(weighting="gauss")
    Traceback (most recent call last):
    ...
    ValueError: weighting must be one of 'auto', 'distance', 'none', got 'gauss'
    """
    unknown = sorted(set(options) - set(OPTION_NAMES))
    if unknown:
        raise ValueError(f"unknown estimator option: {', '.join(unknown)} (known: "
                         f"{', '.join(OPTION_NAMES)})")
    for name, allowed in CHOICES.items():
        if name in options and options[name] not in allowed:
            raise ValueError(f"{name} must be one of {', '.join(map(repr, allowed))}, "
                             f"got {options[name]!r}")
    if "n_directions" in options:
        nd = options["n_directions"]
        try:
            ok = float(nd) == int(nd) and 3 <= int(nd) <= MAX_DIRECTIONS
        except (TypeError, ValueError, OverflowError):
            ok = False
        if not ok:
            raise ValueError(f"n_directions must be a whole number from 3 to {MAX_DIRECTIONS}, "
                             f"got {nd!r}")
    for name, *bounds in _RANGES:
        if name in options:
            _check_in_range(name, options[name], *bounds)
    if "min_points" in options and not float(options["min_points"]).is_integer():
        raise ValueError(f"min_points must be a whole number, got {options['min_points']!r}")
    orientation = options.get("orientation", "mst")
    if isinstance(orientation, str) and orientation in ORIENTATIONS:
        return orientation
    if not isinstance(orientation, str):
        orientation = np.asarray(orientation, dtype=np.float64)
    if isinstance(orientation, str) or orientation.shape != (3,) or not np.isfinite(
            orientation).all():
        raise ValueError(f"orientation must be 'mst', '+z' or a finite (3,) viewpoint, "
                         f"got {options['orientation']!r}")
    return orientation


@dataclass(frozen=True)
class Options:
    """The research switches of :func:`meshcurv.principal_curvatures`, checked when made.

    The defaults are the estimator's; change one with ``Options(weighting="none")`` or
    ``options.replace(robust=False)``, or pass it by name to ``principal_curvatures``.

    Parameters
    ----------
    slab : float, default 0.25
        Half-width of each plane's slab, as a fraction of ``radius``. Wider slabs use more
        points (less noise) at the price of a blend of directions, which ``section_blend``
        models. Where the data are clean a point's weight tapers to 0 at the slab's edges
        (:func:`meshcurv.fit.circle.add_half_set`).
    min_points : int, default 3
        Fewest neighbors (besides x) a half-set needs to be fitted.
    min_spread : float, default 0.25
        Fewest fraction of ``radius`` the farthest point of a half-set must reach along its
        direction; rejects one-sided stubs near borders and holes.
    weighting : {"auto", "distance", "none"}
        Weights of the points in each circle fit. "distance": ``(1 - r^2 / radius^2)^4``,
        which favours near points: where the curvature varies inside the ball it halves the
        error of equal weights (Table 2 paraboloid, radius 2: mean |dk1| 0.0015 vs 0.0030).
        "none": equal weights, about a third of the noise-induced error. "auto" (default): per
        vertex, distance weights where the local cubic fit leaves no noise and equal weights
        where it does, mixed smoothly (:func:`meshcurv.pipeline.weight_blend`).
    circle_normalization : {"tangent", "unit"}
        Normalisation of the CGA sphere vector t in each circle fit. "unit": |t| = 1, the
        smallest eigenvector of the 3x3 matrix (the paper). "tangent" (default): t1 = 1, the
        same eigenproblem with normalisation matrix diag(1, 0, 0); identical on exact data, but
        it cannot drift to spheres centred at x, whose curvature is unbounded - with noise of
        15 % of the radius the unit form has a 6x wider spread and 1000x outliers.
    section_blend : bool, default True
        Fit the Euler model to the direction mix each half-set really measured (from its own
        points) instead of the plane's nominal angle. Removes the slab's blurring of k1 - k2.
    robust : bool, default True
        Drop circle fits further than 3 robust sigmas from the Euler model and refit.
    half_frequency : bool, default False
        Add ``cos theta, sin theta`` terms (the paper's half-frequency fit, linear form) to
        absorb differences between opposite directions.
    bias_correction : bool, default True
        Remove the circle model's bias where the data are clean: a second fit over the
        same neighbors within ``BIAS_RATIO * radius`` and the extrapolation of the shape
        operator to radius 0 (the bias grows like radius^2), mixed in by the measured noise
        like the weights (:func:`meshcurv.fit.extrapolate.extrapolate_to_zero`).
    normal_estimation : {"auto", "faces", "pca"}
        Used when ``normals`` is None. "faces": area-weighted face normals. "pca": normal of
        the least-squares plane through the same neighborhood, oriented by the faces if there
        are any, else by ``orientation``. "auto" (default): on meshes, the two mixed per
        vertex by their expected errors (:func:`meshcurv.pipeline.face_weights`: the face
        normals' from the mesh's own roughness, about noise / edge length), so smooth meshes
        get their face normals and noisy ones the plane fits; on clouds "pca". Plane fits
        tilt with the curvature across a truncated or uneven ball: open cylinder 32 x 16 at
        the default radius, max |K| / k1^2 0.0086 with them, 2e-8 with the mix. Face normals
        are the worst choice on noisy meshes (0.3 % noise, random sphere: mean |dk1| + |dk2|
        0.60 with face normals, 0.38 with PCA ones; max |dk1| 13 vs 0.9).
    refine_normals : bool, None or "auto", default None
        Refine the normals by a local fit over the same neighborhood (``normal_fit``) before
        the circle fits, mixed with the starting normal by the measured noise (the mix of
        ``weighting="auto"``, :func:`meshcurv.pipeline.weight_blend`, whatever ``weighting``
        is): face and PCA normals tilt with irregular sampling (0.7 degrees on a random
        sphere, up to 3 % in curvature), the jet's normal does not but is noisier (its
        quartic's gradient where the data are clean, its quadric's under noise:
        :func:`meshcurv.fit.jet.local_jet`). None: refine estimated normals, use given ones as
        they are. "auto": refine estimated normals; given ones are
        kept where the data agree with them and mixed with the fitted normal where a test
        over the whole input finds them noisier than the points
        (:func:`meshcurv.pipeline.given_normal_noise`; exact given normals stay bit for bit).
        Measured on the benchmark clouds with normal noise sigma_xi 0.1-0.2: mean |dk| 5-14x
        smaller on clean points, 3-10 % smaller with position noise 0.1-0.2. Not the default:
        the test is over the input, so tiled runs would differ from untiled ones. True: refine
        given normals like estimated ones; False: never.
    orientation : "mst", "+z" or (3,) array-like
        Global orientation of estimated point-cloud normals (meshes follow their faces).
        "mst" (default): signs propagated along a minimum spanning tree, then one sign per
        connected piece (:func:`meshcurv.normals.orient.piece_signs`): a closed piece (its
        mean unit normal shorter than 0.25: by Gauss' theorem a closed surface's normals sum
        to zero) points outward, ``sum (p - centroid) . n > 0`` (3 x its volume, right on
        non-convex shapes too); an open piece (a one-sided view) points towards +z, the side a
        viewer above sees (a dome, a terrain, the top of a torus, the inside of a bowl); an
        open piece facing sideways (mean normal within ~6 degrees of horizontal) points away
        from its centroid. "+z": every normal towards +z on its own (``n_z >= 0``; aerial
        scans, the command line's default for LAS/LAZ input; walls stay undecided). A (3,)
        point: every normal towards it (a scanner position; exact for what a scanner there
        saw). ``result.orientation`` says which rule was used.
    normal_fit : {"auto", "sphere", "quadric"}, default "auto"
        The fit that refines normals (``refine_normals``). "quadric": the local jet's height
        fits (:func:`meshcurv.fit.jet.local_jet`: the quartic's gradient where the data are
        clean, the quadric's under noise). "sphere": the Pratt-normalised
        algebraic sphere/plane fit of the paper's section 4
        (:func:`meshcurv.normals.sphere.sphere_normals`), exact on spheres and planes
        whatever the sampling, but tilted where the shape is far from a sphere. "auto": the
        two mixed per vertex by how much of the sphere fit's residual is noise
        (:func:`meshcurv.pipeline.sphericity`). Measured (own normals, clean clouds): random
        sphere mean relative |dk| 6e-5 with "quadric", 5e-10 with "sphere" and "auto";
        paraboloid 2.7e-3 / 1.5e-2 / 2.7e-3, benchmark torus 3.8e-3 / 4.7e-3 / 3.8e-3,
        Goursat 1.8e-2 / 1.9e-2 / 1.8e-2; with position noise all three alike (the noise
        mix then keeps the PCA normal).
    normal_constraints : {"auto", "off"}
        "auto": where every point has a normal before the circle fits (given normals, the
        spanning-tree normals of clouds, the face normals of meshes) each half-set's circle
        fit also fits its neighbors' normals: along the half-set's direction e the normal
        turns by (n_p - n_x) . e = kappa (p . e), rows added to the least squares with the
        weight of their measured reliability (the ratio of the position rows' and the normal
        rows' residual variances, pooled per vertex), so noisy normals count little and exact
        ones dominate under position noise. Estimated normals (and given ones refined with
        ``refine_normals=True``) carry nothing beyond the positions where those are clean: their
        rows' weight is scaled by the measured noise blend (0 on clean data). Measured (mean
        |dH| over the six clouds of Lachaud et al. 2023 at the default radius, ~100
        neighbors): with exact normals and position noise 0.1 / 0.2: 0.087 -> 0.0060 and
        0.195 -> 0.0092; with normals of noise 0.1 as well 0.087 -> 0.013; clean, or clean
        positions with noisy normals: unchanged; without normals (spanning-tree normals)
        0.087 -> 0.016 and 0.194 -> 0.022. Noisy meshes (0.3 % noise, torus, paraboloid,
        spheres): mean |dk| 4.7-5.7x lower; clean meshes unchanged (torus 240 x 60 0.0085 ->
        0.0069). Cost: +0-10 % on clouds, +25 % on meshes (the plane-fit normals of every
        vertex before the blocks); on noisy meshes the wider field of those normals
        (``Plan.wide_field``) cuts the error by up to 3x more (torus 240 x 60, 0.3 % noise:
        0.036 -> 0.015; ellipsoid 0.056 -> 0.054) at 1.6-1.7x the time (300k vertices, 0.1 %
        noise). A tiled run's halo then covers two radii. "off": positions only.
    robust_points : bool, default True
        Down-weight stray points (scanner spikes) in every fit: each point gets an outlier
        score, its distance from a robust (Tukey-reweighted) height fit of its neighborhood
        in robust noise scales, as a Gaussian deviate (:mod:`meshcurv.fit.outliers`); its
        weight in the normals, the local jet and the circle fits is 1 up to a score of 2, then
        descends to 0 at 4.685, where the point is flagged (``Status.OUTLIER``, no curvature).
        With 2 % of a noisy sphere's vertices pushed 1-4 % of the diagonal off it, the good
        vertices off by more than 10 % drop from 45 % to none; on clean surfaces every weight
        is 1 (results unchanged). Costs one more pass over the points, with a cubic fit and up
        to three reweighted ones each (none where no residual reaches 4.685 robust scales: clean
        data, Gaussian noise): 0.7 s of a 4.1 s default run (torus of 250k vertices, normals
        given, 2 threads; 1.0 s of 3.5 s with noise of 0.1 % of the diagonal).
    sparse_retry : bool, default True
        Re-estimate the vertices whose ball holds too few points - their fit failed for lack
        of points (no 5 usable half-sets, an ill-posed or one-directional Euler fit, no plane
        fit), or the local cubic fit had no 11 points to measure noise and refine the normal -
        at 1.5, 2, 3 and 4 times ``radius``, each at the smallest that serves while its ball
        holds at most a quarter of the points (a local patch, not the other side of a small
        object); where none does, with half-sets of a single point (a coarse mesh's 1-ring).
        Clumpy or gappy sampling and density falling across a scan otherwise leave such
        vertices invalid, or estimated from a handful of points with a PCA normal a clump can
        tilt (clumpy unit-sphere clouds without normals: |dk| up to 9). On clouds with
        estimated normals an estimate from fewer than 11 points that no larger ball replaces
        is dropped (``TOO_FEW_NEIGHBORS``). The other way round, on meshes and on clouds
        whose normals are given and used as they are, vertices whose ball reaches around the
        surface (``WRAPS_AROUND``: a small part beside a large one, a thin tube) are
        estimated at 1/2, 1/4, 1/8 and 1/16 of ``radius``, each at the largest that serves,
        as a call at that radius would estimate them (clouds with estimated normals keep
        ``WRAPS_AROUND``: their shape test still passes some balls about 2.8 times wider
        than a tube, where a smaller ball could land).
        ``result.n_neighbors`` is the count of the ball used, ``result.radius_used`` its
        radius; ``result.radius`` stays the call's. A radius list and ``radius="auto"``
        retry sparse rows only. False: every vertex at ``radius`` alone (tiled runs, whose
        halo covers that radius only).
    coarse_fit : {"mls", "circles"}, default "mls"
        Inputs coarse for their shape (the default radius had to be made smaller because
        balls of ~100 points reached around the shape: a low-poly torus), estimated at their
        default radius: "mls" blends in, row by row as the measured noise allows, the
        curvature of the MLS surface of oriented spheres through the points and the circle
        fits' normals (:mod:`meshcurv.coarse`; trimesh tori of 16-32 vertices around the
        tube: mean |dk| 0.0020-0.022 instead of 0.022-0.069 on the meshes, 0.0025-0.018
        instead of 0.019-0.068 on their points alone; of 12, meshes, 0.0063-0.011 instead
        of 0.054-0.195); the normals, d1 and d2 of those rows are
        the MLS surface's. Other inputs, at their default radius, a given radius or each of
        a list of radii, get the same blend where a probe of 256 rows finds the circle fits
        limited by a regular sampling (:func:`meshcurv.coarse.sampling_limited`: tori of
        96 x 24 to 360 x 60 vertices, mean |dk| 4-15x smaller); elsewhere they keep the
        circle fits' bits; ``radius="auto"`` is blended where its default radius is.
        "circles": the circle fits alone.
    area_weights : bool, default True
        Every point weighs in the MLS surface's fits (the probe of ``coarse_fit`` and the
        blend's passes) by the area it stands for, times its outlier weight: a mesh vertex
        by a third of its faces' areas, a cloud point by the squared distance to its 6th
        nearest (:mod:`meshcurv.area_weights`). Those fits then sum over the surface, not
        over the sampling, where that is uneven; they weigh the evaluation point like the
        others, so points of equal areas give what they gave. The probe blends where the
        weighted or the unweighted MLS surface finds the circle fits limited
        (:func:`meshcurv.coarse.estimate`). Meshes decimated by MeshLab's quadric edge
        collapse (denser where the surface bends more), mean |dk|: ellipsoid at 10 % 0.0105
        -> 0.0029 (the probe now takes the blend), torus at 5 % 0.022 -> 0.018; their points
        alone 0.0103 -> 0.0036 and 0.024 -> 0.020; coarse tori -15 % to +11 % (README). The
        circle fits and the local jet stay unweighted: they weigh the point itself 1
        whatever its neighbours weigh, so a mesh with parts of very different vertex
        spacing lost rows there, and weighted they cost the tori with 0.1 % noise 2 % (the
        normals' plane fits weighted too: 70 %). False: every point weighs alike.
    ring_jet : bool, default True
        At the default radius and with ``radius="auto"`` (a radius given is kept), each
        valid row's curvature moves towards that of a quartic height fit over the vertex's
        3-ring (a cloud point's 36 nearest) where that fit is measurably the more accurate:
        where it differs from the circle fits by more than a margin of its expected error
        (on a mesh three times its standard error, on a cloud twice the most its residuals
        could move it; with its change to the 4-ring in both), by the part beyond
        (:mod:`meshcurv.jet_blend`; ``result.jet_share``). Clean ellipsoid meshes, mean
        |dk|: 3 / 1 / 0.5 of 2562 / 10242 vertices 0.096 / 0.016 -> 0.031 / 0.0048; 20k
        random vertices of an egg crate and a saddle 0.0012 / 0.0005 -> 0.00001 / 0.000001;
        no row of the noisy inputs checked took a jet (README, step 10). False: the circle
        fits (and MLS blend) alone.

    Examples
    --------
    >>> Options(weighting="none").replace(robust=False).robust
    False
    >>> Options(slab=0.3, weighting="gauss")
    Traceback (most recent call last):
    ...
    ValueError: weighting must be one of 'auto', 'distance', 'none', got 'gauss'
    """

    slab: float = 0.25
    min_points: int = 3
    min_spread: float = 0.25
    weighting: str = "auto"
    circle_normalization: str = "tangent"
    section_blend: bool = True
    robust: bool = True
    half_frequency: bool = False
    bias_correction: bool = True
    normal_estimation: str = "auto"
    refine_normals: object = None
    orientation: object = "mst"
    normal_fit: str = "auto"
    normal_constraints: str = "auto"
    robust_points: bool = True
    sparse_retry: bool = True
    coarse_fit: str = "mls"
    area_weights: bool = True
    ring_jet: bool = True

    def __post_init__(self):
        check_options(**self.as_dict())

    def as_dict(self):
        """``{name: value}`` of every switch, in field order."""
        return {f.name: getattr(self, f.name) for f in fields(self)}

    def replace(self, **switches):
        """A copy with these switches changed (ValueError for an unknown name or value)."""
        check_options(**switches)
        unknown = sorted(set(switches) - set(SWITCH_NAMES))
        if unknown:
            raise ValueError(f"{', '.join(unknown)} is not a switch of Options (known: "
                             f"{', '.join(SWITCH_NAMES)})")
        return replace(self, **switches)

    @classmethod
    def merged(cls, options=None, switches=None):
        """``options`` (default ``Options()``) with ``switches`` ({name: value}) applied."""
        if options is None:
            options = cls()
        elif not isinstance(options, cls):
            raise ValueError(f"options must be a meshcurv.Options, got {type(options).__name__}")
        return options.replace(**switches) if switches else options


class Plan(NamedTuple):
    """How one estimate runs, resolved from the options and what the input holds
    (:func:`resolve_plan`); read by :func:`meshcurv.pipeline.run`.

    ``use_kring``: k-ring neighborhoods (else ball queries). ``normals``: "given" (used as
    they are), "faces" (area-weighted face normals), "pca" (plane fits block by block, oriented
    like the face normals if there are faces, else towards ``viewpoint``, else towards +z) or
    "mst" (plane fits of all points first, oriented along a spanning tree). ``refine``: refined
    normals, by the fit ``normal_fit`` ("auto", "sphere" or "quadric"). ``check_given``: given
    normals kept except where the data disagree with them (``refine_normals="auto"``).
    ``weighting``: as the option. ``bias_correction``: as the option (a second, smaller fit
    extrapolated to radius 0). ``fit``: the fused kernel's settings ``(n_directions, slab,
    min_points, min_spread, unit_norm, section_blend, half_frequency, robust)``, typed.
    ``normal_constraints``: normal-aware circle fits where a normal field exists.
    ``robust_points``: the point-outlier pass and its weights.
    ``sparse_retry``: as the option. ``face_mix``: "pca" normals mixed with the face normals
    by their expected errors (``normal_estimation="auto"`` on a mesh). ``wide_field``:
    estimated normals for the normal-aware fits mixed, point by point, with plane fits over a
    neighborhood :data:`meshcurv.pipeline.FIELD_RATIO` times the radius (clouds; meshes where
    they are noisy, :data:`meshcurv.pipeline.WIDE_FIELD_GAIN`;
    :func:`meshcurv.pipeline.field_mix`; off under ``radius="auto"``, whose
    ladder widens the balls themselves where the noise asks for it: CNC clouds without
    normals at sigma_eps 0.1, mean |dH| 0.0095 with the field at each radius, 0.0119 with it
    wider). ``coarse_mls``: inputs coarse for their shape, at their default radius, blended
    with the MLS surface's curvature (:mod:`meshcurv.coarse`). ``area_weights``: points
    weighted by their areas in the MLS surface's fits (:mod:`meshcurv.area_weights`).
    ``ring_jet``: rows at a radius meshcurv chose moved towards their ring jets
    (:mod:`meshcurv.jet_blend`).
    """

    use_kring: bool
    normals: str
    viewpoint: object
    refine: bool
    weighting: str
    bias_correction: bool
    fit: tuple
    normal_fit: str = "auto"
    check_given: bool = False
    normal_constraints: bool = False
    robust_points: bool = True
    sparse_retry: bool = True
    face_mix: bool = False
    wide_field: bool = True
    coarse_mls: bool = False
    area_weights: bool = False
    ring_jet: bool = False


def resolve_plan(has_faces, has_normals, n_directions=8, neighborhood="auto", slab=0.25,
                 min_points=3, min_spread=0.25, weighting="auto",
                 circle_normalization="tangent", section_blend=True, robust=True,
                 half_frequency=False, bias_correction=True, normal_estimation="auto",
                 refine_normals=None, orientation="mst", normal_fit="auto",
                 normal_constraints="auto", robust_points=True, sparse_retry=True,
                 coarse_fit="mls", area_weights=True, ring_jet=True):
    """The :class:`Plan` of a call with these options (the defaults of
    :func:`meshcurv.principal_curvatures`) on input with or without faces and given normals.

    Raises ValueError (one line) where :func:`check_options` does, and for a k-ring
    neighborhood or face normals without faces.

    >>> resolve_plan(False, False).normals
    'mst'
    >>> resolve_plan(True, False, neighborhood="ball").use_kring
    False
    """
    orientation = check_options(neighborhood=neighborhood, normal_estimation=normal_estimation,
                                orientation=orientation, weighting=weighting,
                                circle_normalization=circle_normalization,
                                n_directions=n_directions, normal_fit=normal_fit,
                                normal_constraints=normal_constraints,
                                coarse_fit=coarse_fit)
    if neighborhood == "kring" and not has_faces:
        raise ValueError("neighborhood='kring' needs faces")
    if normal_estimation == "faces" and not has_normals and not has_faces:
        raise ValueError("normal_estimation='faces' needs faces")
    viewpoint = None if isinstance(orientation, str) else orientation
    if has_normals:
        normals = "given"
    elif normal_estimation == "faces":
        normals = "faces"
    else:
        spanning_tree = isinstance(orientation, str) and orientation == "mst"
        normals = "mst" if spanning_tree and not has_faces else "pca"
    fit = (int(n_directions), float(slab), float(min_points), float(min_spread),
           circle_normalization == "unit", bool(section_blend), bool(half_frequency),
           bool(robust))
    if not (refine_normals is None or isinstance(refine_normals, (bool, np.bool_))
            or (isinstance(refine_normals, str) and refine_normals == "auto")):
        raise ValueError(f"refine_normals must be None, True, False or 'auto', "
                         f"got {refine_normals!r}")
    auto = isinstance(refine_normals, str)
    refine = not has_normals if refine_normals is None or auto else bool(refine_normals)
    return Plan(has_faces and neighborhood != "ball", normals, viewpoint, refine, weighting,
                bool(bias_correction), fit, normal_fit, has_normals and auto,
                normal_constraints == "auto", bool(robust_points),
                bool(sparse_retry), normals == "pca" and has_faces and normal_estimation == "auto",
                coarse_mls=coarse_fit == "mls", area_weights=bool(area_weights),
                ring_jet=bool(ring_jet))
