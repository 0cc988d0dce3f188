"""What the estimator returns: :class:`CurvatureResult`, and the per-vertex field schema every
writer (PLY, LAS/LAZ, the pymeshlab filter) uses."""

from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np

from . import shape
from .fit import constants

__all__ = ["CurvatureResult", "Status", "CURVATURE_FIELDS", "curvature_fields", "mls_shares",
           "jet_shares",
           "oriented_like"]

# Per-vertex curvature fields of every annotated file (PLY properties, LAS extra bytes).
CURVATURE_FIELDS = shape.FIELDS + ("valid", "status", "d1x", "d1y", "d1z", "d2x", "d2y", "d2z",
                                   "outlier_score", "radius_used", "mls_share", "jet_share")


class Status(IntEnum):
    """Why a vertex has an estimate or not: ``CurvatureResult.status`` (int8), the first reason
    the estimator met.

    - ``OK`` (0): estimated (``valid``).
    - ``NO_POSITION`` (1): the vertex's coordinates are NaN or infinite.
    - ``NO_NORMAL`` (2): its normal is zero, NaN or infinite (e.g. fewer than 3 points for a
      plane fit, a vertex in no face), or, given, more than 60 degrees off the plane fit of
      its neighborhood.
    - ``TOO_FEW_NEIGHBORS`` (3): fewer than ``min_points`` neighbors within the radius: no
      half-set can be fitted (an isolated point, a radius below the spacing); or, on a cloud
      with estimated normals, fewer than 11 within every radius tried (``sparse_retry``).
    - ``TOO_FEW_HALF_SETS`` (4): fewer than 5 half-sets with enough points reaching far enough,
      or fewer than 3 planes with one (borders, holes, one-sided neighborhoods).
    - ``ILL_POSED_FIT`` (5): the Euler model's least-squares system is singular, or too few
      circle fits remain after the robust refit.
    - ``DEGENERATE_DIRECTIONS`` (6): the directions the circle fits measured do not span the
      Euler model (neighbors along one curve, e.g. the rim of a triangle fan).
    - ``OUT_OF_RANGE`` (7): the curvatures exceed float64 (clouds of subnormal size).
    - ``OUTLIER`` (8): the point lies further from the robust fit of its neighborhood than
      the noise explains (``outlier_score`` above 4.685: a spike or stray point); it was left
      out of its neighbors' fits and gets no curvature of its own.
    - ``WRAPS_AROUND`` (9): the ball reaches a third of the way around the surface: it holds
      points on the far side of a tube or sphere narrower than it, whose normals turn by more
      than 120 degrees, and the surface bending around to them (:mod:`meshcurv.fit.wrap`; not
      the other side of a thin sheet, which the fits handle); on a cloud whose normals are
      estimated, also where the ball's points are less flat than such a cap and, as the
      ball shrinks, flatten like a surface or keep a round section as wide (a pole, a
      branch; :func:`meshcurv.fit.wrap.beyond_a_cap`). A smaller radius gives an estimate:
      on meshes and clouds with normals given, ``sparse_retry`` tries 1/2 to 1/16 of it.
    """

    OK = constants.STATUS_OK
    NO_POSITION = constants.STATUS_NO_POSITION
    NO_NORMAL = constants.STATUS_NO_NORMAL
    TOO_FEW_NEIGHBORS = constants.STATUS_TOO_FEW_NEIGHBORS
    TOO_FEW_HALF_SETS = constants.STATUS_TOO_FEW_HALF_SETS
    ILL_POSED_FIT = constants.STATUS_ILL_POSED_FIT
    DEGENERATE_DIRECTIONS = constants.STATUS_DEGENERATE_DIRECTIONS
    OUT_OF_RANGE = constants.STATUS_OUT_OF_RANGE
    OUTLIER = constants.STATUS_OUTLIER
    WRAPS_AROUND = constants.STATUS_WRAPS_AROUND


@dataclass
class CurvatureResult:
    """Per-vertex principal curvatures; one row per input vertex (or query point), input order.

    Attributes
    ----------
    k1, k2 : (n,) float64, principal curvatures, 1 / model units, ``k1 >= k2``, convex positive
        under the outward normal; NaN where ``valid`` is False
    d1, d2 : (n, 3) float64, unit principal directions; ``(d1, d2, normals)`` is right-handed
    normals : (n, 3) float64, the unit normals used (given, from faces, or estimated)
    valid : (n,) bool
    n_neighbors : (n,) int32, neighbors within the radius
    n_samples : (n,) int32, circle fits used in the Euler fit (at most ``2 * n_directions``)
    residual : (n,) float64, RMS residual of the Euler fit, 1 / model units
    noise : (n,) float64, RMS height residual of a local quartic (cubic where too few points)
        fit over the neighborhood, model units: an estimate of the noise along the normal (NaN
        with fewer than 11 points)
    radius : float, the neighborhood radius used, model units
    status : (n,) int8, why a row has no estimate (:class:`Status`; ``Status.OK`` where
        ``valid``), or None where the producer does not tell
    orientation : str or None, how the normals got their sign, one line: "as given",
        "oriented like the faces", "oriented towards the viewpoint", "oriented towards +z",
        or the spanning tree's rule per piece, e.g. "oriented outward (closed surface)" (see
        :func:`meshcurv.normals.orient.piece_signs`); None where the producer does not tell
    outlier_score : (n,) float64, the point's distance from a robust cubic fit of its
        neighborhood in robust noise scales (:mod:`meshcurv.fit.outliers`; above 4.685:
        ``Status.OUTLIER``); NaN where not computed (``robust_points=False``, too few
        neighbors), or None where the producer does not tell
    radius_used : (n,) float64, the neighborhood radius of the row's estimate, model units:
        ``radius`` for a fixed radius, the radius each vertex chose with ``radius="auto"``
        (:mod:`meshcurv.scale`), the wider radius where ``sparse_retry`` re-estimated a row
        that had too few points, the smaller one where its ball reached around the surface
        or, at the default radius and with "auto", was no small cap of a surface whose
        curvature varies across it (:func:`meshcurv.api._varying_caps`); NaN where ``valid``
        is False. None where the producer does not tell (then ``radius`` where valid)
    mls_share : (n,) float64 in [0, 1] or None, the share of the MLS surface's curvature in
        each row's k1 and k2 (:mod:`meshcurv.coarse`; where it is at least 0.5, d1, d2 and
        the normal are the MLS surface's too); 0 where the row kept its circle fits. None
        where no MLS blend ran: ``coarse_fit="circles"``, tiled runs, and inputs whose
        circle fits the probe found not limited by their sampling
    jet_share : (n,) float64 in [0, 1] or None, how far each row's shape operator moved from
        the estimate before towards its ring jet's, a quartic over the vertex's 3-ring
        (:mod:`meshcurv.jet_blend`; k1, k2, d1 and d2 follow, the normal stays); 0 where the
        row kept it. None where no jet blend ran: a radius given, ``ring_jet=False``, tiled
        runs
    """

    k1: np.ndarray
    k2: np.ndarray
    d1: np.ndarray
    d2: np.ndarray
    normals: np.ndarray
    valid: np.ndarray
    n_neighbors: np.ndarray
    n_samples: np.ndarray
    residual: np.ndarray
    noise: np.ndarray
    radius: float
    status: np.ndarray = None
    orientation: str = None
    outlier_score: np.ndarray = None
    radius_used: np.ndarray = None
    mls_share: np.ndarray = None
    jet_share: np.ndarray = None

    @property
    def mean(self):
        """Mean curvature (k1 + k2) / 2, (n,)."""
        return shape.mean_curvature(self.k1, self.k2)

    @property
    def gaussian(self):
        """Gaussian curvature k1 * k2, (n,)."""
        return shape.gaussian_curvature(self.k1, self.k2)

    @property
    def shape_index(self):
        """Shape index in [-1, 1], +1 for a convex cap, (n,)."""
        return shape.shape_index(self.k1, self.k2)

    @property
    def curvedness(self):
        """Curvedness sqrt((k1^2 + k2^2) / 2), (n,)."""
        return shape.curvedness(self.k1, self.k2)

    def __len__(self):
        return len(self.k1)


def curvature_fields(result):
    """The :data:`CURVATURE_FIELDS` of a :class:`~meshcurv.CurvatureResult`, in that order, as
    ``{name: (n,) array}``: float64, ``valid`` uint8 (1 = estimated), ``status`` uint8
    (:class:`Status`), ``d1x .. d2z`` the components of the principal directions,
    ``outlier_score`` float64 (NaN where not computed), ``radius_used`` float64 (model units,
    NaN where not valid; ``radius`` where valid if the result does not tell), ``mls_share``
    float64 in [0, 1] (the MLS surface's share of the row's curvature; 0 where no blend
    ran), ``jet_share`` float64 in [0, 1] (the ring jet's; 0 where no jet blend ran)."""
    out = {f: np.asarray(getattr(result, f), dtype=np.float64) for f in shape.FIELDS}
    out["valid"] = np.asarray(result.valid, dtype=np.uint8)
    out["status"] = np.asarray(result.status, dtype=np.uint8)
    for name in ("d1", "d2"):
        arr = getattr(result, name)
        for a, c in enumerate("xyz"):
            out[name + c] = arr[:, a]
    score = result.outlier_score
    out["outlier_score"] = (np.full(len(result.k1), np.nan) if score is None else
                            np.asarray(score, dtype=np.float64))
    used = result.radius_used
    out["radius_used"] = (np.where(out["valid"] == 1, float(result.radius), np.nan)
                          if used is None else np.asarray(used, dtype=np.float64))
    out["mls_share"] = mls_shares(result)
    out["jet_share"] = jet_shares(result)
    return out


def mls_shares(result):
    """``result.mls_share`` as float64 (n,), 0 where no blend ran (``mls_share`` None): the
    field of every annotated file and of the pymeshlab filter."""
    return _zero_where_none(result.mls_share, len(result.k1))


def jet_shares(result):
    """``result.jet_share`` as float64 (n,), 0 where no jet blend ran (``jet_share`` None):
    the field of every annotated file and of the pymeshlab filter."""
    return _zero_where_none(result.jet_share, len(result.k1))


def _zero_where_none(share, n):
    return np.zeros(n) if share is None else np.asarray(share, dtype=np.float64)


def oriented_like(result, normals):
    """``result`` with its rows whose normal faces away from ``normals`` ((n, 3), the rows'
    reference normals) turned round: the normal negated, k1, k2 = -k2, -k1 and d1, d2 = d2, d1
    (still d2 = n x d1). The same object where no row faces away.

    >>> import meshcurv, numpy as np, trimesh
    >>> res = meshcurv.principal_curvatures(trimesh.creation.icosphere(3), radius=0.5)
    >>> turned = oriented_like(res, -res.normals)
    >>> bool(res.valid.all() and np.allclose(turned.k1, -1.0) and np.allclose(turned.k2, -1.0))
    True
    """
    with np.errstate(invalid="ignore"):
        away = np.einsum("ij,ij->i", np.asarray(result.normals), np.asarray(normals)) < 0.0
    if not away.any():
        return result
    return replace(result, normals=np.where(away[:, None], -result.normals, result.normals),
                   k1=np.where(away, -result.k2, result.k1),
                   k2=np.where(away, -result.k1, result.k2),
                   d1=np.where(away[:, None], result.d2, result.d1),
                   d2=np.where(away[:, None], result.d1, result.d2))
