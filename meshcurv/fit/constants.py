"""Constants of the estimator shared by the compiled kernels and their numpy specifications
(plain numbers: importing them loads neither numba nor a kernel)."""

# Exponent p of the distance weights (1 - r^2 / radius^2)^p (measured: p = 2 leaves twice the
# bias of p = 4 on the Table 2 paraboloid; p = 8 gains little more and doubles the noise again).
WEIGHT_POWER = 4


# Noise level (RMS height residual of the local jet, as a fraction of the radius) at which
# weighting="auto" mixes equal and distance weights half and half, and the jet's refined
# normal its quartic's and its quadric's gradients. Measured: clean samples of the test
# surfaces stay below 0.01 % of the radius (below 0.09 % with the cubic jet this was set with:
# Table 2 paraboloid 0.02 %, torus 0.08 %), normal noise of 0.03 % of the bounding-box
# diagonal already gives 0.6-0.9 %, and from there on equal weights are the more accurate.
NOISE_SCALE = 2e-3


# Plane i makes the angle (i + PLANE_OFFSET) * pi / ndir with the tangent frame's first axis.
PLANE_OFFSET = 0.25


# Fewest spread of the directions the circle fits measured for an estimate: the smaller
# eigenvalue of the covariance of their (cos 2phi, sin 2phi) mixes over the samples kept
# (:func:`meshcurv.fit.euler.direction_spread`; the mixes from
# :func:`meshcurv.fit.circle.sample_design`). Measured: directions all around ~0.34 (sphere), mesh borders and
# corners >= 0.15, the border of a random half-sphere cloud >= 0.027, the corners of a random
# square patch 0.0069 .. 0.0095 (still accurate); neighbors along one curve (the rim of a
# triangle fan) 0 .. 0.0018: there the Euler model's B and C are not determined, and k1, k2
# would be noise (often exactly 0) marked valid.
MIN_DIRECTION_SPREAD = 3e-3

# Why a vertex has no estimate: the codes of :class:`meshcurv.result.Status` (int8, documented
# there), set by the fused kernel (OUT_OF_RANGE by meshcurv.api after a rescaled run, OUTLIER
# and WRAPS_AROUND by meshcurv.pipeline).
STATUS_OK = 0
STATUS_NO_POSITION = 1
STATUS_NO_NORMAL = 2
STATUS_TOO_FEW_NEIGHBORS = 3
STATUS_TOO_FEW_HALF_SETS = 4
STATUS_ILL_POSED_FIT = 5
STATUS_DEGENERATE_DIRECTIONS = 6
STATUS_OUT_OF_RANGE = 7
STATUS_OUTLIER = 8
STATUS_WRAPS_AROUND = 9

# Tukey biweight of the point-outlier pass (:mod:`meshcurv.fit.outliers`): a point whose
# residual from its neighborhood's robust cubic fit exceeds TUKEY_C robust scales gets weight 0
# and is flagged (STATUS_OUTLIER). 4.685 is the biweight's usual tuning constant (95 %
# efficiency under Gaussian noise): Gaussian noise alone exceeds it at 3 points in a million.
TUKEY_C = 4.685

# Outlier scores up to which a point keeps its full weight in the later fits: two robust
# sigmas, what Gaussian noise gives 95 % of the points. The weight then descends as Tukey's
# biweight of the excess to 0 at TUKEY_C, so clean and ordinarily noisy points are weighted
# exactly as without the outlier pass.
OUTLIER_TRUSTED = 2.0

# Reweighting rounds of that robust fit after its least-squares start (measured: the spike
# residuals and the scale settle after 2-3; the default weights change by < 1e-3 beyond 3),
# none where no residual of the least-squares start reaches TUKEY_C robust scales: no neighbor
# the biweight would reject, so the efficient least-squares fit stands. Clean data and
# Gaussian noise stop there (a residual of 4.685 sigmas in 3 of a million: 3 in 10,000 balls
# of 100 points); a ball holding a spike keeps every round. Measured against always four
# rounds: surfaces, spikes (100 % flagged), density and icosahedra cases and the benchmark
# clouds at noise 0.1-0.2 unchanged to 4 digits; the pass 2.9x faster on a noisy torus.
OUTLIER_ITERATIONS = 3

# Least robust scale of that pass, as a fraction of the radius: on clean samples the cubic's
# residuals are rounding or sampling-sized and their MAD can be arbitrarily small, so any
# point would read as an outlier. Below the noise level at which weighting="auto" starts to
# count noise (NOISE_SCALE, 2e-3), above the cubic's residual on clean
# samples of the test surfaces.
OUTLIER_SCALE_FLOOR = 1e-3

# Largest share of a neighborhood the robust fit may leave out (weight 0) and still judge its
# point: a fit that describes less than the rest describes part of it only. On trimesh's
# 32 x 12 torus 1 / 0.3 at a radius of 0.34, a top-ring vertex's 10 neighbors: the fit kept
# the plane of the 6 below and left out the vertex's own two ring neighbors, as far off it as
# the vertex itself (0.12 radii, scale 0.001), and flagged its whole ring as spikes.
OUTLIER_MAX_REJECTED = 0.25
