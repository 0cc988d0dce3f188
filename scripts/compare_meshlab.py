"""Compare meshcurv with MeshLab's built-in curvature filters (through pymeshlab).

Methods: meshcurv (CGA circle fits), MeshLab "Taubin approximation", "Quadric Fitting",
"Scale Dependent Quadric Fitting" (SDQF) from ``compute_curvature_principal_directions_per_vertex``
and APSS (``compute_curvature_and_color_apss_per_vertex``) on the point set. Every MeshLab filter
runs in a child process (``python compare_meshlab.py --worker in.npz out.npz``) with a timeout:
some filters abort the whole process (glibc "double free" in Taubin, APSS on some inputs); a crash
or timeout becomes a result row instead of killing the comparison.

Data: the analytic surfaces of :mod:`meshcurv.surfaces` (clean, and with Gaussian noise of 0.1 %
and 0.3 % of the bounding-box diagonal along the normal; regular and random sampling) against
their exact curvatures, and the sample meshes shipped with pymeshlab (no ground truth: agreement
statistics between methods).

Usage::

    python scripts/compare_meshlab.py            # full run -> docs/comparison.md, docs/*.png
    python scripts/compare_meshlab.py --quick    # smaller meshes, about a minute of CPU time
    python scripts/compare_meshlab.py --smallest --out /tmp/cmp   # the test-suite configuration

Accuracy cases against exact curvature, one group or all (``all`` at full size with the default
methods and options writes docs/accuracy_cases.md; anything else a temporary folder or --out)::

    python scripts/compare_meshlab.py --accuracy-cases all
    python scripts/compare_meshlab.py --accuracy-cases cnc --methods meshcurv
    python scripts/compare_meshlab.py --accuracy-cases surfaces,spikes --option weighting=none

Groups: ``surfaces`` (clean and noisy torus, paraboloid, ellipsoid, cylinder K = 0; meshes),
``cnc`` (the six clouds of ../shared/bench/cnc under the paper's noise grid, mean |dH|, with
their README's CNC figures beside), ``density`` (one-sided half sphere, density falling 25x),
``icosahedra`` (subdivisions 0-2), ``coarse`` (trimesh's low-poly tori), ``spikes`` (sphere
with 2 % scanner spikes), ``terrain`` (scan-line terrains). MeshLab runs on the mesh groups
only.

Sign and label normalisation (all methods are brought to meshcurv's convention: outward normal,
convex positive, k1 >= k2); measured on a sphere and a torus with outward-wound faces:

- QF / SDQF: the vertex quality written for ``curvcolormethod="Min Curvature"`` is our k1 (the
  larger, convex-positive value) and "Max Curvature" is our k2 -- MeshLab's labels are swapped,
  its signs agree with ours. "Mean Curvature" is (k1 + k2) / 2 and "Gaussian Curvature" k1 k2.
- Taubin approximation: same signs, but the two qualities are not ordered per vertex (about 20 %
  of the vertices of a torus have "Min" < "Max"), so k1 = max and k2 = min of the two.
- APSS: ``curvaturetype="K1"`` is k1 and "K2" is k2, convex positive with outward normals
  ("Mean" is not (k1 + k2) / 2 and is not used).
- Each value needs its own filter call (MeshLab exposes k1 and k2 only through vertex quality),
  so every MeshLab method runs twice per mesh; the reported time is that of one call.
- Taubin returned 0 for both curvatures at vertex 0 of the 2562-vertex icosphere (a valence-5
  vertex; the other eleven are fine), which sets its max error there to 1.0; left as measured.
- APSS aborts the process (SIGABRT) on some clean inputs (seen on the 2562-vertex icosphere,
  not on the 10242-vertex one); the child process turns that into a "crash (signal 6)" row.
- Radius: SDQF takes ``scale=PureValue(radius)``. APSS takes a multiple ``filterscale`` of a
  per-point radius r_i = d16_i / 2 (d16: distance to the 16th nearest neighbour, MeshLab's
  ``computeVertexRaddi``); we pass ``filterscale = radius / mean(r_i)`` so its support matches
  the ball radius. Taubin (1-ring) and QF (2-ring) have no radius.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(HERE)

# MeshLab filter methods compared, with the enum strings of pymeshlab 2025.7.
MESHLAB_METHODS = {
    "Taubin": "Taubin approximation",
    "QF": "Quadric Fitting",
    "SDQF": "Scale Dependent Quadric Fitting",
    "APSS": None,
}


# ---------------------------------------------------------------------------------------------
# MeshLab, in a child process
# ---------------------------------------------------------------------------------------------

def apss_filterscale(vertices, radius):
    """APSS ``filterscale`` whose support matches a ball of ``radius``: MeshLab's support is
    filterscale x a per-point radius d16 / 2 (its ``computeVertexRaddi``)."""
    from scipy.spatial import cKDTree

    d16 = cKDTree(vertices).query(vertices, min(16, len(vertices)), workers=-1)[0][:, -1]
    return float(radius / np.mean(0.5 * d16))


def _worker(inp, out):
    """Child process: run one MeshLab method on the mesh in ``inp`` (npz), write ``out`` (npz)."""
    import pymeshlab

    d = np.load(inp)
    v, f, method, radius = d["vertices"], d["faces"], str(d["method"]), float(d["radius"])
    values, seconds = [], []
    if method == "APSS":
        if "normals" in d and d["normals"].size:
            normals = d["normals"]
        else:
            normals = pymeshlab.Mesh(v, f).vertex_normal_matrix()
        filterscale = apss_filterscale(v, radius)
        for ctype in ("K1", "K2"):
            ms = pymeshlab.MeshSet()
            ms.add_mesh(pymeshlab.Mesh(vertex_matrix=v, v_normals_matrix=normals))
            t0 = time.perf_counter()
            ms.compute_curvature_and_color_apss_per_vertex(filterscale=filterscale,
                                                           curvaturetype=ctype)
            seconds.append(time.perf_counter() - t0)
            values.append(ms.current_mesh().vertex_scalar_array().astype(np.float64))
    else:
        for cm in ("Min Curvature", "Max Curvature"):
            ms = pymeshlab.MeshSet()
            ms.add_mesh(pymeshlab.Mesh(v, f))
            t0 = time.perf_counter()
            ms.compute_curvature_principal_directions_per_vertex(
                method=MESHLAB_METHODS[method], curvcolormethod=cm,
                scale=pymeshlab.PureValue(radius), autoclean=False)
            seconds.append(time.perf_counter() - t0)
            m = ms.current_mesh()
            if m.vertex_number() != len(v):
                raise RuntimeError(f"MeshLab changed the vertex count {len(v)} -> {m.vertex_number()}")
            values.append(m.vertex_scalar_array().astype(np.float64))
    a, b = values
    # Normalise: "Min" (QF/SDQF) and "K1" (APSS) are our k1; Taubin's pair is unordered.
    k1, k2 = np.fmax(a, b), np.fmin(a, b)
    np.savez(out, k1=k1, k2=k2, seconds=np.mean(seconds))


def run_meshlab(method, vertices, faces, radius, normals=None, timeout=300.0, retries=3):
    """Run one MeshLab method in a child process.

    Parameters
    ----------
    method : {"Taubin", "QF", "SDQF", "APSS"}
    vertices : (n, 3) float; faces : (m, 3) int
    radius : float, model units (SDQF scale, APSS support)
    normals : (n, 3) float, optional, point normals for APSS (default: MeshLab's vertex normals)
    timeout : float, seconds per attempt
    retries : int, extra attempts after a crash (MeshLab's crashes are not deterministic)

    Returns
    -------
    dict with k1, k2 ((n,) float, NaN on failure), seconds (one filter call) and status
    ("ok", "crash (signal N)", "timeout", or the error message).
    """
    n = len(vertices)
    nan = np.full(n, np.nan)
    status = "not run"
    with tempfile.TemporaryDirectory() as tmp:
        inp, out = os.path.join(tmp, "in.npz"), os.path.join(tmp, "out.npz")
        np.savez(inp, vertices=np.asarray(vertices, np.float64),
                 faces=np.asarray(faces, np.int64), method=method, radius=radius,
                 normals=np.zeros((0, 3)) if normals is None else np.asarray(normals, np.float64))
        for _ in range(retries + 1):
            try:
                p = subprocess.run([sys.executable, os.path.abspath(__file__), "--worker", inp, out],
                                   capture_output=True, text=True, timeout=timeout)
            except subprocess.TimeoutExpired:
                return dict(k1=nan, k2=nan, seconds=timeout, status="timeout")
            if p.returncode == 0 and os.path.exists(out):
                r = np.load(out)
                return dict(k1=r["k1"], k2=r["k2"], seconds=float(r["seconds"]), status="ok")
            if p.returncode < 0:
                status = f"crash (signal {-p.returncode})"
            else:
                lines = (p.stderr or "").strip().splitlines()
                status = "error: " + (lines[-1][:120] if lines else f"exit {p.returncode}")
                break
    return dict(k1=nan, k2=nan, seconds=float("nan"), status=status)


# ---------------------------------------------------------------------------------------------
# meshcurv
# ---------------------------------------------------------------------------------------------

# meshcurv variants compared. "meshcurv" uses the library's defaults; "meshcurv (equal
# weights)" the same with weighting="none", the choice for noisy data when the weights are not
# picked from the measured noise; "meshcurv (auto R)" the defaults with the radius from
# meshcurv.autoradius.
EQUAL_WEIGHTS = dict(weighting="none")


def current_defaults():
    """The estimator's default options that the comparison varies, as ``name=value`` text."""
    import inspect

    import meshcurv

    params = inspect.signature(meshcurv.principal_curvatures).parameters
    options = meshcurv.Options()
    names = ("weighting", "normal_estimation", "slab", "n_directions", "robust")
    return ", ".join(f"`{n}={params[n].default if n in params else getattr(options, n)!r}`"
                     for n in names if n in params or hasattr(options, n))


def run_meshcurv(vertices, faces, radius, **settings):
    """meshcurv.principal_curvatures, timed (call :func:`warm_up` first); returns a dict."""
    import meshcurv

    t0 = time.perf_counter()
    res = meshcurv.principal_curvatures(vertices, faces, radius=radius, **settings)
    return dict(k1=res.k1, k2=res.k2, seconds=time.perf_counter() - t0, status="ok")


def warm_up():
    """Compile the numba kernels once so run times exclude JIT compilation."""
    import meshcurv
    from meshcurv import surfaces

    s = surfaces.sphere(1.0, 2)
    for ne in ("faces", "pca"):
        meshcurv.principal_curvatures(s.vertices, s.faces, radius=0.5, normal_estimation=ne)


# ---------------------------------------------------------------------------------------------
# Cases with ground truth
# ---------------------------------------------------------------------------------------------

NOISE_LEVELS = (0.0, 0.001, 0.003)


@dataclass
class Case:
    """One analytic surface at one noise level; ``radius`` is shared by all ball methods."""

    surface: str
    sampling: str
    noise: float
    radius: float
    mesh: object = field(repr=False)

    @property
    def label(self):
        return f"{self.surface} ({self.sampling})"


def _surfaces(mode):
    """(name, sampling, Surface, radius) per configuration; radius ~ 8-10 sample spacings."""
    from meshcurv import surfaces as S

    if mode == "smallest":
        return [("sphere", "regular", S.sphere(1.0, 4), 0.6)]
    if mode == "quick":
        return [("sphere", "regular", S.sphere(1.0, 4), 0.6),
                ("sphere", "random", S.sphere(1.0, sampling="random", n=2500), 0.6),
                ("torus", "regular", S.torus(2.0, 0.5, 120, 30), 0.45),
                ("paraboloid", "regular", S.paraboloid(spacing=0.4), 3.0),
                ("paraboloid", "random", S.paraboloid("random", n=2500), 3.0)]
    return [("sphere", "regular", S.sphere(1.0, 5), 0.35),
            ("sphere", "random", S.sphere(1.0, sampling="random", n=10000), 0.35),
            ("torus", "regular", S.torus(2.0, 0.5, 240, 60), 0.3),
            ("paraboloid", "regular", S.paraboloid(spacing=0.2), 2.0),
            ("paraboloid", "random", S.paraboloid("random", n=10000), 2.0)]


def build_cases(mode, noise_levels=NOISE_LEVELS):
    """All (surface, sampling, noise) cases of a configuration."""
    from meshcurv.surfaces import add_normal_noise

    cases = []
    for name, sampling, surf, radius in _surfaces(mode):
        for noise in noise_levels:
            mesh = add_normal_noise(surf, noise, seed=1) if noise > 0 else surf
            cases.append(Case(name, sampling, noise, radius, mesh))
    return cases


def error_stats(k1, k2, surf, mask):
    """Errors against the exact curvatures on ``mask``; NaN estimates count as failures.

    rel = mean(|dk1| + |dk2|) / mean(|k1| + |k2|) over the vertices with an estimate.
    """
    e1 = np.abs(k1[mask] - surf.k1[mask])
    e2 = np.abs(k2[mask] - surf.k2[mask])
    ok = np.isfinite(e1) & np.isfinite(e2)
    if not ok.any():
        return dict(mean_dk1=np.nan, max_dk1=np.nan, mean_dk2=np.nan, max_dk2=np.nan,
                    rel=np.nan, failed=1.0)
    scale = np.mean(np.abs(surf.k1[mask][ok]) + np.abs(surf.k2[mask][ok]))
    return dict(mean_dk1=float(e1[ok].mean()), max_dk1=float(e1[ok].max()),
                mean_dk2=float(e2[ok].mean()), max_dk2=float(e2[ok].max()),
                rel=float((e1[ok] + e2[ok]).mean() / scale), failed=float(1 - ok.mean()))


def run_case(case, methods, timeout):
    """Run every method on one case; returns (rows, {method: (k1, k2)})."""
    from meshcurv.autoradius import auto_radius

    m = case.mesh
    mask = m.border_distance >= case.radius
    rows, fields = [], {}
    for method in methods:
        radius = case.radius
        if method == "meshcurv":
            r = run_meshcurv(m.vertices, m.faces, radius)
        elif method == "meshcurv (equal weights)":
            r = run_meshcurv(m.vertices, m.faces, radius, **EQUAL_WEIGHTS)
        elif method == "meshcurv (auto R)":
            t0 = time.perf_counter()
            radius = auto_radius(m.vertices, m.faces)
            r = run_meshcurv(m.vertices, m.faces, radius)
            r["seconds"] = time.perf_counter() - t0
        else:
            r = run_meshlab(method, m.vertices, m.faces, radius, timeout=timeout)
        stats = error_stats(r["k1"], r["k2"], m, mask)
        rows.append(dict(surface=case.surface, sampling=case.sampling, noise=case.noise,
                         method=method, radius=radius if method in BALL_METHODS else None,
                         seconds=r["seconds"], status=r["status"], n=int(mask.sum()), **stats))
        fields[method] = (r["k1"], r["k2"])
    return rows, fields


# meshcurv options measured one at a time against the defaults (same radius).
SETTINGS_STUDY = {
    "defaults (auto, PCA normals)": {},
    "none, PCA normals": dict(weighting="none", normal_estimation="pca"),
    "none, face normals": dict(weighting="none", normal_estimation="faces"),
    "distance, PCA normals": dict(weighting="distance", normal_estimation="pca"),
    "distance, face normals": dict(weighting="distance", normal_estimation="faces"),
    "auto, face normals": dict(weighting="auto", normal_estimation="faces"),
    "none, PCA, slab 0.1": dict(weighting="none", normal_estimation="pca", slab=0.1),
    "none, PCA, slab 0.5": dict(weighting="none", normal_estimation="pca", slab=0.5),
    "none, PCA, 16 directions": dict(weighting="none", normal_estimation="pca", n_directions=16),
    "none, PCA, robust off": dict(weighting="none", normal_estimation="pca", robust=False),
    "none, PCA, section blend off": dict(weighting="none", normal_estimation="pca",
                                         section_blend=False),
    "none, PCA, unit circle norm.": dict(weighting="none", normal_estimation="pca",
                                         circle_normalization="unit"),
}

# Radii of the radius study, as multiples of each case's shared radius.
RADIUS_FACTORS = (0.5, 0.75, 1.0, 1.5)


def mean_error(k1, k2, surf, mask):
    """Mean (|dk1| + |dk2|) / 2 over ``mask`` (NaN estimates skipped)."""
    st = error_stats(k1, k2, surf, mask)
    return 0.5 * (st["mean_dk1"] + st["mean_dk2"])


def settings_study(cases, names=None):
    """meshcurv under the entries ``names`` of SETTINGS_STUDY (default all); rows of
    (case, setting, error)."""
    import meshcurv

    rows = []
    for case in cases:
        m = case.mesh
        mask = m.border_distance >= case.radius
        for name in names or list(SETTINGS_STUDY):
            settings = SETTINGS_STUDY[name]
            res = meshcurv.principal_curvatures(m.vertices, m.faces, radius=case.radius,
                                                **settings)
            error = mean_error(res.k1, res.k2, m, mask)
            rows.append(dict(surface=case.surface, sampling=case.sampling, noise=case.noise,
                             setting=name, error=error))
    return rows


def radius_study(cases):
    """meshcurv (defaults) at fixed multiples of the shared radius and at auto_radius."""
    import meshcurv
    from meshcurv.autoradius import auto_radius

    rows = []
    for case in cases:
        m = case.mesh
        mask = m.border_distance >= case.radius
        row = dict(surface=case.surface, sampling=case.sampling, noise=case.noise,
                   radius=case.radius)
        for factor in RADIUS_FACTORS:
            res = meshcurv.principal_curvatures(m.vertices, m.faces, radius=factor * case.radius)
            row[factor] = mean_error(res.k1, res.k2, m, mask)
        auto = auto_radius(m.vertices, m.faces)
        res = meshcurv.principal_curvatures(m.vertices, m.faces, radius=auto)
        row["auto"], row["auto_radius"] = mean_error(res.k1, res.k2, m, mask), auto
        rows.append(row)
    return rows


BALL_METHODS = ("meshcurv", "meshcurv (equal weights)", "meshcurv (auto R)", "SDQF", "APSS")
COMPARED = ["meshcurv", "meshcurv (equal weights)", "meshcurv (auto R)", "Taubin", "QF", "SDQF",
            "APSS"]


# ---------------------------------------------------------------------------------------------
# Real meshes (no ground truth)
# ---------------------------------------------------------------------------------------------

SAMPLE_MESHES = {"smallest": [], "quick": ["bunny10k_textured.obj"],
                 "full": ["bunny.obj", "bunny10k_textured.obj", "rangemaps/face000.ply"]}


def sample_mesh_dir():
    import pymeshlab

    return os.path.join(os.path.dirname(pymeshlab.__file__), "tests", "sample_meshes")


def load_mesh(path):
    """Vertices and faces of a mesh file (pymeshlab loader; unreferenced vertices are kept)."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.load_new_mesh(path)
    m = ms.current_mesh()
    return m.vertex_matrix().astype(np.float64), m.face_matrix().astype(np.int64)


def crop_mesh(vertices, faces, max_vertices):
    """The ``max_vertices`` vertices nearest the centre of the bounding box, with the faces
    among them (renumbered); the mesh itself when it is small enough."""
    if len(vertices) <= max_vertices:
        return vertices, faces, len(vertices)
    centre = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
    keep = np.zeros(len(vertices), dtype=bool)
    keep[np.argsort(np.linalg.norm(vertices - centre, axis=1))[:max_vertices]] = True
    faces = faces[keep[faces].all(axis=1)]
    return vertices[keep], _reindex(faces, keep), len(vertices)


def agreement(fields, used, reference="meshcurv"):
    """Agreement of each method with ``reference`` on the vertices ``used``.

    Curvatures are compared in units of the reference's median curvedness (c):
    median |dk1| / c, median |dk2| / c, Spearman correlation of the mean curvature H, and the
    share of vertices where the sign of H (convex/concave) agrees.
    """
    from scipy.stats import spearmanr

    from meshcurv.shape import curvedness

    k1r, k2r = fields[reference]
    c = np.nanmedian(curvedness(k1r, k2r)[used])
    rows = []
    for method, (k1, k2) in fields.items():
        if method == reference:
            continue
        ok = used & np.isfinite(k1) & np.isfinite(k2) & np.isfinite(k1r) & np.isfinite(k2r)
        if ok.sum() < 10:
            rows.append(dict(method=method, dk1=np.nan, dk2=np.nan, rho_h=np.nan, sign_h=np.nan,
                             covered=float(ok.mean())))
            continue
        h, hr = (k1 + k2)[ok], (k1r + k2r)[ok]
        rows.append(dict(method=method, dk1=float(np.median(np.abs(k1 - k1r)[ok]) / c),
                         dk2=float(np.median(np.abs(k2 - k2r)[ok]) / c),
                         rho_h=float(spearmanr(h, hr)[0]),
                         sign_h=float(np.mean(np.sign(h) == np.sign(hr))),
                         covered=float(ok.sum() / used.sum())))
    return rows, float(c)


# Larger sample meshes are cropped around their centre (MeshLab's APSS and SDQF take minutes
# on the 86k-vertex range map on a shared 2-core machine).
MAX_REAL_VERTICES = 36000


def run_real(name, path, timeout):
    """All methods on one sample mesh; radius from meshcurv.autoradius for every ball method."""
    from meshcurv.autoradius import auto_radius

    v, f, n_original = crop_mesh(*load_mesh(path), MAX_REAL_VERTICES)
    if n_original > len(v):
        name = f"{name}, cropped to the {len(v)} of {n_original} vertices nearest its centre"
    used = np.zeros(len(v), dtype=bool)
    used[f.ravel()] = True
    radius = auto_radius(v, f)
    fields, times, status = {}, {}, {}
    for method in ["meshcurv", "Taubin", "QF", "SDQF", "APSS"]:
        if method == "meshcurv":
            r = run_meshcurv(v, f, radius)
        elif method == "APSS":
            # APSS gets the referenced points only (unreferenced ones have no normal)
            r = run_meshlab(method, v[used], _reindex(f, used), radius, timeout=timeout)
            k1, k2 = np.full(len(v), np.nan), np.full(len(v), np.nan)
            k1[used], k2[used] = r["k1"], r["k2"]
            r = {**r, "k1": k1, "k2": k2}
        else:
            r = run_meshlab(method, v, f, radius, timeout=timeout)
        fields[method] = (r["k1"], r["k2"])
        times[method], status[method] = r["seconds"], r["status"]
    rows, c = agreement(fields, used)
    return dict(name=name, n=int(used.sum()), faces=len(f), radius=radius, scale=c, rows=rows,
                times=times, status=status, fields=fields, vertices=v, faces_array=f)


def _reindex(faces, used):
    """Faces renumbered onto the used vertices only (APSS gets the referenced points)."""
    new = np.cumsum(used) - 1
    return new[faces]


# ---------------------------------------------------------------------------------------------
# Accuracy cases (--accuracy-cases): one group at a time, each against exact curvature
# ---------------------------------------------------------------------------------------------

ACCURACY_GROUPS = ("surfaces", "cnc", "density", "icosahedra", "coarse", "decimated",
                   "ellipsoids", "spikes", "terrain")
MESHLAB_NAMES = tuple(MESHLAB_METHODS)

# CNC reference: mean |H - H_true| over the six clouds, the authors' code (Avg-Hexagram,
# K nearest neighbours), from ../shared/bench/cnc/README.md; keys (sigma_eps, sigma_xi).
CNC_REFERENCE = {(0.0, 0.0): (0.0012, 0.0017), (0.0, 0.1): (0.067, 0.026),
                 (0.1, 0.0): (0.022, 0.0088), (0.1, 0.1): (0.079, 0.028),
                 (0.2, 0.2): (0.160, 0.056)}
CNC_NOISE = (0.0, 0.1, 0.2)
CNC_FILES = ("goursat_010000", "goursat_025000", "goursat_050000",
             "torus_010000", "torus_025000", "torus_050000")

# Seeds of the generated noise, spikes and samplings (fixed: reruns give the same points).
SEED_CNC, SEED_DENSITY, SEED_SPIKES, SEED_TERRAIN, SEED_ELLIPSOID = 2023, 25, 13, 7, 0


def find_cnc_dir():
    """The benchmark clouds' folder: ``$MESHCURV_CNC_DIR``, else ``shared/bench/cnc`` beside
    the repository or beside one of its parent folders; None when absent."""
    env = os.environ.get("MESHCURV_CNC_DIR")
    if env:
        return env
    d = ROOT
    while True:
        cand = os.path.join(os.path.dirname(d), "shared", "bench", "cnc")
        if os.path.isdir(cand):
            return cand
        if os.path.dirname(d) == d:
            return None
        d = os.path.dirname(d)


def load_cnc_cloud(path):
    """One cloud of the CNC benchmark: (points (n, 3), exact normals (n, 3), truth Surface).

    Read with :func:`meshcurv.io.xyz.read_xyz` (``x y z nx ny nz``; the '#' first line, whose
    column names are wrong, is skipped); the truth is the exact geometry at each point's
    projection onto the surface (:func:`meshcurv.surfaces.torus_at` with R 6, r 2, or
    :func:`meshcurv.surfaces.goursat_at`), named by the file's name.
    """
    from meshcurv import surfaces
    from meshcurv.io.xyz import read_xyz

    data = read_xyz(path)
    name = os.path.basename(path)
    if name.startswith("torus"):
        truth = surfaces.torus_at(data.vertices, 6.0, 2.0)
    elif name.startswith("goursat"):
        truth = surfaces.goursat_at(data.vertices)
    else:
        raise ValueError(f"{name}: not a cloud of the CNC benchmark (torus_* or goursat_*)")
    return data.vertices, data.normals, truth


def noisy_positions(points, sigma, seed):
    """The paper's position noise: a copy of ``points`` + N(0, sigma^2) per coordinate
    (absolute units)."""
    noise = np.random.default_rng(seed).normal(scale=sigma, size=points.shape) if sigma else 0
    return points + noise


def noisy_normals(normals, sigma, seed):
    """The paper's normal noise: n + N(0, sigma^2 I), renormalised (a copy)."""
    n = normals + (np.random.default_rng(seed).normal(scale=sigma, size=normals.shape)
                   if sigma else 0)
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def _selected(methods, group_has_mesh=True):
    """The methods of ``methods`` that run on a group (MeshLab's only on meshes)."""
    return [m for m in methods if m == "meshcurv" or (group_has_mesh and m in MESHLAB_NAMES)]


def _dk(k1, k2, t1, t2):
    """Per-vertex errors: mean (|dk1| + |dk2|) / 2 and worst max(|dk1|, |dk2|); NaN where no
    estimate."""
    e1, e2 = np.abs(k1 - t1), np.abs(k2 - t2)
    return 0.5 * (e1 + e2), np.fmax(e1, e2) + np.where(np.isnan(e1) | np.isnan(e2), np.nan, 0)


def _curvature_row(k1, k2, truth, mask):
    """% valid (finite estimate), mean / max of |dk| over the valid rows of ``mask``."""
    mean_dk, max_dk = _dk(k1[mask], k2[mask], truth.k1[mask], truth.k2[mask])
    ok = np.isfinite(mean_dk)
    return dict(n=int(mask.sum()), valid=float(ok.mean()) if ok.size else np.nan,
                mean_dk=float(mean_dk[ok].mean()) if ok.any() else np.nan,
                max_dk=float(max_dk[ok].max()) if ok.any() else np.nan)


def _radius_switch(radius, switches):
    """(radius, Options switches) of a meshcurv run: ``--option radius=...`` (e.g. "auto")
    replaces the case's radius of every meshcurv run."""
    switches = dict(switches)
    return switches.pop("radius", radius), switches


def _run(method, v, f, radius, switches, timeout, normals=None):
    """One method on one input: dict(k1, k2, seconds, status, radius, valid_flags)."""
    import meshcurv

    if method == "meshcurv":
        radius, switches = _radius_switch(radius, switches)
        t0 = time.perf_counter()
        res = meshcurv.principal_curvatures(v, f, normals=normals, radius=radius, **switches)
        return dict(k1=res.k1, k2=res.k2, seconds=time.perf_counter() - t0, status="ok",
                    radius=res.radius, valid=res.valid)
    r = run_meshlab(method, v, np.zeros((0, 3), np.int64) if f is None else f, radius,
                    timeout=timeout)
    return {**r, "radius": radius if method in ("SDQF", "APSS") else None,
            "valid": np.isfinite(r["k1"]) & np.isfinite(r["k2"])}


def _mesh_surfaces(size):
    """(name, Surface, radius or None = meshcurv's default, noise levels) of group surfaces."""
    from meshcurv import surfaces as S

    cyl = S.cylinder(1.0, height=np.pi, n_around=32, n_along=17)   # 32 x 16 square quads
    if size == "smallest":
        return [("torus", S.torus(2.0, 0.5, 60, 15), 0.6, (0.0, 0.003)),
                ("paraboloid", S.paraboloid(spacing=0.5), 2.0, (0.0,)),
                ("ellipsoid", S.ellipsoid((2.0, 1.5, 1.0), 3), 0.6, (0.0,)),
                ("cylinder 32x16", cyl, None, (0.0,)),
                ("egg crate, random", S.egg_crate("random", n=2000), None, (0.0,))]
    return [("torus", S.torus(2.0, 0.5, 240, 60), 0.3, NOISE_LEVELS),
            ("paraboloid", S.paraboloid(spacing=0.2), 2.0, (0.0,)),
            ("ellipsoid", S.ellipsoid((2.0, 1.5, 1.0), 5), 0.3, (0.0,)),
            ("cylinder 32x16", cyl, None, (0.0,)),
            # surfaces no constant was chosen on: curvature varying everywhere, saddles
            ("egg crate", S.egg_crate(), None, (0.0, 0.001)),
            ("egg crate, random", S.egg_crate("random", n=20000), None, (0.0,)),
            ("saddle, random", S.saddle("random", n=20000), None, (0.0,)),
            # a grid 4 times finer one way (scan lines): 4 rows across a border ball
            ("bump, grid 0.02 x 0.08", S.bump(spacing=(0.02, 0.08)), None, (0.0, 0.001))]


def group_surfaces(methods, size, switches, timeout, **_):
    """Clean and noisy torus, clean paraboloid, ellipsoid, cylinder, egg crate and saddle
    meshes (faces given);
    errors over the vertices at least one radius from a border; on the cylinder also
    max |K| / k1^2 (exact K = 0, k1 the exact 1 / radius)."""
    from meshcurv.neighbors import default_radius
    from meshcurv.surfaces import add_normal_noise

    rows = []
    for name, surf, radius, noise_levels in _mesh_surfaces(size):
        radius = float(default_radius(surf.vertices)) if radius is None else radius
        for noise in noise_levels:
            m = add_normal_noise(surf, noise, seed=1) if noise > 0 else surf
            mask = m.border_distance >= radius
            for method in _selected(methods):
                r = _run(method, m.vertices, m.faces, radius, switches, timeout)
                row = dict(group="surfaces", case=f"{name}, {len(m.vertices)} vertices",
                           noise=noise, method=method,
                           radius=r["radius"], seconds=r["seconds"], status=r["status"],
                           **_curvature_row(r["k1"], r["k2"], m, mask))
                if name.startswith("cylinder"):
                    # |K| / k1^2 at least one radius from the border and off its two rings
                    kk = np.abs(r["k1"] * r["k2"]) / m.k1 ** 2
                    for key, where in (("max_K_over_k1sq", mask),
                                       ("max_K_over_k1sq_off_border", m.border_distance > 0)):
                        row[key] = float(np.nanmax(kk[where])) if np.isfinite(
                            kk[where]).any() else np.nan
                rows.append(row)
                print(f"surfaces {name} noise {noise * 100:.1f} % {method}: mean |dk| "
                      f"{row['mean_dk']:.4g}", flush=True)
    return rows


def group_cnc(methods, size, switches, timeout, cnc_dir=None, **_):
    """The six CNC clouds under the paper's noise grid: mean |H - H_true| per file, for
    meshcurv given the noisy normals and given none, at its default radius and at the radius
    whose ball holds ~50 points (CNC's K = 50)."""
    from meshcurv.neighbors import default_radius

    if "meshcurv" not in methods:
        return []
    cnc_dir = cnc_dir or find_cnc_dir()
    if cnc_dir is None or not os.path.isdir(cnc_dir):
        raise FileNotFoundError("the CNC benchmark clouds were not found; pass --cnc-dir "
                                "(or set MESHCURV_CNC_DIR) to the folder of the .pts files")
    files = CNC_FILES[::3] if size == "smallest" else CNC_FILES
    grid = [(0.1, 0.1)] if size == "smallest" else [
        (se, sx) for se in CNC_NOISE for sx in CNC_NOISE]
    import meshcurv

    rows = []
    for fi, name in enumerate(files):
        points, normals, truth = load_cnc_cloud(os.path.join(cnc_dir, name + ".pts"))
        if size == "smallest":
            keep = np.sort(np.random.default_rng(0).choice(len(points), 2000, replace=False))
            points, normals = points[keep], normals[keep]
            truth = truth_rows(truth, keep)
        h_true = 0.5 * (truth.k1 + truth.k2)
        positions_done = set()
        for se, sx in grid:
            # the same noisy positions for every sigma_xi, the same normal noise for every
            # sigma_eps: "no normals" runs once per sigma_eps
            p = noisy_positions(points, se, SEED_CNC + 100 * fi + round(10 * se))
            n = noisy_normals(normals, sx, SEED_CNC + 100 * fi + 50 + round(10 * sx))
            r50 = float(default_radius(p, target_neighbors=50))
            modes = [("normals", n, sx)]
            if se not in positions_done:
                modes.append(("no normals", None, None))
                positions_done.add(se)
            rules = (("default", None), ("~50 points", r50))
            if "radius" in switches:
                rules = ((f"radius={switches['radius']}", None),)
            for mode, given, sigma_xi in modes:
                for rule, radius in rules:
                    radius, options = _radius_switch(radius, switches)
                    t0 = time.perf_counter()
                    res = meshcurv.principal_curvatures(p, normals=given, radius=radius,
                                                        **options)
                    dh = np.abs(res.mean - h_true)
                    ok = np.isfinite(dh)
                    rows.append(dict(group="cnc", file=name, sigma_eps=se, sigma_xi=sigma_xi,
                                     method=f"meshcurv, {mode}", radius_rule=rule,
                                     radius=res.radius, n=len(p),
                                     median_neighbors=float(np.median(res.n_neighbors)),
                                     mean_dH=float(dh[ok].mean()) if ok.any() else np.nan,
                                     valid=float(ok.mean()),
                                     seconds=time.perf_counter() - t0, status="ok"))
            print(f"cnc {name} sigma_eps {se} sigma_xi {sx}: " + ", ".join(
                f"{r['method']} ({r['radius_rule']}) {r['mean_dH']:.4g}" for r in rows[-4:]),
                flush=True)
    return rows


def truth_rows(surface, rows):
    """The exact fields of ``surface`` (a cloud without faces) at the indices ``rows``."""
    return type(surface)(surface.name, surface.vertices[rows], surface.faces,
                         surface.normals[rows], surface.k1[rows], surface.k2[rows],
                         surface.d1[rows], surface.d2[rows], surface.border_distance[rows])


def half_sphere_variable_density(n=10000, falloff=25.0, seed=SEED_DENSITY):
    """About ``n`` points of the upper half (z > 0) of the unit sphere whose density falls
    ``falloff`` times from x = -1 to x = 1 (exponentially in x; uniform points kept with
    probability falloff^(-(x + 1) / 2)): a one-sided scan seen from +z. Exact k1 = k2 = 1 and
    outward normals; a :class:`meshcurv.surfaces.Surface` without faces."""
    from meshcurv.surfaces import Surface

    rng = np.random.default_rng(seed)
    # acceptance: x is uniform on the sphere, so the mean of falloff^-t over t in [0, 1]
    accept = (1 - 1 / falloff) / np.log(falloff)
    u = rng.normal(size=(int(np.ceil(n / accept)), 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u[:, 2] = np.abs(u[:, 2])
    u = u[rng.uniform(size=len(u)) < falloff ** (-(u[:, 0] + 1) / 2)]
    ones, nan3 = np.ones(len(u)), np.full((len(u), 3), np.nan)
    return Surface("half sphere", u, np.zeros((0, 3), np.int64), u.copy(), ones, ones.copy(),
                   nan3, nan3.copy(), u[:, 2].copy())


def group_density(methods, size, switches, timeout, **_):
    """One-sided variable-density cloud (half unit sphere, density falling 25x): % valid and
    max |dk| over all points, for meshcurv without normals (default radius and "auto") and
    with the exact normals."""
    if "meshcurv" not in methods:
        return []
    s = half_sphere_variable_density(2000 if size == "smallest" else 10000)
    everywhere = np.ones(len(s.vertices), dtype=bool)
    rows = []
    for label, normals, radius in (("meshcurv, no normals", None, None),
                                   ("meshcurv, no normals, radius auto", None, "auto"),
                                   ("meshcurv, exact normals", s.normals, None)):
        r = _run("meshcurv", s.vertices, None, radius, switches, timeout, normals=normals)
        rows.append(dict(group="density", case=f"half sphere, {len(s.vertices)} points",
                         method=label, radius=r["radius"], seconds=r["seconds"],
                         status=r["status"], **_curvature_row(r["k1"], r["k2"], s, everywhere)))
        print(f"density {label}: valid {rows[-1]['valid']:.4f}, max |dk| "
              f"{rows[-1]['max_dk']:.4g}", flush=True)
    return rows


def group_icosahedra(methods, size, switches, timeout, **_):
    """Icosahedra of subdivision 0-2 (12, 42, 162 vertices, unit radius; k = 1): % valid and
    max |dk| over the valid rows, meshcurv on the mesh and on its points alone; MeshLab on the
    mesh, SDQF and APSS at meshcurv's radius."""
    import trimesh

    from meshcurv.neighbors import default_radius
    from meshcurv.surfaces import Surface

    rows = []
    for sub in (0, 1, 2):
        ico = trimesh.creation.icosphere(subdivisions=sub, radius=1.0)
        v = np.asarray(ico.vertices, dtype=np.float64)
        v /= np.linalg.norm(v, axis=1, keepdims=True)
        f = np.asarray(ico.faces, dtype=np.int64)
        ones = np.ones(len(v))
        truth = Surface("icosphere", v, f, v, ones, ones, v * np.nan, v * np.nan, ones * np.inf)
        everywhere = np.ones(len(v), dtype=bool)
        ball = float(default_radius(v))     # meshcurv's default radius, for SDQF and APSS
        runs = [("meshcurv", "meshcurv, mesh", f), ("meshcurv", "meshcurv, points", None)] \
            if "meshcurv" in methods else []
        runs += [(m, m, f) for m in _selected(methods) if m != "meshcurv"]
        for method, label, faces in runs:
            r = _run(method, v, faces, None if method == "meshcurv" else ball, switches,
                     timeout)
            rows.append(dict(group="icosahedra", case=f"subdivision {sub} ({len(v)} vertices)",
                             method=label, radius=r["radius"], seconds=r["seconds"],
                             status=r["status"], **_curvature_row(r["k1"], r["k2"], truth,
                                                                  everywhere)))
        print(f"icosahedra {sub}: " + ", ".join(
            f"{r['method']} valid {r['valid']:.2f} max {r['max_dk']:.3g}"
            for r in rows[-len(runs):]), flush=True)
    return rows


# Coarse tori of trimesh.creation.torus: (major radius, minor radius, major x minor sections).
COARSE_TORI = ((2.0, 0.5, 32, 32), (1.0, 0.2, 32, 32), (1.0, 0.3, 64, 16), (3.0, 1.0, 40, 20),
               (1.0, 0.3, 32, 12))


def group_coarse(methods, size, switches, timeout, **_):
    """Tori of ``trimesh.creation.torus`` coarse for their shape (:data:`COARSE_TORI`, its own
    32 x 32 grid first): % valid, mean and max |dk| over all vertices, meshcurv at its default
    radius on the mesh and on its points alone; MeshLab on the mesh, SDQF and APSS at
    meshcurv's radius for the mesh."""
    import trimesh

    from meshcurv.surfaces import torus_at

    rows = []
    for major, minor, n_major, n_minor in COARSE_TORI[:2] if size == "smallest" else COARSE_TORI:
        mesh = trimesh.creation.torus(major, minor, major_sections=n_major,
                                      minor_sections=n_minor)
        v = np.asarray(mesh.vertices, dtype=np.float64)
        f = np.asarray(mesh.faces, dtype=np.int64)
        truth = torus_at(v, major, minor)
        case = f"torus {major:g} / {minor:g}, {n_major} x {n_minor} ({len(v)} vertices)"
        rows += _mesh_and_points_rows("coarse", case, v, f, truth, methods, switches, timeout)
    return rows


def _mesh_and_points_rows(group, case, v, f, truth, methods, switches, timeout):
    """Rows of one mesh of a group: meshcurv at its default radius with the faces and on the
    points alone, MeshLab's ``methods`` on the mesh (SDQF and APSS at meshcurv's default
    radius for the mesh); errors over all vertices."""
    from meshcurv.neighbors import default_radius

    everywhere = np.ones(len(v), dtype=bool)
    runs = [("meshcurv", "meshcurv, mesh", f), ("meshcurv", "meshcurv, points", None)] \
        if "meshcurv" in methods else []
    runs += [(m, m, f) for m in _selected(methods) if m != "meshcurv"]
    ball = float(default_radius(v, faces=f))    # meshcurv's default radius for the mesh
    rows = []
    for method, label, faces in runs:
        r = _run(method, v, faces, None if method == "meshcurv" else ball, switches, timeout)
        rows.append(dict(group=group, case=case, method=label, radius=r["radius"],
                         seconds=r["seconds"], status=r["status"],
                         **_curvature_row(r["k1"], r["k2"], truth, everywhere)))
    print(f"{group} {case}: " + ", ".join(f"{r['method']} {r['mean_dk']:.3g}" for r in rows),
          flush=True)
    return rows


# Meshes decimated by MeshLab's quadric edge collapse (the mesh, the share of its faces
# kept): the torus 2 / 0.5 of 240 x 60 and the ellipsoid 2 / 1.5 / 1 of 40962 vertices.
DECIMATED = (("torus", 0.2), ("torus", 0.05), ("ellipsoid", 0.1), ("ellipsoid", 0.02))


def decimated_mesh(shape, keep):
    """(vertices, faces, truth): the torus 2 / 0.5 (240 x 60) or the ellipsoid 2 / 1.5 / 1
    (icosphere of 40962 vertices) decimated by MeshLab's quadric edge collapse to ``keep`` of
    its faces (normals preserved); the truth at each vertex's projection onto the surface."""
    import pymeshlab

    from meshcurv import surfaces

    s = surfaces.torus(2.0, 0.5, 240, 60) if shape == "torus" else \
        surfaces.ellipsoid((2.0, 1.5, 1.0), 6)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(s.vertices, s.faces))
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=int(keep * len(s.faces)),
                                                preservenormal=True)
    m = ms.current_mesh()
    v = np.asarray(m.vertex_matrix(), dtype=np.float64)
    f = np.asarray(m.face_matrix(), dtype=np.int64)
    truth = surfaces.torus_at(v, 2.0, 0.5) if shape == "torus" else \
        surfaces.ellipsoid_at(v)
    return v, f, truth


def group_decimated(methods, size, switches, timeout, **_):
    """Meshes decimated by MeshLab (:data:`DECIMATED`): irregular triangles, denser where the
    surface is more curved. meshcurv at its default radius with the faces and on the points
    alone; MeshLab on the mesh, SDQF and APSS at meshcurv's radius for the mesh. Errors over
    all vertices."""
    rows = []
    for shape, keep in DECIMATED[::2] if size == "smallest" else DECIMATED:
        v, f, truth = decimated_mesh(shape, keep)
        case = f"{shape}, decimated to {keep * 100:g} % ({len(v)} vertices)"
        rows += _mesh_and_points_rows("decimated", case, v, f, truth, methods, switches,
                                      timeout)
    return rows


# Ellipsoids at resolutions where a ball of ~100 vertices is no small cap at the ends of their
# long axis: (semi-axes, icosphere subdivisions or None, random points or None).
ELLIPSOIDS = (((2.0, 1.5, 1.0), 3, None), ((2.0, 1.5, 1.0), 4, None),
              ((2.0, 1.5, 1.0), None, 642), ((3.0, 1.0, 0.5), 4, None),
              ((3.0, 1.0, 0.5), 5, None))


def group_ellipsoids(methods, size, switches, timeout, **_):
    """Clean ellipsoid meshes (:data:`ELLIPSOIDS`) whose curvature varies across the default
    radius's balls: meshcurv at its default radius with the faces and on the points alone;
    MeshLab on the mesh, SDQF and APSS at meshcurv's radius for the mesh. Errors over all
    vertices."""
    from meshcurv import surfaces

    rows = []
    for axes, subdivisions, n in ELLIPSOIDS[:2] if size == "smallest" else ELLIPSOIDS:
        s = surfaces.ellipsoid(axes, subdivisions or 0, "random" if n else "regular", n or 0,
                               seed=SEED_ELLIPSOID)
        sampling = f"{n} random points" if n else f"icosphere of {len(s.vertices)} vertices"
        case = f"ellipsoid {' / '.join(f'{a:g}' for a in axes)}, {sampling}"
        rows += _mesh_and_points_rows("ellipsoids", case, s.vertices, s.faces, s, methods,
                                      switches, timeout)
    return rows


def sphere_with_spikes(subdivisions=5, noise=0.0005, spike_share=0.02, spike_range=(0.01, 0.04),
                       seed=SEED_SPIKES):
    """An icosphere (unit radius) with Gaussian noise along the normal (``noise`` x the
    bounding-box diagonal) and ``spike_share`` of its vertices pushed out or in along the
    normal by a uniform ``spike_range`` x the diagonal: (Surface, spike mask (n,) bool).
    The exact curvature stays k = 1 everywhere."""
    from meshcurv.surfaces import add_normal_noise, sphere

    s = add_normal_noise(sphere(1.0, subdivisions), noise, seed=seed)
    rng = np.random.default_rng(seed + 1)
    n = len(s.vertices)
    spikes = np.zeros(n, dtype=bool)
    spikes[rng.choice(n, int(round(spike_share * n)), replace=False)] = True
    push = rng.uniform(*spike_range, spikes.sum()) * rng.choice([-1.0, 1.0], spikes.sum())
    s.vertices = s.vertices.copy()
    s.vertices[spikes] += (push * s.diagonal)[:, None] * s.normals[spikes]
    return s, spikes


def group_spikes(methods, size, switches, timeout, **_):
    """Sphere with scanner spikes: error on the vertices that are not spikes at R 0.3 (mean
    |dk| and share off by more than 10 %, an invalid row counted as off) and the share of the
    spikes meshcurv marks invalid; mesh and cloud path, MeshLab at the same radius."""
    s, spikes = sphere_with_spikes(3 if size == "smallest" else 5)
    radius = 0.6 if size == "smallest" else 0.3
    good = ~spikes
    rows = []
    runs = [("meshcurv", "meshcurv, mesh", s.faces), ("meshcurv", "meshcurv, points", None)] \
        if "meshcurv" in methods else []
    runs += [(m, m, s.faces) for m in _selected(methods) if m != "meshcurv"]
    for method, label, faces in runs:
        r = _run(method, s.vertices, faces, radius, switches, timeout)
        _, worst = _dk(r["k1"], r["k2"], s.k1, s.k2)
        off = ~(worst[good] <= 0.1 * s.k1[good])          # NaN (no estimate) counts as off
        off_h = ~(np.abs(0.5 * (r["k1"] + r["k2"]) - 1.0)[good] <= 0.1)
        row = dict(group="spikes", case=f"sphere, {len(s.vertices)} vertices, "
                   f"{int(spikes.sum())} spikes", method=label, radius=r["radius"],
                   seconds=r["seconds"], status=r["status"],
                   **_curvature_row(r["k1"], r["k2"], s, good), off_10pct=float(off.mean()),
                   off_h_10pct=float(off_h.mean()),
                   spikes_flagged=float((~r["valid"][spikes]).mean())
                   if method == "meshcurv" else np.nan)
        rows.append(row)
        print(f"spikes {label}: mean |dk| {row['mean_dk']:.4g}, off > 10 % "
              f"{row['off_10pct'] * 100:.1f} %", flush=True)
    return rows


def group_terrain(methods, size, switches, timeout, **_):
    """Airborne-scan-like clouds (:func:`meshcurv.surfaces.scan_terrain`, no faces, no
    normals): a gentle and a bumpy terrain, three scan patterns, Gaussian height noise; meshcurv
    oriented towards +z (LAS input's default) at its default radius; errors over the points at
    least two radii from the border."""
    from meshcurv.surfaces import scan_terrain

    if "meshcurv" not in methods:
        return []
    extent = 3.0 if size == "smallest" else 10.0
    patterns = (((0.1, 0.1), 0.0),) if size == "smallest" else \
        (((0.1, 0.1), 0.0), ((0.05, 0.25), 0.1), ((0.03, 0.4), 0.05))
    noises = (0.02,) if size == "smallest" else (0.005, 0.02, 0.05)
    rows = []
    for label, wavelength in (("gentle", 4 * np.pi), ("bumpy", 3.0)):
        for spacing, jitter in patterns:
            s = scan_terrain(spacing, jitter, wavelength=wavelength, extent=extent,
                             seed=SEED_TERRAIN)
            for noise in noises:
                v = s.vertices.copy()
                v[:, 2] += np.random.default_rng(SEED_TERRAIN + 1).normal(scale=noise,
                                                                          size=len(v))
                r = _run("meshcurv", v, None, None, {**switches, "orientation": "+z"}, timeout)
                inner = s.border_distance >= 2 * r["radius"]
                case = (f"{label} terrain, scan {spacing[0]:g} x {spacing[1]:g}, jitter "
                        f"{jitter:g}, {len(v)} points, height noise {noise:g}")
                rows.append(dict(group="terrain", case=case, method="meshcurv, +z",
                                 radius=r["radius"], seconds=r["seconds"], status=r["status"],
                                 **_curvature_row(r["k1"], r["k2"], s, inner)))
                print(f"terrain {case}: mean |dk| {rows[-1]['mean_dk']:.4g}", flush=True)
    return rows


GROUP_RUNNERS = {"surfaces": group_surfaces, "cnc": group_cnc, "density": group_density,
                 "icosahedra": group_icosahedra, "coarse": group_coarse,
                 "decimated": group_decimated, "ellipsoids": group_ellipsoids,
                 "spikes": group_spikes, "terrain": group_terrain}


def _git_commit():
    """Short commit id of the working tree (with "+changes" when it differs), or "-"."""
    try:
        out = subprocess.run(["git", "-C", ROOT, "describe", "--always", "--dirty=+changes"],
                             capture_output=True, text=True, timeout=10)
        return out.stdout.strip() or "-"
    except (OSError, subprocess.SubprocessError):
        return "-"


def _cnc_tables(rows):
    """Markdown: mean |dH| averaged over the files per noise condition, then per file."""
    if not rows:
        return ["(not run: meshcurv not among the methods)", ""]
    # (method, radius rule) in the order run: normals before no normals
    columns = sorted(dict.fromkeys((r["method"], r["radius_rule"]) for r in rows),
                     key=lambda c: c[0].endswith("no normals"))
    grid = list(dict.fromkeys((r["sigma_eps"], r["sigma_xi"]) for r in rows
                              if r["sigma_xi"] is not None))
    n_files = len({r["file"] for r in rows})

    def average(method, rule, se, sx):
        vals = [r["mean_dH"] for r in rows if (r["method"], r["radius_rule"], r["sigma_eps"])
                == (method, rule, se) and (r["sigma_xi"] == sx or sx is None)]
        return float(np.mean(vals)) if len(vals) == n_files else np.nan

    def min_valid(se, sx):
        vals = [r["valid"] for r in rows if r["sigma_eps"] == se
                and r["sigma_xi"] in (sx, None)]
        return min(vals)

    out = ["| sigma_eps | sigma_xi | CNC K=20 | CNC K=50 | " + " | ".join(
        f"{m.split(', ')[1]}, R {rule}" for m, rule in columns) + " | least valid |",
           "|---|---|---|---|" + "---|" * len(columns) + "---|"]
    for se, sx in grid:
        ref = CNC_REFERENCE.get((se, sx), (np.nan, np.nan))
        cells = [_fmt(average(m, rule, se, None if m.endswith("no normals") else sx))
                 for m, rule in columns]
        out.append(f"| {se:g} | {sx:g} | {_fmt(ref[0])} | {_fmt(ref[1])} | "
                   + " | ".join(cells) + f" | {_pct(min_valid(se, sx))} |")
    out += ["", "Per file (the radius in model units, the median number of neighbours in "
            "its ball):", "",
            "| file | sigma_eps | sigma_xi | method | radius | median neighbours | "
            "mean\\|dH\\| | valid |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        sx = "-" if r["sigma_xi"] is None else f"{r['sigma_xi']:g}"
        out.append(f"| {r['file']} | {r['sigma_eps']:g} | {sx} | {r['method']} "
                   f"| {r['radius_rule']}: {_fmt(r['radius'], 3)} "
                   f"| {r['median_neighbors']:.0f} | {_fmt(r['mean_dH'])} | {_pct(r['valid'])} |")
    return out + [""]


def _case_table(rows, extra=()):
    """Markdown table of case rows; ``extra`` = ((key, heading, formatter), ...)."""
    head = "| case | method | radius | valid | mean\\|dk\\| | max\\|dk\\| | " + "".join(
        f"{h} | " for _, h, _ in extra) + "time s | status |"
    out = [head, "|" + "---|" * (8 + len(extra))]
    for r in rows:
        case = r["case"] + (f", noise {r['noise'] * 100:.1f} %" if "noise" in r else "")
        out.append(f"| {case} | {r['method']} | {_fmt(r['radius'], 3)} | {_pct(r['valid'])} "
                   f"| {_fmt(r['mean_dk'])} | {_fmt(r['max_dk'], 3)} | "
                   + "".join(f"{fmt(r.get(k, np.nan))} | " for k, _, fmt in extra)
                   + f"{_fmt(r['seconds'], 2)} | {r['status']} |")
    return out + [""]


GROUP_TEXT = {
    "surfaces": ("Meshes with faces (the ring neighbourhood)",
                 "Torus R 2, r 0.5 (240 x 60), clean and with Gaussian noise along the normal "
                 "(0.1 % and 0.3 % of the bounding-box diagonal), R 0.3; paraboloid z = 0.2 x^2 "
                 "+ 0.1 y^2 on a regular grid of spacing 0.2, R 2; ellipsoid of semi-axes 2, "
                 "1.5, 1 (a 10242-vertex icosphere scaled), R 0.3; open cylinder r 1 of 32 x 16 "
                 "square quads (each split in two triangles) at meshcurv's default radius, "
                 "where max\\|K\\|/k1² is the largest \\|k1 k2\\| / k1_exact² (exact K = 0) "
                 "at its vertices at least one radius from the border, and at all but the two "
                 "border rings; surfaces no constant of meshcurv was chosen on, at its "
                 "default radius: egg crate z = 0.3 sin x sin y on [-3, 3]^2 (a regular grid of "
                 "spacing 0.05, clean and with 0.1 % noise; 20k random points, Delaunay), "
                 "saddle z = 0.25 (x^2 - y^2) on [-2, 2]^2 (20k random points, Delaunay). "
                 "Errors over the vertices at least one radius from a border."),
    "cnc": ("The CNC benchmark clouds (Lachaud et al. 2023)",
            "The six clouds of `../shared/bench/cnc` under the paper's noise model (Gaussian, "
            "per coordinate: sigma_eps on the positions, sigma_xi on the normals, then "
            "renormalised; absolute units; fixed seeds). Mean \\|H - H_true\\| over each "
            "file's points with an estimate, averaged over the files; H_true is the exact "
            "mean curvature at the noise-free point's projection onto the surface (torus "
            "R 6, r 2; Goursat's implicit function, P Hess(F) P / \\|grad F\\|). meshcurv "
            "given the noisy normals, and given none (then it estimates and orients its own; "
            "those columns do not depend on sigma_xi); radius: meshcurv's default "
            "(`radius=None`, a ball of ~100 points) and the ball holding ~50 points "
            "(`default_radius(points, target_neighbors=50)`, CNC's K = 50). CNC columns: "
            "the reference figures of the benchmark's README (the authors' code, K nearest "
            "neighbours, exact normals perturbed by sigma_xi); no figure where it gives none. "
            "`least valid`: the smallest share of points with an estimate among the files."),
    "density": ("One-sided cloud of falling density",
                "Upper half of the unit sphere (k = 1), ~10000 points whose density falls 25x "
                "from x = -1 to x = 1 (random, exponential in x), no faces. valid and errors "
                "over all points, the open rim included; \\|dk\\| = max(\\|dk1\\|, "
                "\\|dk2\\|) for the max."),
    "icosahedra": ("Low-poly spheres",
                   "`trimesh.creation.icosphere(subdivisions)` 0, 1, 2 (12, 42, 162 vertices, "
                   "radius 1, k = 1); meshcurv at its default radius with the faces and on the "
                   "points alone; SDQF and APSS at meshcurv's default radius. A row is valid "
                   "where the method gave a finite estimate."),
    "coarse": ("Coarse tori",
               "`trimesh.creation.torus(major, minor, major_sections, minor_sections)` 2 / 0.5 "
               "(32 x 32, trimesh's own grid), 1 / 0.2 (32 x 32), 1 / 0.3 (64 x 16), 3 / 1 "
               "(40 x 20): few vertices around the tube, so that a ball of ~100 vertices "
               "reaches around it. meshcurv at its default radius with the faces and on the "
               "points alone; MeshLab on the mesh, SDQF and APSS at meshcurv's radius for the "
               "mesh. Errors over all vertices against the exact torus."),
    "decimated": ("Meshes decimated by MeshLab",
                  "The torus 2 / 0.5 of 240 x 60 vertices (`meshcurv.surfaces.torus`) and the "
                  "ellipsoid 2 / 1.5 / 1 of 40962 vertices (`meshcurv.surfaces.ellipsoid`, "
                  "icosphere of 6 subdivisions) decimated by pymeshlab's "
                  "`meshing_decimation_quadric_edge_collapse` (normals preserved) to the share "
                  "of their faces the case gives: irregular triangles, denser where the surface "
                  "is more curved, vertices 0.0004-0.0026 off the surface (median; at most "
                  "0.0009-0.0087). Truth at each "
                  "vertex's projection onto the exact surface. meshcurv at its default radius "
                  "with the faces and on the points alone; MeshLab on the mesh, SDQF and APSS "
                  "at meshcurv's radius for the mesh. Errors over all vertices."),
    "ellipsoids": ("Ellipsoids whose curvature varies across the default balls",
                   "Clean ellipsoids 2 / 1.5 / 1 (`meshcurv.surfaces.ellipsoid`: icospheres of 3 "
                   "and 4 subdivisions scaled by the semi-axes, and 642 uniform random points of "
                   "the sphere, seed 0, with their hull's faces) and 3 / 1 / 0.5 (icospheres of "
                   "4 and 5 subdivisions; curvature 12 at the ends of the long axis): at the "
                   "default radius the balls there turn by more than a radian over a surface "
                   "whose curvature varies across them. meshcurv at its default radius with the "
                   "faces and on the points alone; MeshLab on the mesh, SDQF and APSS at "
                   "meshcurv's radius for the mesh. Errors over all vertices against the exact "
                   "ellipsoid."),
    "terrain": ("Airborne-scan-like terrains",
                "z = 0.03 x^2 - 0.02 y^2 + 0.1 sin(2 pi x / wavelength) on [-10, 10]^2, "
                "gentle (wavelength 4 pi, ~19 default radii) and bumpy (wavelength 3, ~4.5 "
                "radii), sampled on scan lines (a point every 0.1 on lines 0.1 apart; 0.05 on "
                "lines 0.25 apart, jittered by 0.1 of the spacings; 0.03 on lines 0.4 apart, "
                "jittered by 0.05), Gaussian height noise 0.005 / 0.02 / 0.05 (absolute; "
                "fixed seeds); no faces, no normals, meshcurv oriented towards +z at its "
                "default radius. Errors over the points at least two radii from the border."),
    "spikes": ("Sphere with scanner spikes",
               "Icosphere of 10242 vertices (radius 1), Gaussian noise of 0.05 % of the "
               "diagonal along the normal, 2 % of the vertices pushed out or in along the "
               "normal by 1-4 % of the diagonal (uniform, random sign; fixed seed); R 0.3. "
               "Errors over the other 98 %: mean \\|dk\\| = mean (\\|dk1\\| + "
               "\\|dk2\\|) / 2 over their estimates, `off > 10 %` = share whose max"
               "(\\|dk1\\|, \\|dk2\\|) exceeds 0.1 or that have no estimate, "
               "`H off > 10 %` the same for \\|H - 1\\|; "
               "`spikes flagged` = share of the spikes meshcurv marks invalid. meshcurv with "
               "the faces and on the points alone (normals estimated); MeshLab on the mesh "
               "(APSS with MeshLab's vertex normals)."),
}


def _summary(results):
    """Markdown rows: per case of the mesh groups, meshcurv against the best MeshLab method."""
    out = []
    for group in ("surfaces", "coarse", "decimated", "ellipsoids", "spikes"):
        rows = results.get(group, [])
        keys = list(dict.fromkeys((r["case"], r.get("noise")) for r in rows))
        for case, noise in keys:
            by = {r["method"]: r for r in rows if (r["case"], r.get("noise")) == (case, noise)}
            ours = by.get("meshcurv", by.get("meshcurv, mesh"))
            others = [(r["mean_dk"], m) for m, r in by.items()
                      if m in ("QF", "SDQF", "APSS") and np.isfinite(r["mean_dk"])]
            if ours is None or not others:
                continue
            best, name = min(others)
            label = case + (f", noise {noise * 100:.1f} %" if noise is not None else "")
            out.append(f"| {label} | {_fmt(ours['mean_dk'])} | {name} {_fmt(best)} "
                       f"| {_fmt(ours['mean_dk'] / best, 2)} |")
    if not out:
        return []
    return ["| case | meshcurv | best MeshLab | ratio |", "|---|---|---|---|"] + out + [""]


def write_accuracy_report(path, results, command, seconds, switches):
    """docs/accuracy_cases.md: one section per group run."""
    import meshcurv

    lines = ["# Accuracy cases: meshcurv and MeshLab against exact curvature", "",
             f"Generated by `{command}` in {seconds:.0f} s on commit {_git_commit()}. "
             "Run one group with `python scripts/compare_meshlab.py --accuracy-cases GROUP` "
             f"(groups: {', '.join(ACCURACY_GROUPS)}; `--methods meshcurv` skips MeshLab, "
             "`--option NAME=VALUE` passes a meshcurv switch, `--smallest` the test-suite "
             "sizes). Sign convention of every column: outward normal, convex positive, "
             "k1 >= k2.", "",
             f"meshcurv: `principal_curvatures` with "
             f"`{meshcurv.Options(**_radius_switch(None, switches)[1])!r}`"
             + (f" (switches given: {switches})" if switches else " (its defaults)")
             + ", its default radius where a row says none. MeshLab (pymeshlab, one child "
             "process per call): Taubin (1-ring), QF (2-ring), SDQF (`scale` = the radius), "
             "APSS (support matched to the radius); see the script's docstring. "
             "valid = share of the rows with a finite estimate; \\|dk\\| per vertex = "
             "(\\|dk1\\| + \\|dk2\\|) / 2 for the mean, max(\\|dk1\\|, "
             "\\|dk2\\|) for the max, over the valid rows.", ""]
    extras = {"surfaces": (("max_K_over_k1sq", "max\\|K\\|/k1²", lambda x: _fmt(x, 4)),
                           ("max_K_over_k1sq_off_border", "same, off the border rings",
                            lambda x: _fmt(x, 4))),
              "spikes": (("off_10pct", "off > 10 %", _pct), ("off_h_10pct", "H off > 10 %", _pct),
                         ("spikes_flagged", "spikes flagged", _pct))}
    summary = _summary(results)
    if summary:
        lines += ["## Summary", "", "meshcurv's mean \\|dk\\| against the best MeshLab method "
                  "of the same row set (QF, SDQF, APSS; Taubin is never the best); ratio > 1: "
                  "meshcurv worse.", ""] + summary
    for group, rows in results.items():
        title, text = GROUP_TEXT[group]
        lines += [f"## {title} (`--accuracy-cases {group}`)", "", text, ""]
        lines += _cnc_tables(rows) if group == "cnc" else _case_table(rows, extras.get(group, ()))
    with open(path, "w") as fh:
        fh.write("\n".join(lines))


def parse_methods(text):
    """``--methods`` text -> method names in run order; "meshlab" = Taubin, QF, SDQF, APSS."""
    names = []
    for item in (t.strip() for t in text.split(",") if t.strip()):
        expanded = list(MESHLAB_NAMES) if item.lower() == "meshlab" else [item]
        for name in expanded:
            match = [m for m in ("meshcurv",) + MESHLAB_NAMES if m.lower() == name.lower()]
            if not match:
                raise SystemExit(f"--methods: unknown method {name!r}; choose from meshcurv, "
                                 f"meshlab, {', '.join(MESHLAB_NAMES)}")
            names += [m for m in match if m not in names]
    return names


def parse_groups(text):
    """``--accuracy-cases`` text -> group names; "all" = every group."""
    items = [t.strip().lower() for t in text.split(",") if t.strip()]
    if "all" in items:
        return list(ACCURACY_GROUPS)
    bad = [t for t in items if t not in ACCURACY_GROUPS]
    if bad or not items:
        raise SystemExit(f"--accuracy-cases: unknown group {bad[0] if bad else text!r}; choose "
                         f"from all, {', '.join(ACCURACY_GROUPS)}")
    return [g for g in ACCURACY_GROUPS if g in items]


def parse_switches(items):
    """``--option NAME=VALUE`` items -> meshcurv switches (values read as Python literals
    where they are, e.g. False, 0.5, (0, 0, 100); else as text)."""
    import ast

    import meshcurv

    # radius: every meshcurv run's radius instead of the case's (e.g. radius=auto)
    fields = set(meshcurv.Options.__dataclass_fields__) | {"radius"}
    switches = {}
    for item in items or ():
        name, sep, value = item.partition("=")
        if not sep or name.strip() not in fields:
            raise SystemExit(f"--option: expected NAME=VALUE with NAME one of "
                             f"{', '.join(sorted(fields))}, got {item!r}")
        try:
            switches[name.strip()] = ast.literal_eval(value.strip())
        except (ValueError, SyntaxError):
            switches[name.strip()] = value.strip()
    return switches


def run_accuracy_cases(groups, methods, size="full", switches=None, out=None, timeout=300.0,
                       cnc_dir=None, command=None):
    """Run the accuracy-case ``groups`` with ``methods``; writes ``accuracy_cases.md`` and
    ``accuracy_cases.json`` into ``out`` and returns {group: rows}."""
    switches = switches or {}
    t0 = time.perf_counter()
    warm_up()
    results = {}
    for group in groups:
        results[group] = GROUP_RUNNERS[group](methods, size, switches, timeout, cnc_dir=cnc_dir)
    os.makedirs(out, exist_ok=True)
    with open(os.path.join(out, "accuracy_cases.json"), "w") as fh:
        json.dump(results, fh, indent=1, default=float)
    path = os.path.join(out, "accuracy_cases.md")
    write_accuracy_report(path, results, command or "python scripts/compare_meshlab.py",
                          time.perf_counter() - t0, switches)
    print("wrote", path)
    return results


# ---------------------------------------------------------------------------------------------
# Pictures
# ---------------------------------------------------------------------------------------------

def _view(ax, v, f, values, title, vmin=-1.0, vmax=1.0, cmap="jet", elev=25, azim=-60):
    """Mesh rendered with flat faces coloured by the mean of their vertex values."""
    import matplotlib.pyplot as plt
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    fv = np.nanmean(values[f], axis=1)
    colors = plt.get_cmap(cmap)(np.clip((fv - vmin) / (vmax - vmin), 0, 1))
    colors[~np.isfinite(fv)] = (0.6, 0.6, 0.6, 1.0)
    # simple Lambert shading so the shape reads in a still picture
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    n /= np.linalg.norm(n, axis=1, keepdims=True) + 1e-300
    light = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    shade = 0.55 + 0.45 * np.abs(n @ light)
    colors[:, :3] *= shade[:, None]
    pc = Poly3DCollection(v[f], facecolors=colors, edgecolors="none")
    ax.add_collection3d(pc)
    lo, hi = v.min(axis=0), v.max(axis=0)
    mid, half = (lo + hi) / 2, (hi - lo).max() / 2
    ax.set_xlim(mid[0] - half, mid[0] + half)
    ax.set_ylim(mid[1] - half, mid[1] + half)
    ax.set_zlim(mid[2] - half, mid[2] + half)
    ax.view_init(elev=elev, azim=azim)
    ax.set_box_aspect((1, 1, 1), zoom=1.35)
    ax.set_axis_off()
    ax.set_title(title, fontsize=9, y=0.95)


def save_png(fig, path, dpi=90):
    """Save a figure as a 256-colour PNG (the shaded meshes stay well under 300 kB)."""
    import io

    from PIL import Image

    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    buf.seek(0)
    Image.open(buf).convert("RGB").quantize(256).save(path, optimize=True)


def shape_index_picture(path, v, f, panels, suptitle, y_up=False, **view):
    """Side-by-side shape-index pictures; ``panels`` is a list of (title, k1, k2).

    ``y_up``: the mesh is stored with y up (scans, the pymeshlab samples); it is turned so that
    y points up in the picture.
    """
    if y_up:
        v = np.column_stack([v[:, 0], -v[:, 2], v[:, 1]])
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from meshcurv.shape import shape_index

    fig = plt.figure(figsize=(3.0 * len(panels), 3.2))
    for i, (title, k1, k2) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), i + 1, projection="3d")
        with np.errstate(invalid="ignore"):
            _view(ax, v, f, shape_index(k1, k2), title, **view)
    fig.suptitle(suptitle + "\nshape index: blue -1 cup, green 0 saddle, red +1 cap; "
                 "grey: no estimate", fontsize=9)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.86, wspace=0)
    save_png(fig, path)
    plt.close(fig)


def error_vs_noise_plot(path, rows):
    """Mean (|dk1| + |dk2|) / 2 against noise, one panel per surface and sampling."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = sorted({(r["surface"], r["sampling"]) for r in rows})
    fig, axes = plt.subplots(1, len(groups), figsize=(3.6 * len(groups), 3.4), squeeze=False)
    for ax, (surf, samp) in zip(axes[0], groups):
        for method in COMPARED:
            pts = sorted((r["noise"] * 100, 0.5 * (r["mean_dk1"] + r["mean_dk2"])) for r in rows
                         if (r["surface"], r["sampling"], r["method"]) == (surf, samp, method))
            if pts:
                x, y = zip(*pts)
                ax.plot(x, y, "o-", label=method, lw=2 if method == "meshcurv" else 1)
        ax.set_yscale("log")
        ax.set_xlabel("noise, % of bbox diagonal")
        ax.set_title(f"{surf} ({samp})", fontsize=9)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("mean (|dk1| + |dk2|) / 2")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    save_png(fig, path, dpi=80)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------------------------

def _fmt(x, digits=4):
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "-"
    return f"{x:.{digits}f}" if abs(x) < 1000 else f"{x:.3g}"


def _pct(x):
    return "-" if not np.isfinite(x) else f"{x * 100:.1f} %"


def table(rows):
    """Markdown table of ground-truth error rows."""
    head = ("| surface | noise | method | radius | mean\\|Δk1\\| | max\\|Δk1\\| | mean\\|Δk2\\| "
            "| max\\|Δk2\\| | rel. error | failed | time s | status |")
    out = [head, "|" + "---|" * 12]
    for r in rows:
        out.append(f"| {r['surface']} ({r['sampling']}) | {r['noise'] * 100:.1f} % | {r['method']} "
                   f"| {_fmt(r['radius'], 3)} | {_fmt(r['mean_dk1'])} | {_fmt(r['max_dk1'], 3)} "
                   f"| {_fmt(r['mean_dk2'])} | {_fmt(r['max_dk2'], 3)} | {_fmt(r['rel'], 3)} "
                   f"| {r['failed'] * 100:.1f} % | {_fmt(r['seconds'], 2)} | {r['status']} |")
    return "\n".join(out)


def win_summary(rows):
    """Per case: meshcurv's mean error over the best MeshLab ball method and over Taubin."""
    out = ["| surface | noise | meshcurv | best of SDQF/APSS | ratio | Taubin | Taubin / meshcurv |",
           "|---|---|---|---|---|---|---|"]
    keys = sorted({(r["surface"], r["sampling"], r["noise"]) for r in rows})
    for key in keys:
        by = {r["method"]: r for r in rows if (r["surface"], r["sampling"], r["noise"]) == key}
        if "meshcurv" not in by:
            continue

        def err(m):
            r = by.get(m)
            return np.nan if r is None else 0.5 * (r["mean_dk1"] + r["mean_dk2"])

        ours = err("meshcurv")
        best = np.nanmin([err("SDQF"), err("APSS")]) if any(
            np.isfinite([err("SDQF"), err("APSS")])) else np.nan
        tau = err("Taubin")
        out.append(f"| {key[0]} ({key[1]}) | {key[2] * 100:.1f} % | {_fmt(ours)} | {_fmt(best)} "
                   f"| {_fmt(ours / best, 2)} | {_fmt(tau)} | {_fmt(tau / ours, 1)} |")
    return "\n".join(out)


def settings_table(rows):
    """Markdown table: one row per case, one column per meshcurv setting; best value in bold."""
    names = list(dict.fromkeys(r["setting"] for r in rows))
    keys = list(dict.fromkeys((r["surface"], r["sampling"], r["noise"]) for r in rows))
    out = ["| surface | noise | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for key in keys:
        by = {r["setting"]: r["error"] for r in rows
              if (r["surface"], r["sampling"], r["noise"]) == key}
        best = np.nanmin([by[n] for n in names])
        cells = [f"**{_fmt(by[n])}**" if by[n] == best else _fmt(by[n]) for n in names]
        out.append(f"| {key[0]} ({key[1]}) | {key[2] * 100:.1f} % | " + " | ".join(cells) + " |")
    return "\n".join(out)


def settings_winners(rows):
    """Per noise level: each setting's error relative to the defaults, averaged (geometric
    mean over the cases); < 1 means better than the defaults."""
    names = list(dict.fromkeys(r["setting"] for r in rows))
    ref = names[0]
    out = ["| noise | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]
    for noise in sorted({r["noise"] for r in rows}):
        cells = []
        for n in names:
            ratios = []
            for key in {(r["surface"], r["sampling"]) for r in rows if r["noise"] == noise}:
                by = {r["setting"]: r["error"] for r in rows
                      if (r["surface"], r["sampling"], r["noise"]) == (*key, noise)}
                ratios.append(by[n] / by[ref])
            cells.append(_fmt(float(np.exp(np.mean(np.log(ratios)))), 2))
        best = min((c for c in cells if c != "-"), key=float)
        cells = [f"**{c}**" if c == best else c for c in cells]
        out.append(f"| {noise * 100:.1f} % | " + " | ".join(cells) + " |")
    return "\n".join(out)


def radius_table(rows):
    """Markdown table of the radius study (mean (|dk1| + |dk2|) / 2)."""
    head = " | ".join(f"{f:g} R" for f in RADIUS_FACTORS)
    out = [f"| surface | noise | R | {head} | auto | auto radius |",
           "|---|---|---|" + "---|" * (len(RADIUS_FACTORS) + 2)]
    for r in rows:
        vals = [r[f] for f in RADIUS_FACTORS] + [r["auto"]]
        best = np.nanmin(vals)
        cells = [f"**{_fmt(x)}**" if x == best else _fmt(x) for x in vals]
        out.append(f"| {r['surface']} ({r['sampling']}) | {r['noise'] * 100:.1f} % "
                   f"| {_fmt(r['radius'], 3)} | " + " | ".join(cells)
                   + f" | {_fmt(r['auto_radius'], 3)} |")
    return "\n".join(out)


def losses(rows, method="meshcurv"):
    """Markdown list of the cases where a MeshLab method beats ``method`` (mean error)."""
    out = []
    keys = list(dict.fromkeys((r["surface"], r["sampling"], r["noise"]) for r in rows))
    for key in keys:
        by = {r["method"]: 0.5 * (r["mean_dk1"] + r["mean_dk2"]) for r in rows
              if (r["surface"], r["sampling"], r["noise"]) == key}
        if method not in by:
            continue
        better = sorted((e, m) for m, e in by.items()
                        if m in MESHLAB_METHODS and np.isfinite(e) and e < by[method])
        if better:
            out.append(f"- {key[0]} ({key[1]}), noise {key[2] * 100:.1f} %: {method} "
                       f"{_fmt(by[method])}; better: " + ", ".join(
                           f"{m} {_fmt(e)} ({by[method] / e:.1f}x)" for e, m in better))
    return "\n".join(out) if out else f"- none: {method} has the smallest mean error in every case."


def write_report(path, mode, rows, real, pictures, seconds, study=(), radii=()):
    clean = [r for r in rows if r["noise"] == 0]
    noisy = [r for r in rows if r["noise"] > 0]
    lines = [
        "# meshcurv vs MeshLab curvature filters",
        "",
        f"Generated by `python scripts/compare_meshlab.py{'' if mode == 'full' else ' --' + mode}` "
        f"in {seconds:.0f} s (configuration: {mode}). Sign convention of every column: outward "
        "normal, convex positive, k1 >= k2 (see the script's docstring for what each MeshLab "
        "method needed).",
        "",
        "Methods: **meshcurv** = `principal_curvatures(vertices, faces, radius)` with the "
        "library's defaults at the time of the run (" + current_defaults() + "); "
        "**meshcurv (equal weights)** = the same with `weighting='none'`; "
        "**meshcurv (auto R)** = the defaults with the radius from "
        "`meshcurv.autoradius.auto_radius` (its own "
        "radius, in the radius column). MeshLab: **Taubin** approximation (1-ring), **QF** "
        "Quadric Fitting (2-ring), **SDQF** Scale Dependent Quadric Fitting "
        "(`scale=PureValue(radius)`), **APSS** on the point set with MeshLab's vertex normals "
        "(`filterscale` matched to the radius). All ball methods share the radius of the row.",
        "",
        "Errors are over the vertices at least one radius from an open border; `rel. error` = "
        "mean(|Δk1| + |Δk2|) / mean(|k1| + |k2|); `failed` = share of those vertices without an "
        "estimate (NaN); time = one filter call (MeshLab needs two, one per curvature), "
        "meshcurv after JIT warm-up; noise = Gaussian along the normal, sigma as % of the "
        "bounding-box diagonal.",
        "",
        "## Where meshcurv wins and loses",
        "",
        "Mean (|Δk1| + |Δk2|) / 2 per case; ratio < 1: meshcurv better than the best of SDQF "
        "and APSS at the same radius.",
        "",
        win_summary(rows),
        "",
        "Cases where a MeshLab filter has a smaller mean error than meshcurv (defaults):",
        "",
        losses(rows),
        "",
        "The same for meshcurv with equal weights:",
        "",
        losses(rows, "meshcurv (equal weights)"),
        "",
        "## Clean surfaces",
        "",
        table(clean),
        "",
        "## Noisy surfaces",
        "",
        table(noisy),
        "",
        "![error vs noise](compare_error_vs_noise.png)",
        "",
    ]
    if study:
        lines += ["## meshcurv options under noise", "",
                  "Mean (|Δk1| + |Δk2|) / 2 of meshcurv with one option changed at a time, same "
                  "radius and vertices as above (`weighting`: \"none\" = equal weights, "
                  "\"distance\" = (1 - r²/R²)⁴; normals from a PCA plane fit over the ball or "
                  "from the faces). Best per row in bold.", "",
                  settings_table(study), "",
                  "Error relative to the defaults (first column), geometric mean "
                  "over the surfaces of each noise level; < 1 is better:", "",
                  settings_winners(study), ""]
    if radii:
        lines += ["## Fixed radii and `radius=\"auto\"`", "",
                  "meshcurv defaults at multiples of the shared radius R of each "
                  "case and at the radius of `meshcurv.autoradius.auto_radius` (chosen from the "
                  "sampling density and a noise estimate, without the ground truth). Mean "
                  "(|Δk1| + |Δk2|) / 2 on the same vertices; best per row in bold.", "",
                  radius_table(radii), ""]
    if real:
        lines += ["## Sample meshes shipped with pymeshlab (no ground truth)", "",
                  "Agreement with meshcurv; curvature differences in units of meshcurv's median "
                  "curvedness c; ρ(H) = Spearman correlation of the mean curvature; sign(H) = share "
                  "of vertices where convex/concave agrees. Radius from `auto_radius` for every "
                  "ball method.", ""]
        for rr in real:
            lines += [f"### {rr['name']} ({rr['n']} vertices, {rr['faces']} faces, radius "
                      f"{rr['radius']:.4g}, c = {rr['scale']:.4g})", "",
                      "| method | median\\|Δk1\\|/c | median\\|Δk2\\|/c | ρ(H) | sign(H) agrees "
                      "| covered | time s | status |", "|---|---|---|---|---|---|---|---|"]
            for a in rr["rows"]:
                m = a["method"]
                lines.append(f"| {m} | {_fmt(a['dk1'], 3)} | {_fmt(a['dk2'], 3)} "
                             f"| {_fmt(a['rho_h'], 3)} | {_pct(a['sign_h'])} "
                             f"| {_pct(a['covered'])} | {_fmt(rr['times'][m], 2)} "
                             f"| {rr['status'][m]} |")
            lines += [f"| meshcurv | - | - | - | - | - | {_fmt(rr['times']['meshcurv'], 2)} | ok |", ""]
    if pictures:
        lines += ["## Pictures", ""] + [f"![{p}]({p})" for p in pictures] + [""]
    with open(path, "w") as fh:
        fh.write("\n".join(lines))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    g = ap.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="smaller meshes, under 2 minutes")
    g.add_argument("--smallest", action="store_true", help="one sphere, two noise levels (tests)")
    ap.add_argument("--out", default=None,
                    help="output folder (default: docs/ for the full run, a folder in the "
                         "system's temporary directory for --quick and --smallest)")
    ap.add_argument("--timeout", type=float, default=None, help="seconds per MeshLab call")
    ap.add_argument("--no-pictures", action="store_true")
    ap.add_argument("--accuracy-cases", metavar="GROUPS", default=None,
                    help="run the accuracy cases instead of the comparison: 'all' or a comma "
                         f"list of {', '.join(ACCURACY_GROUPS)}; writes accuracy_cases.md "
                         "(docs/ for 'all' at full size with the default methods and "
                         "options, else a temporary folder, or --out)")
    ap.add_argument("--methods", default="meshcurv,meshlab",
                    help="with --accuracy-cases: comma list of meshcurv, meshlab (= Taubin, "
                         "QF, SDQF, APSS) or single MeshLab methods (default: %(default)s)")
    ap.add_argument("--option", action="append", metavar="NAME=VALUE",
                    help="with --accuracy-cases: a meshcurv.Options switch for every meshcurv "
                         "run (repeatable), e.g. --option weighting=none; radius=VALUE "
                         "replaces every meshcurv run's radius (e.g. --option radius=auto)")
    ap.add_argument("--cnc-dir", default=None,
                    help="folder of the CNC benchmark clouds (default: $MESHCURV_CNC_DIR or "
                         "shared/bench/cnc beside the repository or a parent folder)")
    args = ap.parse_args(argv)
    mode = "quick" if args.quick else "smallest" if args.smallest else "full"
    timeout = args.timeout or {"smallest": 60, "quick": 60, "full": 300}[mode]
    if args.accuracy_cases is not None:
        if args.quick:
            ap.error("--quick has no accuracy-case sizes; use --smallest or neither")
        groups, methods = parse_groups(args.accuracy_cases), parse_methods(args.methods)
        switches = parse_switches(args.option)
        if args.out is None:
            reference = (groups == list(ACCURACY_GROUPS) and mode == "full" and not switches
                         and args.methods == ap.get_default("methods"))
            args.out = (os.path.join(ROOT, "docs") if reference else
                        os.path.join(tempfile.gettempdir(), "meshcurv_accuracy_cases"))
        command = "python scripts/compare_meshlab.py " + " ".join(
            a for a in (argv if argv is not None else sys.argv[1:]))
        return run_accuracy_cases(groups, methods, "smallest" if args.smallest else "full",
                                  switches, args.out, timeout, args.cnc_dir, command.strip())
    if args.out is None:
        args.out = (os.path.join(ROOT, "docs") if mode == "full" else
                    os.path.join(tempfile.gettempdir(), f"meshcurv_comparison_{mode}"))
    os.makedirs(args.out, exist_ok=True)
    t0 = time.perf_counter()
    warm_up()

    noise = (0.0, 0.003) if mode == "smallest" else NOISE_LEVELS
    methods = COMPARED if mode != "smallest" else ["meshcurv", "meshcurv (equal weights)", "Taubin",
                                                   "QF", "SDQF", "APSS"]
    rows, pictures = [], []
    for case in build_cases(mode, noise):
        r, fields = run_case(case, methods, timeout)
        rows += r
        print(f"{case.label:24s} noise {case.noise * 100:.1f} %: " + ", ".join(
            f"{x['method']} {0.5 * (x['mean_dk1'] + x['mean_dk2']):.4f}" for x in r), flush=True)
        pic = (mode != "smallest" and not args.no_pictures and case.sampling == "random"
               and case.surface == "paraboloid" and case.noise == 0.001) or (
            mode != "smallest" and not args.no_pictures and case.surface == "torus"
            and case.noise == 0.001)
        if pic:
            name = f"compare_si_{case.surface}_{case.sampling}.png"
            m = case.mesh
            shape_index_picture(os.path.join(args.out, name), m.vertices, m.faces,
                                [("meshcurv", *fields["meshcurv"]), ("MeshLab Taubin", *fields["Taubin"]),
                                 ("MeshLab SDQF", *fields["SDQF"]), ("truth", m.k1, m.k2)],
                                f"{case.label}, noise {case.noise * 100:.1f} %",
                                elev=50 if case.surface == "torus" else 35)
            pictures.append(name)
    study, radii = [], []
    if mode == "full":
        cases = build_cases(mode)
        study = settings_study(cases)
        radii = radius_study(cases)
        print("settings and radius studies done", flush=True)
    elif mode == "quick":
        # the weighting and normal options only, on the noisy cases (time budget)
        cases = [c for c in build_cases(mode) if c.noise == 0.003]
        study = settings_study(cases, list(SETTINGS_STUDY)[:6])
    with open(os.path.join(args.out, f"comparison_{mode}.json"), "w") as fh:
        json.dump(dict(rows=rows, settings_study=study,
                       radius_study=[{str(k): v for k, v in r.items()} for r in radii]),
                  fh, indent=1)
    if not args.no_pictures and mode != "smallest":
        error_vs_noise_plot(os.path.join(args.out, "compare_error_vs_noise.png"), rows)

    real = []
    for fname in SAMPLE_MESHES[mode]:
        path = os.path.join(sample_mesh_dir(), fname)
        if not os.path.exists(path):
            continue
        rr = run_real(os.path.basename(fname), path, timeout)
        real.append(rr)
        print(f"{rr['name']}: " + ", ".join(f"{a['method']} rho(H) {a['rho_h']:.3f}" for a in rr["rows"]),
              flush=True)
        if not args.no_pictures:
            name = f"compare_si_{os.path.splitext(os.path.basename(fname))[0]}.png"
            v, f = rr["vertices"], rr["faces_array"]
            shape_index_picture(os.path.join(args.out, name), v, f,
                                [(m, *rr["fields"][m]) for m in ["meshcurv", "Taubin", "SDQF", "APSS"]],
                                rr["name"], **_camera(fname))
            pictures.append(name)
    report = "comparison.md" if mode == "full" else f"comparison_{mode}.md"
    write_report(os.path.join(args.out, report), mode, rows, real, pictures,
                 time.perf_counter() - t0, study, radii)
    print("wrote", os.path.join(args.out, report))
    return rows, real


def _camera(fname):
    """Views that show the sample meshes' fronts (they are stored y-up)."""
    if "bunny" in fname:
        return dict(y_up=True, elev=10, azim=-70)
    return dict(y_up=True, elev=10, azim=-90)


if __name__ == "__main__" and len(sys.argv) == 4 and sys.argv[1] == "--worker":
    _worker(sys.argv[2], sys.argv[3])
    sys.exit(0)

if __name__ == "__main__":
    main()
