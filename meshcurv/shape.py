"""Curvature descriptors derived from the principal curvatures: mean, Gaussian, shape index,
curvedness; and the colour maps used to display them.

Sign convention everywhere: outward normal, convex positive, k1 >= k2. Arrays are (n,) float64
and NaN propagates.
"""

import numpy as np

__all__ = ["mean_curvature", "gaussian_curvature", "shape_index", "curvedness", "FIELDS",
           "COLORMAPS", "INVALID_COLOR", "color_range", "colorize", "colormap_table"]


def mean_curvature(k1, k2):
    """Mean curvature ``H = (k1 + k2) / 2`` (1 / length); +1 on a unit sphere."""
    return 0.5 * (np.asarray(k1, dtype=np.float64) + np.asarray(k2, dtype=np.float64))


def gaussian_curvature(k1, k2):
    """Gaussian curvature ``K = k1 k2`` (1 / length^2); independent of the normal's orientation."""
    return np.asarray(k1, dtype=np.float64) * np.asarray(k2, dtype=np.float64)


def shape_index(k1, k2):
    """Koenderink's shape index ``S = (2 / pi) atan((k1 + k2) / (k1 - k2))`` in [-1, 1].

    +1 convex cap (sphere seen from outside), +0.5 ridge (cylinder), 0 symmetric saddle,
    -0.5 valley, -1 concave cup. Computed as ``atan2(k1 + k2, k1 - k2)`` so umbilics give
    exactly +-1 and a plane (k1 = k2 = 0) gives 0. Scale invariant; flips sign with the normal.

    Examples
    --------
    >>> shape_index(np.array([1.0, 1.0, 1.0]), np.array([1.0, 0.0, -1.0]))
    array([1. , 0.5, 0. ])
    """
    k1 = np.asarray(k1, dtype=np.float64)
    k2 = np.asarray(k2, dtype=np.float64)
    return (2.0 / np.pi) * np.arctan2(k1 + k2, k1 - k2)


def curvedness(k1, k2):
    """Koenderink's curvedness ``C = sqrt((k1^2 + k2^2) / 2)`` (1 / length); 1 on a unit sphere."""
    k1 = np.asarray(k1, dtype=np.float64)
    k2 = np.asarray(k2, dtype=np.float64)
    return np.sqrt(0.5 * (k1 * k1 + k2 * k2))


# Per-vertex scalar fields a curvature result offers, in file and attribute order.
FIELDS = ("k1", "k2", "mean", "gaussian", "shape_index", "curvedness")

# Colour of vertices without an estimate (valid False), RGB uint8.
INVALID_COLOR = (128, 128, 128)

# MeshLab's colour maps (``compute_color_from_scalar_per_vertex(colormap=...)``, MeshLab 2025.07)
# sampled at 33 evenly spaced stops, RGB 0..255. MeshLab interpolates linearly between these
# and truncates, so :func:`colorize` reproduces the filter's colours exactly. Low values take the
# first colour: "RGB" runs red -> yellow -> green -> cyan -> blue, "Turbo" dark blue -> dark red.
_TABLES = {
    "RGB": """
        255,0,0 255,31,0 255,63,0 255,95,0 255,127,0 255,159,0 255,191,0 255,223,0 255,255,0
        223,255,0 191,255,0 159,255,0 127,255,0 95,255,0 63,255,0 31,255,0 0,255,0 0,255,31 0,255,63
        0,255,95 0,255,127 0,255,159 0,255,191 0,255,223 0,255,255 0,223,255 0,191,255 0,159,255
        0,127,255 0,95,255 0,63,255 0,31,255 0,0,255""",
    "Viridis": """
        68,1,84 70,12,95 71,24,106 72,34,115 70,45,124 68,55,129 65,65,134 61,74,137 57,84,139
        53,92,140 49,100,141 46,108,142 42,117,142 39,124,142 36,132,141 34,139,141 31,148,139
        30,155,137 31,163,134 36,170,130 46,178,124 57,185,118 71,192,110 87,198,101 107,205,89
        126,210,78 146,215,65 167,219,51 191,223,36 212,225,26 233,228,25 253,231,36 253,231,36""",
    "Plasma": """
        12,7,134 33,5,143 49,4,150 63,3,156 78,2,161 90,0,165 103,0,167 115,0,168 129,4,167
        140,10,164 151,19,160 162,28,154 173,38,146 182,47,139 190,56,131 198,65,124 207,75,116
        214,85,109 220,94,102 227,103,95 233,114,87 238,124,80 243,134,73 246,145,66 250,157,58
        252,169,52 253,181,45 253,193,40 251,208,36 248,221,36 244,234,38 239,248,33 239,248,33""",
    "Cividis": """
        0,34,77 0,40,91 0,45,105 4,50,112 28,56,110 40,62,109 50,68,108 59,73,107 69,79,107
        77,85,108 84,90,108 91,96,110 99,102,111 106,108,113 113,114,115 120,120,118 128,126,120
        135,132,120 143,138,119 151,144,118 160,151,117 168,158,115 176,164,112 184,171,109
        194,178,105 202,185,100 211,192,95 219,199,89 229,207,80 238,215,71 248,222,59 253,231,55
        253,231,55""",
    "Turbo": """
        48,18,59 57,41,114 64,64,161 68,86,199 70,109,230 70,130,248 64,150,254 52,170,248
        37,192,230 26,209,210 24,224,189 34,235,169 59,244,141 89,251,114 120,254,89 149,254,68
        174,249,55 195,241,51 214,229,53 231,215,56 244,196,58 251,179,54 254,158,46 252,134,36
        246,107,24 237,85,15 226,66,9 212,50,5 192,35,2 172,22,1 148,12,1 122,4,2 122,4,2""",
    "RdPu": """
        255,247,243 254,241,237 253,235,231 253,229,226 252,223,219 252,216,212 252,209,205
        252,202,198 251,194,191 251,184,188 250,175,185 250,165,182 249,153,178 248,139,173
        248,125,168 247,111,163 243,96,159 236,83,157 230,70,154 223,57,152 212,42,146 200,30,140
        189,17,134 177,4,127 162,1,124 149,1,122 136,1,121 123,1,119 109,0,115 97,0,112 85,0,109
        73,0,106 73,0,106""",
}
COLORMAPS = tuple(_TABLES)
_LUT = {name.lower(): np.array([[int(c) for c in rgb.split(",")] for rgb in table.split()],
                               dtype=np.float64)
        for name, table in _TABLES.items()}


def colormap_table(name):
    """The colour ramp ``name`` (one of :data:`COLORMAPS`, any case) as (k, 3) float64 RGB in
    0..255, from its low end to its high end."""
    return _LUT[str(name).lower()].copy()


def color_range(values, field, clamp=2.0):
    """Value range a colour ramp spans: fixed for the shape index, robust for the rest.

    Parameters
    ----------
    values : (n,) float
        Field values; NaN (invalid vertices) are ignored.
    field : str
        One of :data:`FIELDS`. ``"shape_index"`` always spans its full scale [-1, 1], so colours
        mean the same shape on every mesh.
    clamp : float, default 2.0
        Percent of values clipped at each end for the other fields, so a few wild vertices
        (borders, noise) do not wash out the ramp.

    Returns
    -------
    (lo, hi) : floats with ``lo < hi``

    Examples
    --------
    >>> color_range(np.linspace(0.0, 1.0, 101), "k1", clamp=0.0)
    (0.0, 1.0)
    """
    if field == "shape_index":
        return -1.0, 1.0
    if not 0.0 <= clamp < 50.0:
        raise ValueError(f"clamp must be a percentage in [0, 50), got {clamp}")
    v = np.asarray(values, dtype=np.float64).ravel()
    v = v[np.isfinite(v)]
    if v.size == 0:
        return -1.0, 1.0
    lo, hi = (float(p) for p in np.percentile(v, [clamp, 100.0 - clamp]))
    if not hi > lo:
        # constant field: centre it on the ramp
        half = max(abs(lo), 1.0) * 1e-6
        lo, hi = lo - half, lo + half
    return lo, hi


def colorize(values, field="mean", colormap="Turbo", clamp=2.0, value_range=None):
    """RGB colours of per-vertex values on one of MeshLab's colour ramps.

    Parameters
    ----------
    values : (n,) float
        Field values; NaN marks vertices without an estimate and gets :data:`INVALID_COLOR`.
    field : str
        Name of the field, used for the default range (see :func:`color_range`).
    colormap : str, default "Turbo"
        One of :data:`COLORMAPS` (case-insensitive), the names MeshLab uses.
    clamp : float, default 2.0
        Percent clipped at each end for the default range.
    value_range : (lo, hi), optional
        Values mapped to the ends of the ramp; default :func:`color_range`.

    Returns
    -------
    (n, 3) uint8

    Examples
    --------
    >>> colorize(np.array([-1.0, 1.0, np.nan]), "shape_index", "RGB")
    array([[255,   0,   0],
           [  0,   0, 255],
           [128, 128, 128]], dtype=uint8)
    """
    lut = _LUT.get(str(colormap).lower())
    if lut is None:
        raise ValueError(f"colormap must be one of {', '.join(COLORMAPS)}, got {colormap!r}")
    v = np.asarray(values, dtype=np.float64).ravel()
    lo, hi = color_range(v, field, clamp) if value_range is None else map(float, value_range)
    if not hi > lo:
        raise ValueError(f"value_range must have lo < hi, got ({lo}, {hi})")
    with np.errstate(invalid="ignore"):
        t = np.clip((v - lo) / (hi - lo), 0.0, 1.0)
    stops = np.linspace(0.0, 1.0, len(lut))
    rgb = np.column_stack([np.interp(t, stops, lut[:, c]) for c in range(3)])
    # MeshLab truncates; the epsilon keeps exact stop values from falling one step short
    finite = np.isfinite(v)
    out = np.floor(np.where(finite[:, None], rgb, 0.0) + 1e-9).astype(np.uint8)
    out[~finite] = INVALID_COLOR
    return out
