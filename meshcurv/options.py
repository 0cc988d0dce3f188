"""Options of :func:`meshcurv.principal_curvatures`: the one table of their constraints.

The API, the command line, the pymeshlab filter and tiled runs check options here, before any
work starts (and without loading the compiled kernels).
"""

import numpy as np

__all__ = ["OPTION_NAMES", "CHOICES", "MAX_DIRECTIONS", "check_options"]

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
