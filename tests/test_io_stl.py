"""meshcurv.io.stl: the unshared triangle corners of an STL are merged by exact position, in
order of first appearance."""

import numpy as np

from meshcurv import io, surfaces


def test_stl_corners_are_merged_in_order_of_first_appearance(tmp_path):
    import trimesh

    sphere = surfaces.sphere(subdivisions=2)
    path = tmp_path / "s.stl"
    trimesh.Trimesh(sphere.vertices, sphere.faces, process=False).export(str(path))
    data = io.read(str(path))
    # STL is float32: compare positions at float32 precision, order of first use in faces
    first_use = np.unique(sphere.faces.ravel(), return_index=True)[1]
    order = sphere.faces.ravel()[np.sort(first_use)]
    np.testing.assert_array_equal(data.vertices, sphere.vertices[order].astype(np.float32))
    assert len(data.faces) == len(sphere.faces)
    np.testing.assert_array_equal(data.vertices[data.faces],
                                  sphere.vertices[sphere.faces].astype(np.float32))
