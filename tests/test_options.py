"""The one table of estimator options: it names exactly the keyword options of
principal_curvatures, and every adapter refuses a bad value with the same one-line message."""

import inspect

import numpy as np
import pytest

import meshcurv
from meshcurv import options


def test_option_table_names_every_keyword_option_of_principal_curvatures():
    params = inspect.signature(meshcurv.principal_curvatures).parameters
    keyword = set(params) - {"vertices", "faces", "normals", "query", "progress"}
    assert set(options.OPTION_NAMES) == keyword


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
    if name in options.OPTION_NAMES:  # the API refuses it too, before looking at the data
        with pytest.raises(ValueError, match="must be"):
            meshcurv.principal_curvatures(np.zeros((0, 3)), **{name: bad})


def test_check_options_returns_the_orientation():
    assert options.check_options() == "mst"
    np.testing.assert_array_equal(options.check_options(orientation=[1, 2, 3]), [1.0, 2.0, 3.0])


def test_resolve_plan_has_the_defaults_of_principal_curvatures():
    """The pilot runs of radius="auto" resolve options without the API: same defaults."""
    import inspect

    api_defaults = {k: p.default for k, p in
                    inspect.signature(meshcurv.principal_curvatures).parameters.items()
                    if k in options.OPTION_NAMES and k != "radius"}
    plan_defaults = {k: p.default for k, p in
                     inspect.signature(options.resolve_plan).parameters.items()
                     if k in options.OPTION_NAMES}
    assert plan_defaults == api_defaults
