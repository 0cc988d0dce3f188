"""Options of :func:`meshcurv.principal_curvatures`: the one table of their constraints.

The API, the command line, the pymeshlab filter and tiled runs check options here, before any
work starts (and without loading the compiled kernels).
"""

from dataclasses import dataclass, fields, replace
from typing import NamedTuple

import numpy as np

__all__ = ["Options", "OPTION_NAMES", "CHOICES", "MAX_DIRECTIONS", "check_options", "Plan",
           "resolve_plan"]

# Research switches of the estimator: the fields of Options, in order.
SWITCH_NAMES = ("slab", "min_points", "min_spread", "weighting", "circle_normalization",
                "section_blend", "robust", "half_frequency", "normal_estimation",
                "refine_normals", "orientation", "sparse_retry")
# Every option of principal_curvatures besides the data (vertices, faces, normals) and the
# call's own arguments (options, query, progress): its three public knobs and the switches.
OPTION_NAMES = ("radius", "n_directions", "neighborhood") + SWITCH_NAMES

# Options that take one of a few names.
CHOICES = {"neighborhood": ("auto", "kring", "ball"),
           "normal_estimation": ("auto", "faces", "pca"),
           "weighting": ("auto", "distance", "none"),
           "circle_normalization": ("tangent", "unit")}

# Most planes through the normal (``n_directions``). Each kernel thread holds 2 x that many
# half-set accumulators and the robust step sorts the 2 x n_directions circle fits by insertion
# (quadratic); beyond 64 planes (2.8 degrees apart) the slabs of half-width 0.25 radius overlap
# so much that more planes add no information.
MAX_DIRECTIONS = 64


def check_options(**options):
    """Check option names and values of :func:`meshcurv.principal_curvatures` without running it.

    Raises ValueError (one line) for an unknown name or a value out of its range; returns
    ``orientation``: "mst" or a (3,) float64 viewpoint.

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
    orientation = options.get("orientation", "mst")
    if isinstance(orientation, str) and orientation == "mst":
        return orientation
    if not isinstance(orientation, str):
        orientation = np.asarray(orientation, dtype=np.float64)
    if isinstance(orientation, str) or orientation.shape != (3,) or not np.isfinite(
            orientation).all():
        raise ValueError(f"orientation must be 'mst' or a finite (3,) viewpoint, "
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
        models.
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
    normal_estimation : {"auto", "faces", "pca"}
        Used when ``normals`` is None. "faces": area-weighted face normals. "pca": normal of
        the least-squares plane through the same neighborhood, oriented by the faces if there
        are any, else by ``orientation``. "auto" (default): "pca" - on noisy meshes face normals
        are the worst choice (0.3 % noise, random sphere: mean |dk1| + |dk2| 0.60 with face
        normals, 0.38 with PCA ones; max |dk1| 13 vs 0.9), on clean ones the refinement below
        makes the two equal.
    refine_normals : bool or None, default None
        Refine the normals by a local quadric fit over the same neighborhood before the
        circle fits (:func:`meshcurv.fit.jet.local_jet`), mixed with the starting normal by
        the measured noise (the mix of ``weighting="auto"``,
        :func:`meshcurv.pipeline.weight_blend`, whatever ``weighting`` is): face and PCA normals
        tilt with irregular sampling (0.7 degrees on a random sphere, up to 3 % in
        curvature), the quadric's normal does not but is noisier. None: refine estimated
        normals, use given ones as they are; True: refine given normals too; False: never.
    orientation : "mst" or (3,) array-like
        Global orientation of estimated point-cloud normals: "mst" propagates along a minimum
        spanning tree and then turns each connected piece away from its own centroid; a (3,)
        point orients every normal towards it (a scanner position).
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
        is dropped (``TOO_FEW_NEIGHBORS``). ``result.n_neighbors`` is the count of the ball
        used; ``result.radius`` stays the call's. False: every vertex at ``radius`` alone
        (tiled runs, whose halo covers that radius only).

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
    normal_estimation: str = "auto"
    refine_normals: object = None
    orientation: object = "mst"
    sparse_retry: bool = True

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
    like the face normals if there are faces, else towards ``viewpoint``) or "mst" (plane fits
    of all points first, oriented along a spanning tree). ``refine``: quadric-refined normals.
    ``weighting``: as the option. ``fit``: the fused kernel's settings ``(n_directions, slab,
    min_points, min_spread, unit_norm, section_blend, half_frequency, robust)``, typed.
    ``sparse_retry``: as the option.
    """

    use_kring: bool
    normals: str
    viewpoint: object
    refine: bool
    weighting: str
    fit: tuple
    sparse_retry: bool = True


def resolve_plan(has_faces, has_normals, n_directions=8, neighborhood="auto", slab=0.25,
                 min_points=3, min_spread=0.25, weighting="auto",
                 circle_normalization="tangent", section_blend=True, robust=True,
                 half_frequency=False, normal_estimation="auto", refine_normals=None,
                 orientation="mst", sparse_retry=True):
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
                                n_directions=n_directions)
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
        normals = "pca" if has_faces or viewpoint is not None else "mst"
    fit = (int(n_directions), float(slab), float(min_points), float(min_spread),
           circle_normalization == "unit", bool(section_blend), bool(half_frequency),
           bool(robust))
    refine = not has_normals if refine_normals is None else bool(refine_normals)
    return Plan(has_faces and neighborhood != "ball", normals, viewpoint, refine, weighting, fit,
                bool(sparse_retry))
