"""The per-point fits of the estimator, one module per step of the paper, each a compiled
kernel with its plain numpy specification beside it (``*_spec.py``; the tests hold the kernel
to it, 1e-9):

- :mod:`~meshcurv.fit.frame` / ``frame_spec``: the tangent frame (tu, tv, n) at a point;
- :mod:`~meshcurv.fit.circle` / ``circle_spec``: CGA circle fits of the half-sets (accumulate,
  solve);
- :mod:`~meshcurv.fit.euler` / ``euler_spec``: the Euler model and its robust refit;
- :mod:`~meshcurv.fit.jet` / ``jet_spec``: local cubic fit (noise level, refined normal);
- :mod:`~meshcurv.fit.fused` / ``fused_spec``: the per-point estimator calling those steps,
  and its parallel driver over all query points;
- :mod:`~meshcurv.fit.constants`: the constants kernels and specifications share.

Importing the package loads no kernel.
"""
