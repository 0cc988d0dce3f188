"""The one table of estimator options: it names exactly the keyword options of
principal_curvatures, and every adapter refuses a bad value with the same one-line message."""

import dataclasses
import inspect

import numpy as np
import pytest

import meshcurv
from meshcurv import options


def test_option_table_names_the_knobs_of_principal_curvatures_and_the_fields_of_options():
    params = inspect.signature(meshcurv.principal_curvatures).parameters
    knobs = set(params) - {"vertices", "faces", "normals", "options", "query", "progress",
                           "switches"}
    fields = [f.name for f in dataclasses.fields(options.Options)]
    assert set(options.OPTION_NAMES) == knobs | set(fields)
    assert tuple(fields) == options.SWITCH_NAMES


def test_switches_by_name_and_by_options_give_the_same_result():
    sphere = meshcurv.surfaces.sphere(subdivisions=3)
    by_name = meshcurv.principal_curvatures(sphere.vertices, sphere.faces, radius=0.4,
                                            weighting="none", robust=False)
    by_object = meshcurv.principal_curvatures(
        sphere.vertices, sphere.faces, radius=0.4,
        options=meshcurv.Options(weighting="none").replace(robust=False))
    for name in ("k1", "k2", "d1", "normals", "status"):
        np.testing.assert_array_equal(getattr(by_name, name), getattr(by_object, name))
    # a switch given by name overrides the same switch of options
    mixed = meshcurv.principal_curvatures(sphere.vertices, sphere.faces, radius=0.4,
                                          options=meshcurv.Options(weighting="distance"),
                                          weighting="none", robust=False)
    np.testing.assert_array_equal(mixed.k1, by_name.k1)


def test_unknown_switches_and_wrong_options_objects_are_refused_in_one_line():
    with pytest.raises(ValueError, match="unknown estimator option: curvature"):
        meshcurv.principal_curvatures(np.zeros((0, 3)), curvature=1)
    with pytest.raises(ValueError, match="must be a meshcurv.Options, got dict"):
        meshcurv.principal_curvatures(np.zeros((0, 3)), options={"robust": False})
    with pytest.raises(ValueError, match="radius is not a switch of Options"):
        options.Options().replace(radius=1.0)


@pytest.mark.parametrize("name, bad, message", [
    ("neighborhood", "rings", "neighborhood must be one of 'auto', 'kring', 'ball'"),
    ("weighting", "gauss", "weighting must be one of"),
    ("n_directions", 2, "from 3 to 64"),
    ("n_directions", 65, "from 3 to 64"),
    ("n_directions", 4.5, "from 3 to 64"),
    ("orientation", (0, 0), "finite (3,) viewpoint"),
    ("orientation", (0, 0, np.inf), "finite (3,) viewpoint"),
    ("curvature", 1, "unknown estimator option: curvature"),
])
def test_bad_options_are_refused_in_one_line_before_any_work(name, bad, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")) as exc:
        options.check_options(**{name: bad})
    assert "\n" not in str(exc.value)
    # the API refuses it too, before looking at the data
    with pytest.raises(ValueError, match="must be|unknown"):
        meshcurv.principal_curvatures(np.zeros((0, 3)), **{name: bad})


def test_check_options_returns_the_orientation():
    assert options.check_options() == "mst"
    np.testing.assert_array_equal(options.check_options(orientation=[1, 2, 3]), [1.0, 2.0, 3.0])


def test_resolve_plan_has_the_defaults_of_principal_curvatures():
    """Plans resolved without the API (autoradius' pilot runs) have the API's defaults."""
    api = inspect.signature(meshcurv.principal_curvatures).parameters
    expected = {k: api[k].default for k in ("n_directions", "neighborhood")}
    expected.update(options.Options().as_dict())
    plan = inspect.signature(options.resolve_plan).parameters
    assert {k: p.default for k, p in plan.items() if k in options.OPTION_NAMES} == expected
