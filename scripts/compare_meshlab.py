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
    names = ("weighting", "normal_estimation", "slab", "n_directions", "robust")
    return ", ".join(f"`{n}={params[n].default!r}`" for n in names if n in params)


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
    args = ap.parse_args(argv)
    mode = "quick" if args.quick else "smallest" if args.smallest else "full"
    timeout = args.timeout or {"smallest": 60, "quick": 60, "full": 300}[mode]
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
