"""The accuracy cases of ``scripts/compare_meshlab.py --accuracy-cases``: their exact curvature
(Goursat, torus and ellipsoid truth in :mod:`meshcurv.surfaces`), the CNC cloud reader and noise
model, and the smallest configuration of every group."""

import os
import sys

import numpy as np
import pytest
from scipy.optimize import brentq

from meshcurv import surfaces

sys.path.insert(0, os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                "scripts"))
import compare_meshlab  # noqa: E402

CNC_DIR = compare_meshlab.find_cnc_dir()
needs_cnc = pytest.mark.skipif(CNC_DIR is None, reason="CNC benchmark clouds not found")


def _height_function_curvatures(function, point, normal):
    """k1 >= k2 and the k1 direction of the level set function = 0 at ``point``, from central
    differences of its height over the tangent plane (h solved from function(q + h n) = 0):
    independent of the shape-operator formula. Convex positive: S = -Hess(h)."""
    t1 = np.cross(normal, [0.3, 0.5, 0.7])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)

    def h(u, v):
        q = point + u * t1 + v * t2
        return brentq(lambda t: function(q + t * normal), -0.5, 0.5, xtol=1e-15, rtol=1e-15)

    e = 1e-3
    huu = (h(e, 0) - 2 * h(0, 0) + h(-e, 0)) / e ** 2
    hvv = (h(0, e) - 2 * h(0, 0) + h(0, -e)) / e ** 2
    huv = (h(e, e) - h(e, -e) - h(-e, e) + h(-e, -e)) / (4 * e * e)
    k, vec = np.linalg.eigh(-np.array([[huu, huv], [huv, hvv]]))
    return k[1], k[0], vec[0, 1] * t1 + vec[1, 1] * t2


def test_goursat_truth_matches_finite_differences_of_its_implicit_function():
    rng = np.random.default_rng(3)
    p = rng.normal(size=(8, 3))
    p *= 9.0 / np.linalg.norm(p, axis=1, keepdims=True)        # near the surface (|x| ~ 8-9.7)
    s = surfaces.goursat_at(p)
    f, g, _ = surfaces.goursat_function(s.vertices)
    assert np.all(np.abs(f) < 1e-12)                           # projected onto F = 0
    assert np.all(np.einsum("ij,ij->i", s.normals, s.vertices) > 0)   # outward
    for i in range(len(p)):
        k1, k2, d1 = _height_function_curvatures(
            lambda x: surfaces.goursat_function(x)[0][0], s.vertices[i], s.normals[i])
        # central differences with step 1e-3 on curvatures ~0.1: truncation ~1e-8 (measured
        # 3e-9), rounding of h (1e-15) / step^2 ~1e-9
        assert s.k1[i] == pytest.approx(k1, abs=1e-7)
        assert s.k2[i] == pytest.approx(k2, abs=1e-7)
        assert abs(abs(d1 @ s.d1[i]) - 1) < 1e-6
        assert np.cross(s.d1[i], s.d2[i]) == pytest.approx(s.normals[i], abs=1e-12)


def test_goursat_is_umbilic_and_concave_where_it_crosses_an_axis():
    # 0.03 x^4 - 2 x^2 - 8 = 0 on the x axis; there by symmetry k1 = k2 = F_yy / |F_x|
    x = np.sqrt((2 + np.sqrt(4 + 4 * 0.03 * 8)) / (2 * 0.03))
    s = surfaces.goursat_at([[x + 0.1, 0.0, 0.0], [0.0, 0.0, -x + 0.05]])
    assert s.vertices[0] == pytest.approx([x, 0, 0], abs=1e-12)
    k = -4.0 / (0.12 * x ** 3 - 4 * x)
    assert s.k1 == pytest.approx([k, k], rel=1e-12) and s.k2 == pytest.approx([k, k], rel=1e-12)
    assert np.isnan(s.d1).all()                                # umbilic: no direction


def test_torus_truth_matches_the_generator_and_the_implicit_torus():
    exact = surfaces.torus(6.0, 2.0, 36, 18)
    rng = np.random.default_rng(1)
    noisy = exact.vertices + 0.05 * exact.normals * rng.normal(size=(len(exact.vertices), 1))
    s = surfaces.torus_at(noisy)                               # projected back along the normal
    assert s.vertices == pytest.approx(exact.vertices, abs=1e-12)
    assert s.k1 == pytest.approx(exact.k1) and s.k2 == pytest.approx(exact.k2, abs=1e-12)
    assert s.normals == pytest.approx(exact.normals, abs=1e-12)
    assert s.d1 == pytest.approx(exact.d1, abs=1e-12)
    # (|x|^2 + R^2 - r^2)^2 - 4 R^2 (x^2 + y^2): its shape operator gives the same field
    v, big, small = s.vertices, 6.0, 2.0
    q = np.sum(v ** 2, axis=1) + big ** 2 - small ** 2
    flat = np.diag([1.0, 1.0, 0.0])
    grad = 4 * q[:, None] * v - 8 * big ** 2 * v @ flat
    hess = (4 * q[:, None, None] * np.eye(3) + 8 * v[:, :, None] * v[:, None, :]
            - 8 * big ** 2 * flat)
    normals, k1, k2, d1, _ = surfaces.implicit_curvature(grad, hess)
    assert normals == pytest.approx(s.normals, abs=1e-12)
    assert k1 == pytest.approx(s.k1, abs=1e-12) and k2 == pytest.approx(s.k2, abs=1e-12)
    assert np.abs(np.einsum("ij,ij->i", d1, s.d1)) == pytest.approx(1.0, abs=1e-9)


def test_ellipsoid_truth_on_a_sphere_and_at_the_ends_of_its_axes():
    ball = surfaces.ellipsoid((1.5, 1.5, 1.5), subdivisions=2)
    assert ball.k1 == pytest.approx(np.full(len(ball.k1), 1 / 1.5), abs=1e-12)
    assert ball.k2 == pytest.approx(ball.k1, abs=1e-12)
    assert ball.normals == pytest.approx(ball.vertices / 1.5, abs=1e-12)

    a, b, c = 2.0, 1.5, 1.0
    s = surfaces.ellipsoid((a, b, c), subdivisions=2)
    assert np.sum((s.vertices / [a, b, c]) ** 2, axis=1) == pytest.approx(1.0, abs=1e-12)
    assert np.all(s.k1 >= s.k2) and np.all(s.k2 > 0)
    # at (a, 0, 0) the normal sections are ellipses of curvature a / b^2 and a / c^2
    ends = np.array([[a, 0, 0], [0, b, 0], [0, 0, c]])
    axes = np.array([a, b, c])
    normals, k1, k2, d1, _ = surfaces.implicit_curvature(
        2 * ends / axes ** 2, np.broadcast_to(np.diag(2 / axes ** 2), (3, 3, 3)))
    assert normals == pytest.approx(np.eye(3))
    assert k1 == pytest.approx([a / c ** 2, b / c ** 2, c / b ** 2])
    assert k2 == pytest.approx([a / b ** 2, b / a ** 2, c / a ** 2])
    assert np.abs(d1) == pytest.approx(np.array([[0, 0, 1], [0, 0, 1], [0, 1, 0]]), abs=1e-12)
    # and the generator agrees with finite differences of the implicit function
    for i in (5, 17, 33):
        k1_fd, k2_fd, _ = _height_function_curvatures(
            lambda x: np.sum((x / axes) ** 2) - 1, s.vertices[i], s.normals[i])
        assert (s.k1[i], s.k2[i]) == pytest.approx((k1_fd, k2_fd), abs=1e-6)


@needs_cnc
def test_cnc_reader_gives_points_on_their_surfaces_with_exact_normals():
    for name, rows in (("torus_010000", 10000), ("goursat_010000", 10000)):
        points, normals, truth = compare_meshlab.load_cnc_cloud(
            os.path.join(CNC_DIR, name + ".pts"))
        assert points.shape == normals.shape == (rows, 3)
        # the files hold 6-7 significant digits: points within ~1e-5 of the surface and
        # normals within 0.005 degrees of the outward gradient (the README)
        assert np.abs(points - truth.vertices).max() < 1e-4
        unit = normals / np.linalg.norm(normals, axis=1, keepdims=True)
        assert np.einsum("ij,ij->i", unit, truth.normals).min() > np.cos(np.radians(0.01))
    assert truth.name == "goursat"


def test_noise_model_of_the_cnc_grid():
    points = np.zeros((20000, 3))
    normals = np.tile([0.0, 0.0, 1.0], (20000, 1))
    p = compare_meshlab.noisy_positions(points, 0.1, seed=1)
    assert p.std(axis=0) == pytest.approx([0.1] * 3, rel=0.03)     # 3 / sqrt(2 * 20000) ~ 2 %
    n = compare_meshlab.noisy_normals(normals, 0.2, seed=1)
    assert np.linalg.norm(n, axis=1) == pytest.approx(1.0)
    assert n[:, 0].std() == pytest.approx(0.2 / np.sqrt(1 + 2 * 0.04), rel=0.1)
    assert compare_meshlab.noisy_positions(points, 0.0, seed=1) == pytest.approx(points)


def test_generated_clouds_have_the_described_properties():
    s = compare_meshlab.half_sphere_variable_density(4000)
    assert abs(len(s.vertices) - 4000) < 200
    assert np.linalg.norm(s.vertices, axis=1) == pytest.approx(1.0) and s.vertices[:, 2].min() >= 0
    low, high = np.sum(s.vertices[:, 0] < -0.8), np.sum(s.vertices[:, 0] > 0.8)
    assert 10 < low / high < 40                                 # 25x between the ends
    sph, spikes = compare_meshlab.sphere_with_spikes(3)
    assert spikes.sum() == round(0.02 * len(spikes))
    off = np.abs(np.linalg.norm(sph.vertices, axis=1) - 1) / sph.diagonal
    assert np.all(off[spikes] > 0.007) and np.all(off[~spikes] < 0.003)


def test_smallest_configuration_of_every_group_runs(tmp_path):
    groups = [g for g in compare_meshlab.ACCURACY_GROUPS if g != "cnc" or CNC_DIR]
    results = compare_meshlab.run_accuracy_cases(groups, ["meshcurv"], "smallest",
                                                 out=str(tmp_path), timeout=60)
    assert list(results) == groups
    for group, rows in results.items():
        assert rows, group
        for r in rows:
            assert 0.0 <= r["valid"] <= 1.0
    cyl = [r for r in results["surfaces"] if r["case"].startswith("cylinder")]
    assert len(cyl) == 1 and np.isfinite(cyl[0]["max_K_over_k1sq"])
    assert len(results["icosahedra"]) == 6                      # 3 meshes x (mesh, points)
    assert len(results["coarse"]) == 4                          # 2 tori x (mesh, points)
    # trimesh's own torus grid: the default radius stays on the tube (mean |dk| 0.377 before)
    assert all(r["valid"] == 1.0 and r["mean_dk"] < 0.05 for r in results["coarse"][:2])
    # ... and its mesh gets the MLS blend (0.0044; 0.028 with the circle fits alone)
    assert results["coarse"][0]["method"] == "meshcurv, mesh"
    assert results["coarse"][0]["mean_dk"] < 0.01
    assert {r["method"] for r in results["spikes"]} == {"meshcurv, mesh", "meshcurv, points"}
    assert len(results["decimated"]) == 4                       # 2 meshes x (mesh, points)
    assert all(r["valid"] == 1.0 and r["mean_dk"] < 0.05 for r in results["decimated"])
    assert len(results["ellipsoids"]) == 4                      # 2 meshes x (mesh, points)
    # the 642-vertex ellipsoid's ends take smaller balls: 0.059 -> 0.023 (mesh)
    assert results["ellipsoids"][0]["method"] == "meshcurv, mesh"
    assert results["ellipsoids"][0]["mean_dk"] < 0.04
    if CNC_DIR:
        modes = {(r["method"], r["radius_rule"]) for r in results["cnc"]}
        assert len(modes) == 4 and len(results["cnc"]) == 2 * 4   # files x modes
    report = (tmp_path / "accuracy_cases.md").read_text()
    for group in groups:
        assert f"`--accuracy-cases {group}`" in report
    assert (tmp_path / "accuracy_cases.json").exists()


def test_meshlab_rows_of_a_mesh_group_and_method_parsing():
    rows = compare_meshlab.group_icosahedra(["QF"], "smallest", {}, 60)
    assert [r["method"] for r in rows] == ["QF"] * 3
    assert all(r["status"] == "ok" and r["valid"] == 1.0 for r in rows)
    assert compare_meshlab.parse_methods("meshcurv,meshlab") == [
        "meshcurv", "Taubin", "QF", "SDQF", "APSS"]
    assert compare_meshlab.parse_groups("cnc, spikes") == ["cnc", "spikes"]
    assert compare_meshlab.parse_switches(["weighting=none", "robust=False"]) == dict(
        weighting="none", robust=False)
    with pytest.raises(SystemExit):
        compare_meshlab.parse_methods("libigl")
