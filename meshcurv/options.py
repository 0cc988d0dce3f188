"""Options of :func:`meshcurv.principal_curvatures`: the one table of their constraints.

The API, the command line, the pymeshlab filter and tiled runs check options here, before any
work starts (and without loading the compiled kernels).
"""

from typing import NamedTuple

import numpy as np

__all__ = ["OPTION_NAMES", "CHOICES", "MAX_DIRECTIONS", "check_options", "Plan", "resolve_plan"]

# Keyword options of principal_curvatures besides the data (vertices, faces, normals) and the
# call's own switches (query, progress); tests hold this table to the function's signature.
OPTION_NAMES = ("radius", "n_directions", "neighborhood", "slab", "min_points", "min_spread",
                "weighting", "circle_normalization", "section_blend", "robust",
                "half_frequency", "normal_estimation", "refine_normals", "orientation")

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


class Plan(NamedTuple):
    """How one estimate runs, resolved from the options and what the input holds
    (:func:`resolve_plan`); read by :func:`meshcurv.pipeline.run`.

    ``use_kring``: k-ring neighborhoods (else ball queries). ``normals``: "given" (used as
    they are), "faces" (area-weighted face normals), "pca" (plane fits block by block, oriented
    like the face normals if there are faces, else towards ``viewpoint``) or "mst" (plane fits
    of all points first, oriented along a spanning tree). ``refine``: quadric-refined normals.
    ``weighting``: as the option. ``fit``: the fused kernel's settings ``(n_directions, slab,
    min_points, min_spread, unit_norm, section_blend, half_frequency, robust)``, typed.
    """

    use_kring: bool
    normals: str
    viewpoint: object
    refine: bool
    weighting: str
    fit: tuple


def resolve_plan(has_faces, has_normals, n_directions=8, neighborhood="auto", slab=0.25,
                 min_points=3, min_spread=0.25, weighting="auto",
                 circle_normalization="tangent", section_blend=True, robust=True,
                 half_frequency=False, normal_estimation="auto", refine_normals=None,
                 orientation="mst"):
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
    return Plan(has_faces and neighborhood != "ball", normals, viewpoint, refine, weighting, fit)
