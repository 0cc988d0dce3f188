"""pymeshlab filters of meshcurv: ``import meshcurv.filters`` adds them to ``pymeshlab.MeshSet``.

>>> import pymeshlab, meshcurv.filters
>>> ms = pymeshlab.MeshSet()
>>> ms.load_new_mesh("examples/torus.ply")                                    # doctest: +SKIP
>>> ms.compute_curvature_cga_per_vertex(radius=pymeshlab.PercentageValue(3))  # doctest: +SKIP
>>> meshcurv.filters.save_curvature_mesh(ms, "torus_curvature.ply")          # doctest: +SKIP

``save_curvature_mesh`` writes every field the filter computed (``ms.save_current_mesh`` writes
only quality and colour unless each attribute is asked for); ``load_curvature_mesh`` reads an
annotated PLY back with its fields as custom attributes (MeshLab's reader drops them).

The filters are Python functions, so they run like MeshLab's own (``ms.<name>(...)`` and
``ms.apply_filter("<name>", ...)``) but are not recorded by ``save_filter_script``.
"""

import pymeshlab

from .annotated import load_curvature_mesh, save_curvature_mesh
from .curvature import compute_curvature_cga_per_vertex, resolve_radius

__all__ = ["compute_curvature_cga_per_vertex", "resolve_radius", "save_curvature_mesh",
           "load_curvature_mesh", "FILTERS"]

# Filter name -> function(meshset, **parameters) -> dict
FILTERS = {"compute_curvature_cga_per_vertex": compute_curvature_cga_per_vertex}


def _install():
    """Attach the filters to MeshSet and route ``apply_filter`` for their names (idempotent)."""
    for name, fn in FILTERS.items():
        setattr(pymeshlab.MeshSet, name, fn)
    apply = pymeshlab.MeshSet.apply_filter
    if getattr(apply, "_meshcurv", False):
        return

    def apply_filter(self, filter_name, **kwargs):
        if filter_name in FILTERS:
            return FILTERS[filter_name](self, **kwargs)
        return apply(self, filter_name, **kwargs)

    apply_filter.__doc__ = apply.__doc__
    apply_filter._meshcurv = True
    pymeshlab.MeshSet.apply_filter = apply_filter


_install()
