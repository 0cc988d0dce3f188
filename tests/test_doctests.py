"""Docstring examples of every module and the README's Python example run, so they cannot rot
(docstring examples that need files or a cluster are marked ``# doctest: +SKIP`` where they
stand)."""

import doctest
import importlib
import os
import pkgutil
import re

import numpy as np

import pytest

import meshcurv


def _modules():
    names = ["meshcurv.filters"]
    for info in pkgutil.walk_packages(meshcurv.__path__, "meshcurv."):
        if info.name != "meshcurv.__main__":
            names.append(info.name)
    return sorted(names)


@pytest.mark.parametrize("name", _modules())
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE,
                             report=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} examples of {name} failed"


def test_readme_python_example_runs_on_a_sphere():
    readme = os.path.join(os.path.dirname(__file__), "..", "README.md")
    with open(readme, encoding="utf-8") as f:
        text = f.read()
    section = text[text.index("## Python"):]
    block = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    sphere = meshcurv.surfaces.sphere(sampling="random", n=3000, seed=0)
    namespace = {"vertices": sphere.vertices, "points": sphere.vertices, "radius": 0.25}
    exec(compile(block, "README.md", "exec"), namespace)
    res = namespace["res"]
    assert len(res) == len(sphere.vertices) and np.nanmedian(res.k1) == pytest.approx(1, abs=0.02)
    assert namespace["normals"].shape == (3000, 3)
