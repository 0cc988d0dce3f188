"""meshcurv.filters.attributes: custom vertex attributes are created, and refilled exactly (double
precision) when they exist, without touching the mesh's vertices."""

import numpy as np
import pytest

pymeshlab = pytest.importorskip("pymeshlab")

from meshcurv.filters.attributes import has_attribute, store_point, store_scalar  # noqa: E402


@pytest.fixture
def ms():
    rng = np.random.default_rng(2)
    out = pymeshlab.MeshSet()
    out.add_mesh(pymeshlab.Mesh(vertex_matrix=rng.normal(size=(50, 3))), "cloud")
    return out


def test_a_stored_scalar_reads_back_bit_for_bit_also_when_it_is_refilled(ms):
    mesh = ms.current_mesh()
    assert not has_attribute(mesh.vertex_custom_scalar_attribute_array, "k1")
    first, second = np.linspace(-1, 1, 50) / 3.0, np.full(50, np.pi) * 1e-7
    store_scalar(ms, "k1", first)
    assert has_attribute(ms.current_mesh().vertex_custom_scalar_attribute_array, "k1")
    np.testing.assert_array_equal(ms.current_mesh().vertex_custom_scalar_attribute_array("k1"),
                                  first)
    store_scalar(ms, "k1", second)
    np.testing.assert_array_equal(ms.current_mesh().vertex_custom_scalar_attribute_array("k1"),
                                  second)


def test_a_stored_point_attribute_reads_back_bit_for_bit_also_when_it_is_refilled(ms):
    vertices = ms.current_mesh().vertex_matrix().copy()
    rng = np.random.default_rng(3)
    for values in (rng.normal(size=(50, 3)), rng.normal(size=(50, 3)) / 7.0):
        store_point(ms, "d1", values)
        np.testing.assert_array_equal(
            ms.current_mesh().vertex_custom_point_attribute_matrix("d1"), values)
    np.testing.assert_array_equal(ms.current_mesh().vertex_matrix(), vertices)
