"""The tile grid of a tiled run: square x, y tiles with a halo, their names, the default size."""

from dataclasses import dataclass

import numpy as np

__all__ = ["TileGrid", "tile_name", "default_tile_size"]

_HALO_MARGIN = 1e-6


@dataclass(frozen=True)
class TileGrid:
    """Square tiles of side ``tile_size`` in x, y starting at ``origin``; halo in model units.

    Tile ``(ix, iy)`` owns the points with ``floor((x - ox) / tile_size) == ix`` (same for y) and
    sees every point whose x, y lie within ``halo`` of its square.
    """

    origin: tuple
    tile_size: float
    halo: float

    @classmethod
    def for_radius(cls, origin, tile_size, radius, reach=1):
        """Grid whose halo covers ``reach`` radii with a margin against rounding (see
        :func:`meshcurv.tiled.run._halo_reach`).

        Raises ValueError for tiles narrower than the radius: their work would be mostly halo,
        and every point would belong to many tiles.
        """
        if not tile_size >= radius:
            raise ValueError(f"tile_size ({tile_size}) must be at least the radius ({radius})")
        # the absolute term covers the rounding of (x - origin) / tile_size, ~1e-16 tile sizes
        halo = reach * radius * (1 + _HALO_MARGIN) + 1e-9 * tile_size
        return cls(origin=(float(origin[0]), float(origin[1])), tile_size=float(tile_size),
                   halo=float(halo))

    def own_keys(self, xyz):
        """(k, 2) int64 tile index of each point's own tile; ``xyz`` is (k, 3) float64."""
        o = np.asarray(self.origin, dtype=np.float64)
        return np.floor((xyz[:, :2] - o) / self.tile_size).astype(np.int64)

    def memberships(self, xyz):
        """All (point, tile) pairs of tile + halo membership of the finite points ``xyz``.

        Returns
        -------
        point : (p,) int64 row into ``xyz``; keys : (p, 2) int64 tiles; own : (p,) bool
        """
        o = np.asarray(self.origin, dtype=np.float64)
        lo = np.floor((xyz[:, :2] - self.halo - o) / self.tile_size).astype(np.int64)
        hi = np.floor((xyz[:, :2] + self.halo - o) / self.tile_size).astype(np.int64)
        own = self.own_keys(xyz)
        lo = np.minimum(lo, own)
        hi = np.maximum(hi, own)
        span = int((hi - lo).max(initial=0)) + 1
        pts, keys = [], []
        for dx in range(span):
            for dy in range(span):
                k = lo + (dx, dy)
                ok = np.flatnonzero((k <= hi).all(axis=1))
                pts.append(ok)
                keys.append(k[ok])
        point = np.concatenate(pts)
        keys = np.concatenate(keys)
        return point, keys, (keys == own[point]).all(axis=1)

    def tile_square(self, name):
        """Lower x, y corner (2,) of the tile called ``name`` ("t_IX_IY")."""
        key = np.array(name.split("_")[1:], dtype=np.int64)
        return np.asarray(self.origin, dtype=np.float64) + key * self.tile_size


def tile_name(key):
    return f"t_{int(key[0])}_{int(key[1])}"


def default_tile_size(n_points, extent, radius, target=1_000_000):
    """Side (model units) of square tiles holding about ``target`` points of a uniform cloud,
    and at least 4 radii (a cloud flat in x or y counts as one radius wide)."""
    area = max(float(extent[0]), radius) * max(float(extent[1]), radius)
    return max(float(np.sqrt(area * target / max(n_points, 1))), 4.0 * radius)

