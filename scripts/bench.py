"""Speed of meshcurv against MeshLab's curvature filters, measured in the same run.

Data: a torus and a sphere mesh at 100k and 1M vertices, the 100k torus with Gaussian noise of
0.1 % of its diagonal along the normals (a scan's noise: the estimator's noise-dependent steps
differ), and a 1M-point cloud (uniform random points on a torus, no faces). Radius:
:func:`meshcurv.neighbors.default_radius`, the ball holding about 100 points. Methods:

- ``meshcurv``: exact normals given; ``meshcurv (est.)``: normals estimated by PCA over the
  neighbourhood (k-ring on meshes, ball on the cloud), refined by the local fit and oriented
  (by the faces on meshes, by minimum-spanning-tree propagation on the cloud). Everything
  else at the library's defaults. Both at the radius above, given as a number, as MeshLab
  gets it; ``meshcurv (default radius)``: exact normals given and no radius, the call a user
  types, which picks its own radius (default_radius with the faces on meshes) and ends with
  the steps only a radius it chose takes (:mod:`meshcurv.jet_blend`, the varying caps).
- MeshLab ``compute_curvature_principal_directions_per_vertex`` with "Taubin approximation"
  (1-ring), "Quadric Fitting" (2-ring) and "Scale Dependent Quadric Fitting" (SDQF, ball of the
  same radius), called in this process on a ``MeshSet`` prepared beforehand.
- MeshLab APSS (``compute_curvature_and_color_apss_per_vertex``) on the point set with the
  given normals, support matched to the radius as in ``compare_meshlab.py``; in a child process
  with a timeout, because it can abort the process.
- libigl ``principal_curvature`` (quadric fit over the k-ring nearest the radius) when ``igl``
  is installed.

Whole commands, timed end to end as processes (start-up, reading and writing included):

- ``meshcurv annotate`` of a 600k-point LAZ terrain scan, untiled and tiled on a local Dask
  cluster (``--tile-size``: 4 tiles, one worker per core);
- ``meshcurv batch`` of four 100k-vertex meshes with ``--jobs 1`` and ``--jobs 2``.

Reported per run: the median wall time of ``--repeat`` calls (compilation excluded: kernels are
compiled or loaded from the numba cache first), vertices per second, the speed-up over MeshLab
Taubin and SDQF on the same data (above 1 = faster than that method), and the peak resident
memory of the call above what the process held before it, in bytes per vertex (outputs
included). Peak memory comes from the kernel's high-water mark (``VmHWM``, reset through
``/proc/self/clear_refs``), so it also counts memory that numba kernels and MeshLab allocate
outside Python. Also: the time of ``import meshcurv`` and of the first call in a fresh process
on a warm numba cache, and the split of a meshcurv call into its stages.

Usage::

    python scripts/bench.py                      # full run (several minutes)
    python scripts/bench.py --quick              # small sizes, well under a minute
    python scripts/bench.py --json bench.json    # also write all numbers as JSON
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

# glibc serves large blocks from a heap it keeps after they are freed unless this is fixed;
# with it every block above 64 KiB is mapped and unmapped, so peak RSS measures each call alone.
_MMAP_ENV = "MALLOC_MMAP_THRESHOLD_"

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import compare_meshlab  # noqa: E402  (the MeshLab conventions of the comparison, shared)

# "MeshLab Taubin", "MeshLab QF", "MeshLab SDQF" -> pymeshlab's method names
MESHLAB_METHODS = {f"MeshLab {k}": v for k, v in compare_meshlab.MESHLAB_METHODS.items() if v}


# ---------------------------------------------------------------------------------------------
# Data
# ---------------------------------------------------------------------------------------------

def _torus_surface(n_vertices, major=2.0, minor=0.5):
    """:class:`meshcurv.surfaces.Surface` of a regular torus grid with about ``n_vertices``
    vertices and square cells."""
    from meshcurv import surfaces

    n_minor = max(8, int(round(np.sqrt(n_vertices * minor / major))))
    n_major = max(8, int(round(n_vertices / n_minor)))
    return surfaces.torus(major, minor, n_major=n_major, n_minor=n_minor)


def torus_mesh(n_vertices, major=2.0, minor=0.5):
    """Regular torus grid with about ``n_vertices`` vertices and square cells.

    Returns vertices (n, 3), faces (m, 3) int64 (outward winding), exact normals (n, 3).
    """
    s = _torus_surface(n_vertices, major, minor)
    return s.vertices, s.faces, s.normals


def sphere_mesh(n_vertices, radius=1.0):
    """Unit "cube sphere": the six faces of a cube, each an equal-angle grid, on the sphere.

    Returns vertices (n, 3) with n close to ``n_vertices``, faces (m, 3) int64 (outward
    winding) and exact normals (n, 3). Cell areas vary by less than 1.5x (unlike a UV sphere).
    """
    from meshcurv import surfaces

    m = max(2, int(round(np.sqrt((n_vertices - 2) / 6.0))))
    # grid (m+1) x (m+1) per cube face in the angles a, b in [-pi/4, pi/4]
    t = np.tan(np.linspace(-np.pi / 4, np.pi / 4, m + 1))
    a, b = (g.ravel() for g in np.meshgrid(t, t, indexing="ij"))
    one = np.ones_like(a)
    blocks = []
    for axis in range(3):
        for sign in (1.0, -1.0):
            p = np.empty((len(a), 3))
            p[:, axis] = sign * one
            p[:, (axis + 1) % 3] = a
            p[:, (axis + 2) % 3] = b
            blocks.append(p)
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    c00 = (i * (m + 1) + j).ravel()
    c10, c01, c11 = c00 + (m + 1), c00 + 1, c00 + m + 2
    quad = np.concatenate([np.column_stack([c00, c10, c11]), np.column_stack([c00, c11, c01])])
    faces = np.concatenate([quad + k * (m + 1) ** 2 for k in range(6)])
    p = np.concatenate(blocks)
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    # weld the copies of the cube's edges and corners
    _, first, inverse = np.unique(np.round(p * 1e9).astype(np.int64), axis=0, return_index=True,
                                  return_inverse=True)
    keep = np.sort(first)
    new_index = np.empty(len(p), dtype=np.int64)
    new_index[keep] = np.arange(len(keep))
    faces = new_index[first[inverse.ravel()]][faces]
    v = p[keep] * radius
    normals = p[keep]
    return v, surfaces.orient_faces(v, faces, normals), normals


def torus_cloud(n_points, major=2.0, minor=0.5, seed=0):
    """``n_points`` uniform random points on a torus (area-uniform); points (n, 3), normals (n, 3)."""
    rng = np.random.default_rng(seed)
    u = np.empty(0)
    w = np.empty(0)
    while len(u) < n_points:
        k = int(1.3 * (n_points - len(u))) + 16
        uu = rng.uniform(0, 2 * np.pi, k)
        ww = rng.uniform(0, 2 * np.pi, k)
        # the area element is proportional to major + minor cos w
        keep = rng.uniform(0, major + minor, k) < major + minor * np.cos(ww)
        u = np.concatenate([u, uu[keep]])
        w = np.concatenate([w, ww[keep]])
    u, w = u[:n_points], w[:n_points]
    normals = np.column_stack([np.cos(w) * np.cos(u), np.cos(w) * np.sin(u), np.sin(w)])
    ring = major + minor * np.cos(w)
    v = np.column_stack([ring * np.cos(u), ring * np.sin(u), minor * np.sin(w)])
    return v, None, normals


def noisy_torus_mesh(n_vertices, noise=0.001, seed=0):
    """:func:`torus_mesh` with Gaussian noise along the normals of ``noise`` times the bounding
    box diagonal (the accuracy cases' 0.1 %: a scan's noise, where the estimator runs every
    robust round and no bias correction); the normals returned are the clean torus' exact ones."""
    from meshcurv import surfaces

    s = surfaces.add_normal_noise(_torus_surface(n_vertices), noise, seed=seed)
    return s.vertices, s.faces, s.normals


def datasets(quick):
    """(name, make) of the benchmark's data sets, smallest first; ``make()`` returns
    (vertices, faces or None, exact normals)."""
    small, large = (4000, 16000) if quick else (100_000, 1_000_000)
    out = []
    for n in (small, large):
        out.append((f"torus {_count(n)}", lambda n=n: torus_mesh(n)))
        out.append((f"sphere {_count(n)}", lambda n=n: sphere_mesh(n)))
        if n == small:
            out.append((f"noisy torus {_count(n)}", lambda n=n: noisy_torus_mesh(n)))
    out.append((f"cloud {_count(large)}", lambda: torus_cloud(large)))
    return out


def _count(n):
    return f"{n // 1_000_000}M" if n % 1_000_000 == 0 else f"{n // 1000}k"


# ---------------------------------------------------------------------------------------------
# Measurement
# ---------------------------------------------------------------------------------------------

def _status_kib(field):
    with open("/proc/self/status") as fh:
        for line in fh:
            if line.startswith(field + ":"):
                return int(line.split()[1])
    return 0


def measure(fn, repeat):
    """Median wall time (s) of ``repeat`` calls of ``fn()`` and the peak extra memory (bytes).

    The peak is the high-water mark of the resident set during the first call minus the
    resident set just before it.
    """
    times = []
    peak = float("nan")
    for i in range(repeat):
        if i == 0:
            try:
                with open("/proc/self/clear_refs", "w") as fh:
                    fh.write("5")
                before = _status_kib("VmRSS")
            except OSError:
                before = None
        t0 = time.perf_counter()
        result = fn()
        times.append(time.perf_counter() - t0)
        if i == 0 and before is not None:
            peak = 1024.0 * max(0, _status_kib("VmHWM") - before)
        del result
    return float(np.median(times)), peak


# The user's call: normals given, the radius meshcurv picks (None), so the steps that only a
# radius it chose takes (the varying caps, the ring jets) run too.
DEFAULT_CALL = "meshcurv (default radius)"


def meshcurv_call(v, f, normals, radius, estimate):
    """A closure running meshcurv with the given normals, or estimating and orienting them;
    ``radius`` None: meshcurv's default."""
    import meshcurv

    if estimate:
        return lambda: meshcurv.principal_curvatures(v, f, radius=radius, normal_estimation="pca")
    return lambda: meshcurv.principal_curvatures(v, f, normals=normals, radius=radius)


def meshlab_call(v, f, radius, method):
    """A closure running one MeshLab curvature filter on a MeshSet prepared beforehand."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(v, f))

    def run():
        ms.compute_curvature_principal_directions_per_vertex(
            method=method, curvcolormethod="Mean Curvature", scale=pymeshlab.PureValue(radius),
            autoclean=False)
    return run


def igl_call(v, f, radius):
    """A closure running libigl's principal_curvature, or None when igl is not installed."""
    try:
        import igl
    except ImportError:
        return None
    # libigl's radius counts rings of edges: the ring reaching about the ball radius
    edge = np.linalg.norm(v[f[:, 0]] - v[f[:, 1]], axis=1).mean()
    rings = max(2, int(round(radius / edge)))
    return lambda: igl.principal_curvature(v, f, rings)


def apss_in_child(v, normals, radius, repeat, timeout):
    """Time MeshLab APSS in a child process; returns (seconds, peak bytes, status)."""
    with tempfile.TemporaryDirectory() as tmp:
        inp = os.path.join(tmp, "in.npz")
        np.savez(inp, vertices=v, normals=normals, radius=radius, repeat=repeat)
        try:
            p = subprocess.run([sys.executable, os.path.abspath(__file__), "--apss-worker", inp],
                               capture_output=True, text=True, timeout=timeout)
        except subprocess.TimeoutExpired:
            return float("nan"), float("nan"), f"timeout ({timeout:.0f} s)"
    if p.returncode != 0:
        why = f"crash (signal {-p.returncode})" if p.returncode < 0 else f"exit {p.returncode}"
        return float("nan"), float("nan"), why
    out = json.loads(p.stdout.strip().splitlines()[-1])
    return out["seconds"], out["peak_bytes"], "ok"


def _apss_worker(inp):
    """Child process: run APSS on the point set in ``inp`` and print the timing as JSON."""
    import pymeshlab

    d = np.load(inp)
    v, normals, radius, repeat = d["vertices"], d["normals"], float(d["radius"]), int(d["repeat"])
    filterscale = compare_meshlab.apss_filterscale(v, radius)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, v_normals_matrix=normals))

    def run():
        ms.compute_curvature_and_color_apss_per_vertex(filterscale=filterscale, curvaturetype="K1")
    seconds, peak = measure(run, repeat)
    print(json.dumps(dict(seconds=seconds, peak_bytes=peak)))


_FIRST_CALL = r"""
import json, sys, time
t0 = time.perf_counter()
import meshcurv
t1 = time.perf_counter()
sys.path.insert(0, {here!r})
from bench import torus_mesh, torus_cloud
v, f, n = torus_mesh(2000)
t2 = time.perf_counter()
meshcurv.principal_curvatures(v, f, normals=n)
t3 = time.perf_counter()
v, _, _ = torus_cloud(2000)
t4 = time.perf_counter()
meshcurv.principal_curvatures(v)
t5 = time.perf_counter()
print(json.dumps(dict(import_s=t1 - t0, first_mesh_s=t3 - t2, first_cloud_s=t5 - t4)))
"""


def terrain_cloud(n_points, side=100.0, seed=0):
    """``n_points`` random points (n, 3) of a smooth height field over a ``side`` x ``side``
    square (a terrain scan's shape), in random order."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(0.0, side, (n_points, 2))
    z = 0.04 * side * np.sin(6.0 * xy[:, 0] / side) * np.cos(5.0 * xy[:, 1] / side)
    return np.column_stack([xy, z])


def _write_laz(path, points):
    import laspy

    header = laspy.LasHeader(point_format=3, version="1.4")
    header.scales = np.full(3, 1e-4)
    header.offsets = points.min(axis=0)
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    las.write(path)


def _timed_command(args, repeat):
    """Median wall time (s) of ``repeat`` runs of the command ``args``; raises on failure."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        p = subprocess.run(args, capture_output=True, text=True)
        times.append(time.perf_counter() - t0)
        if p.returncode != 0:
            raise RuntimeError(f"{' '.join(args)} failed: {p.stderr[-500:]}")
    return float(np.median(times))


def command_rows(quick, repeat):
    """Rows of the whole-command measurements: tiled and untiled LAZ annotation, and batch runs
    with one and two jobs (see the module docstring)."""
    from meshcurv import io

    meshcurv_cmd = [sys.executable, "-m", "meshcurv"]
    n_scan, n_mesh = (20_000, 4000) if quick else (600_000, 100_000)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        scan = os.path.join(tmp, "scan.laz")
        _write_laz(scan, terrain_cloud(n_scan))
        data = f"LAZ {_count(n_scan)}"
        for label, extra in (("annotate (untiled)", []),
                             ("annotate --tile-size (4 tiles)", ["--tile-size", "50"])):
            out = os.path.join(tmp, "out.laz")
            seconds = _timed_command(meshcurv_cmd + ["annotate", scan, "-o", out] + extra, repeat)
            rows.append(dict(data=data, n=n_scan, radius=float("nan"), method=label,
                             seconds=seconds, peak_bytes=float("nan"), status="ok"))
            _progress(rows[-1])
        folder = os.path.join(tmp, "meshes")
        os.mkdir(folder)
        for i in range(4):
            v, f, _ = torus_mesh(n_mesh, major=2.0 + 0.1 * i)
            io.write_ply(os.path.join(folder, f"torus{i}.ply"), v, f)
        data = f"batch 4x{_count(n_mesh)}"
        for jobs in (1, 2):
            seconds = _timed_command(meshcurv_cmd + ["batch", folder, "-O", os.path.join(tmp, "o"),
                                                     "--overwrite", "--jobs", str(jobs)], repeat)
            rows.append(dict(data=data, n=4 * n_mesh, radius=float("nan"),
                             method=f"batch --jobs {jobs}", seconds=seconds,
                             peak_bytes=float("nan"), status="ok"))
            _progress(rows[-1])
    return rows


def first_call_times():
    """``import meshcurv`` and first calls (mesh, cloud) in a fresh process, warm numba cache."""
    code = _FIRST_CALL.format(here=os.path.dirname(os.path.abspath(__file__)))
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    if p.returncode != 0:
        raise RuntimeError(p.stderr)
    return json.loads(p.stdout.strip().splitlines()[-1])


def stage_times(v, f, normals, radius):
    """Where the time of a meshcurv call goes: seconds per compiled kernel, and the rest.

    Every public compiled kernel (meshcurv.neighbors, .normals, .fit) that no other kernel
    calls is wrapped with a timer for the duration of one call with the normals given, one
    with them estimated (both at ``radius``) and one with the normals given at meshcurv's
    default radius (:data:`DEFAULT_CALL`); the kernels are the leaves of the pipeline (neighbour search,
    normals, orientation, circle fits, MLS surface), with the blend's ring noise (one stage:
    numpy and its own kernels), and what remains of the call's time is numpy and Python glue.
    Returns ``{mode: {stage: seconds}}``.
    """
    import meshcurv
    from meshcurv import coarse, pipeline
    from meshcurv.fit import fused, jet, mls, outliers, ring_jet, wrap
    from meshcurv.neighbors import grid, kring
    from meshcurv.normals import orient, pca, sphere

    spent = {}
    # the kernels the pipeline calls from Python, by module; not those a kernel of the module
    # calls (its own or imported): numba binds them from the module's globals when it
    # compiles, where a Python wrapper does not compile
    modules = (grid, kring, pca, sphere, orient, jet, outliers, fused, mls, wrap, ring_jet)
    originals = {}
    for module in modules:
        kernels = {name: fn for name, fn in vars(module).items() if hasattr(fn, "py_func")}
        called = {name for fn in kernels.values() for name in fn.py_func.__code__.co_names}
        originals.update({(module, name): fn for name, fn in kernels.items()
                          if not name.startswith("_") and name not in called})
    # and where the pipeline or the MLS blend holds a kernel under its own name (from ...
    # import name)
    originals.update({(holder, name): fn for (_, name), fn in list(originals.items())
                      for holder in (pipeline, coarse) if getattr(holder, name, None) is fn})
    # and the MLS blend's noise over a mesh's rings (numpy and its own kernels, as one stage)
    originals[(coarse, "ring_noise")] = coarse.ring_noise

    def timed(name, fn):
        def call(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                spent[name] = spent.get(name, 0.0) + time.perf_counter() - t0
        return call

    out = {}
    try:
        for (module, name), fn in originals.items():
            setattr(module, name, timed(name, fn))
        for mode, kwargs in (("normals given", dict(normals=normals, radius=radius)),
                             ("normals estimated", dict(normal_estimation="pca", radius=radius)),
                             ("default radius", dict(normals=normals))):
            spent.clear()
            t0 = time.perf_counter()
            meshcurv.principal_curvatures(v, f, **kwargs)
            total = time.perf_counter() - t0
            stages = dict(sorted(spent.items(), key=lambda kv: -kv[1]))
            stages["other (numpy, Python)"] = total - sum(spent.values())
            stages["total"] = total
            out[mode] = stages
    finally:
        for (module, name), fn in originals.items():
            setattr(module, name, fn)
    return out


# ---------------------------------------------------------------------------------------------
# Run and report
# ---------------------------------------------------------------------------------------------

def run(quick=False, repeat=3, apss_timeout=900.0, methods=None, stages=True, data=None,
        commands=True):
    """Run the benchmark; returns a dict with ``rows`` (one per data set and method) and more."""
    from meshcurv.neighbors import default_radius

    import meshcurv
    import numba

    warm_v, warm_f, warm_n = torus_mesh(2000)
    for est in (False, True):
        meshcurv_call(warm_v, warm_f, warm_n, None, est)()
    meshcurv.principal_curvatures(warm_v)
    report = dict(threads=numba.get_num_threads(), cpus=os.cpu_count(), quick=quick,
                  repeat=repeat, rows=[], stages={}, first_call=first_call_times())
    for name, make in datasets(quick):
        if data and not any(name.startswith(d) for d in data):
            continue
        v, f, exact_normals = make()
        n = len(v)
        radius = default_radius(v)
        # one call per method on the 1M sets keeps the run short; MeshLab SDQF alone takes minutes
        rep = repeat if n <= 200_000 else max(1, min(repeat, 2))
        calls = [("meshcurv", meshcurv_call(v, f, exact_normals, radius, False)),
                 ("meshcurv (est.)", meshcurv_call(v, f, exact_normals, radius, True)),
                 (DEFAULT_CALL, meshcurv_call(v, f, exact_normals, None, False))]
        if f is not None:
            calls += [(label, meshlab_call(v, f, radius, m)) for label, m in MESHLAB_METHODS.items()]
            igl = igl_call(v, f, radius)
            if igl is not None:
                calls.append(("libigl", igl))
        for label, fn in calls:
            if methods and not any(label.startswith(m) for m in methods):
                continue
            seconds, peak = measure(fn, 1 if label == "MeshLab SDQF" and n > 200_000 else rep)
            report["rows"].append(dict(data=name, n=n, method=label, seconds=seconds,
                                       radius=float("nan") if label == DEFAULT_CALL else radius,
                                       peak_bytes=peak, status="ok"))
            _progress(report["rows"][-1])
        if f is not None and (not methods or any("MeshLab APSS".startswith(m) for m in methods)):
            seconds, peak, status = apss_in_child(v, exact_normals, radius, 1, apss_timeout)
            report["rows"].append(dict(data=name, n=n, radius=radius, method="MeshLab APSS",
                                       seconds=seconds, peak_bytes=peak, status=status))
            _progress(report["rows"][-1])
        if stages and n >= (16000 if quick else 1_000_000):
            report["stages"][name] = stage_times(v, f, exact_normals, radius)
    if commands:
        report["rows"] += command_rows(quick, 1)
    _add_ratios(report)
    return report


def _progress(row):
    print(f"  {row['data']:<12} {row['method']:<18} {row['seconds']:8.3f} s  {row['status']}",
          file=sys.stderr, flush=True)


def _add_ratios(report):
    """Speed-ups over MeshLab Taubin and SDQF on the same data set, and 1M / 100k time ratios."""
    by = {(r["data"], r["method"]): r for r in report["rows"]}
    for r in report["rows"]:
        for ref, key in (("MeshLab Taubin", "vs_taubin"), ("MeshLab SDQF", "vs_sdqf")):
            base = by.get((r["data"], ref))
            r[key] = base["seconds"] / r["seconds"] if base and r["seconds"] > 0 else float("nan")
        r["vertices_per_s"] = r["n"] / r["seconds"] if r["seconds"] > 0 else float("nan")
        r["bytes_per_vertex"] = r["peak_bytes"] / r["n"]
    for data, single, parallel in (("LAZ", "annotate (untiled)", "annotate --tile-size"),
                                   ("batch", "batch --jobs 1", "batch --jobs 2")):
        for r in report["rows"]:
            base = next((b for b in report["rows"] if b["data"] == r["data"]
                         and b["method"].startswith(single)), None)
            if r["data"].startswith(data) and r["method"].startswith(parallel) and base:
                r["vs_single"] = base["seconds"] / r["seconds"]
    scaling = {}
    size = {r["data"]: r["n"] for r in report["rows"]}
    for shape in ("torus", "sphere"):
        sets = [s for s in size if s.startswith(shape)]
        if len(sets) == 2:
            small, large = sorted(sets, key=size.get)
            for r in report["rows"]:
                if r["data"] == large and (small, r["method"]) in by:
                    scaling[f"{shape} {r['method']}"] = dict(
                        size_ratio=r["n"] / by[(small, r["method"])]["n"],
                        time_ratio=r["seconds"] / by[(small, r["method"])]["seconds"])
    report["scaling"] = scaling


def format_table(report):
    """The report as Markdown tables."""
    lines = [f"{report['threads']} threads on {report['cpus']} CPUs; median of "
             f"{report['repeat']} calls (1M sets: fewer), compilation excluded.", "",
             "| data | method | time (s) | vertices/s | vs Taubin | vs SDQF | peak extra (B/vertex) |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for r in report["rows"]:
        if r["status"] != "ok":
            lines.append(f"| {r['data']} | {r['method']} | {r['status']} | | | | |")
            continue
        lines.append(f"| {r['data']} | {r['method']} | {r['seconds']:.3f} | "
                     f"{r['vertices_per_s'] / 1e3:,.0f}k | {_ratio(r['vs_taubin'])} | "
                     f"{_ratio(r['vs_sdqf'])} | {_bytes(r['bytes_per_vertex'])} |")
    lines += ["", "Speed-up = time of the MeshLab method / time of this method on the same data "
              "(above 1: faster). Whole commands (LAZ, batch): points or vertices per second "
              "end to end; the tiled and two-job runs' speed-up over the untiled and one-job "
              "ones: " + ", ".join(f"{r['data']} {r['method']} {r['vs_single']:.2f}x"
                                   for r in report["rows"] if "vs_single" in r) + ".", ""]
    if report["scaling"]:
        lines += ["| time(large) / time(small) | size ratio | time ratio |", "|---|---:|---:|"]
        for k, s in report["scaling"].items():
            lines.append(f"| {k} | {s['size_ratio']:.1f} | {s['time_ratio']:.1f} |")
        lines.append("")
    fc = report["first_call"]
    lines += [f"Fresh process, warm numba cache: `import meshcurv` {fc['import_s']:.2f} s, first "
              f"call on a mesh {fc['first_mesh_s']:.2f} s, on a point cloud "
              f"{fc['first_cloud_s']:.2f} s.", ""]
    for name, modes in report["stages"].items():
        lines += [f"Time by compiled kernel in one call on {name}:", "",
                  "| kernel | " + " | ".join(f"{m} (s)" for m in modes) + " |",
                  "|---|" + "---:|" * len(modes)]
        keys = list(dict.fromkeys(k for st in modes.values() for k in st))
        keys = [k for k in keys if k not in ("other (numpy, Python)", "total")] + \
            ["other (numpy, Python)", "total"]
        for k in keys:
            lines.append(f"| {k} | " + " | ".join(f"{st[k]:.3f}" if k in st else ""
                                                  for st in modes.values()) + " |")
        lines.append("")
    return "\n".join(lines)


def _bytes(x):
    return "" if not np.isfinite(x) else f"{x:,.0f}"


def _ratio(x):
    return "" if not np.isfinite(x) else f"{x:.2f}x"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="small sizes (4k/16k), for smoke tests")
    ap.add_argument("--repeat", type=int, default=3, help="calls per measurement (median)")
    ap.add_argument("--json", metavar="PATH", help="also write the results as JSON")
    ap.add_argument("--methods", nargs="*", help="only methods whose label starts with these")
    ap.add_argument("--data", nargs="*", help="only data sets whose name starts with these")
    ap.add_argument("--no-stages", action="store_true", help="skip the per-stage split")
    ap.add_argument("--no-commands", action="store_true",
                    help="skip the whole-command runs (tiled LAZ, batch)")
    ap.add_argument("--apss-timeout", type=float, default=900.0, help="seconds per APSS run")
    ap.add_argument("--apss-worker", metavar="NPZ", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.apss_worker:
        _apss_worker(args.apss_worker)
        return
    if os.environ.get(_MMAP_ENV) is None:
        # restart with a fixed mmap threshold so that peak memory is measured per call
        env = dict(os.environ, **{_MMAP_ENV: "65536"})
        os.execve(sys.executable, [sys.executable, os.path.abspath(__file__)] + sys.argv[1:], env)
    report = run(quick=args.quick, repeat=args.repeat, apss_timeout=args.apss_timeout,
                 methods=args.methods, stages=not args.no_stages, data=args.data,
                 commands=not args.no_commands)
    print(format_table(report))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(report, fh, indent=1)


if __name__ == "__main__":
    main()
