"""The work folder of a tiled run: its manifest, atomic npz/json files, tile pieces and results.

Layout (``OUT.meshcurv-work``): ``manifest.json`` (input and parameters: a rerun with others starts
afresh), ``chunks/cNNNNNN.json`` (tiles each input chunk touched), ``pieces/t_IX_IY/cNNNNNN.npz``
(a tile + halo's points from one chunk), ``normals/t_IX_IY.npz|.json`` (MST normals of a tile) and
``results/t_IX_IY/cNNNNNN.npz`` + ``done.json`` (a finished tile's estimates per chunk).
"""

import json
import os
import shutil

import numpy as np

from ..io import atomic_write

__all__ = ["atomic_savez", "atomic_json", "read_json", "prepare_work", "options_manifest",
           "load_tile", "result_rows", "gather", "as_result", "concat_results"]

def atomic_savez(path, **arrays):
    def write(tmp):
        with open(tmp, "wb") as fh:     # a file object: given a name, savez appends ".npz"
            np.savez(fh, **arrays)
    atomic_write(path, write)


def atomic_json(path, obj):
    def write(tmp):
        with open(tmp, "w") as fh:
            json.dump(obj, fh)
    atomic_write(path, write)


def read_json(path):
    with open(path) as fh:
        return json.load(fh)


def prepare_work(work, manifest):
    """Reuse ``work`` if it was made for the same input and parameters, else start it afresh."""
    mpath = os.path.join(work, "manifest.json")
    if os.path.exists(mpath):
        try:
            same = read_json(mpath) == json.loads(json.dumps(manifest))
        except (OSError, ValueError):
            same = False
        if not same:
            shutil.rmtree(work)
    for sub in ("pieces", "normals", "results", "chunks"):
        os.makedirs(os.path.join(work, sub), exist_ok=True)
    if not os.path.exists(mpath):
        atomic_json(mpath, manifest)


def options_manifest(radius, grid, orientation, options, chunk_size):
    return {"radius": radius, "tile_size": grid.tile_size, "halo": grid.halo,
            "origin": list(grid.origin), "chunk_size": chunk_size,
            "orientation": orientation if isinstance(orientation, str) else list(orientation),
            "options": {k: options[k] for k in sorted(options)}}


def load_tile(work, name, chunk_ids):
    """A tile + halo from its pieces, in input order.

    Returns
    -------
    idx : (m,) int64 global point index; xyz : (m, 3) float64; own : (m,) bool;
    normals : (m, 3) float64 or None (given in the input); chunk_of : (m,) int64 input chunk
    """
    folder = os.path.join(work, "pieces", name)
    parts = []
    for c in chunk_ids:
        with np.load(os.path.join(folder, f"c{c:06d}.npz")) as z:
            parts.append({k: z[k] for k in z.files})
    idx = np.concatenate([p["idx"] for p in parts])
    xyz = np.concatenate([p["xyz"] for p in parts])
    own = np.concatenate([p["own"] for p in parts])
    normals = np.concatenate([p["normals"] for p in parts]) if "normals" in parts[0] else None
    chunk_of = np.repeat(np.asarray(chunk_ids, dtype=np.int64), [len(p["idx"]) for p in parts])
    return idx, xyz, own, normals, chunk_of


def result_rows(res):
    """The per-row arrays of a CurvatureResult, ``{name: (m, ...) array}``."""
    m = len(res)
    return {k: v for k, v in vars(res).items() if isinstance(v, np.ndarray) and len(v) == m}


def gather(work, tiles, chunk_id, first, count):
    """Result arrays of points ``first .. first + count - 1`` from the tiles that own them; points
    no tile owns (non-finite coordinates) keep NaN / 0 / False and status NO_POSITION."""
    from ..result import Status

    out = {}
    for name in tiles:
        with np.load(os.path.join(work, "results", name, f"c{chunk_id:06d}.npz")) as z:
            r = {k: z[k] for k in z.files}
        rows = r.pop("idx") - first
        for k, a in r.items():
            if k not in out:
                fill = (np.nan if a.dtype.kind == "f" else
                        Status.NO_POSITION if k == "status" else 0)
                out[k] = np.full((count,) + a.shape[1:], fill, dtype=a.dtype)
            out[k][rows] = a
    if not out:  # a chunk of non-finite points only
        out = {k: np.full(count, np.nan) for k in ("k1", "k2", "residual", "noise")}
        out.update({k: np.full((count, 3), np.nan) for k in ("d1", "d2", "normals")})
        out.update(n_neighbors=np.zeros(count, np.int32), n_samples=np.zeros(count, np.int32),
                   valid=np.zeros(count, bool),
                   status=np.full(count, Status.NO_POSITION, np.int8))
    return out


def as_result(arrays, radius):
    from ..result import CurvatureResult

    return CurvatureResult(radius=float(radius), **arrays)


def concat_results(parts, radius):
    rows = [result_rows(p) for p in parts]
    if not rows:
        return as_result(gather("", [], 0, 0, 0), radius)
    return as_result({k: np.concatenate([r[k] for r in rows]) for k in rows[0]}, radius)

