"""Docstring examples of every module run, so they cannot rot (those that need files or a
cluster are marked ``# doctest: +SKIP`` where they stand)."""

import doctest
import importlib
import pkgutil

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
