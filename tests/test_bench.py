"""Smoke test of the benchmark script: ``scripts/bench.py --quick`` runs and reports every method.

Only that it runs and produces a complete, well-formed report; timings are not asserted (they
depend on the machine and its load).
"""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

SCRIPT = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "scripts",
                      "bench.py")


@pytest.fixture(scope="module")
def quick_report(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench") / "bench.json"
    p = subprocess.run([sys.executable, SCRIPT, "--quick", "--repeat", "1", "--json", str(out)],
                       capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    return json.loads(out.read_text()), p.stdout


def test_quick_benchmark_times_meshcurv_and_meshlab_on_every_mesh(quick_report):
    report, _ = quick_report
    rows = {(r["data"], r["method"]): r for r in report["rows"]}
    meshes = {r["data"] for r in report["rows"]
              if not r["data"].startswith(("cloud", "LAZ", "batch"))}
    assert meshes == {"torus 4k", "sphere 4k", "noisy torus 4k", "torus 16k", "sphere 16k"}
    for data in meshes:
        for method in ("meshcurv", "meshcurv (est.)", "meshcurv (default radius)",
                       "MeshLab Taubin", "MeshLab SDQF"):
            row = rows[(data, method)]
            assert row["status"] == "ok" and row["seconds"] > 0
        # APSS runs in a child process and may crash; it must still leave a row
        assert (data, "MeshLab APSS") in rows
    clouds = [r for r in report["rows"] if r["data"].startswith("cloud")]
    assert {r["method"] for r in clouds} == {"meshcurv", "meshcurv (est.)",
                                             "meshcurv (default radius)"}
    # the split of one call per mode, the default radius's included
    for modes in report["stages"].values():
        assert set(modes) == {"normals given", "normals estimated", "default radius"}
        assert all(st["total"] > 0 for st in modes.values())


def test_quick_benchmark_reports_ratios_memory_and_first_call(quick_report):
    report, table = quick_report
    row = next(r for r in report["rows"] if r["method"] == "meshcurv")
    assert row["vs_taubin"] > 0 and row["vs_sdqf"] > 0 and row["vertices_per_s"] > 0
    assert np.isfinite(row["bytes_per_vertex"]) and row["bytes_per_vertex"] >= 0
    assert report["first_call"]["first_mesh_s"] > 0
    assert "| data | method |" in table and "vs SDQF" in table


def test_quick_benchmark_times_the_whole_commands(quick_report):
    report, table = quick_report
    rows = {r["method"]: r for r in report["rows"]
            if r["data"].startswith(("LAZ", "batch"))}
    assert set(rows) == {"annotate (untiled)", "annotate --tile-size (4 tiles)",
                         "batch --jobs 1", "batch --jobs 2"}
    assert all(r["seconds"] > 0 for r in rows.values())
    assert rows["batch --jobs 2"]["vs_single"] > 0 and "batch --jobs 2" in table
