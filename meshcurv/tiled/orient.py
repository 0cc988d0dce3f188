"""Normal orientation across the tiles of an ``orientation="mst"`` run: one flip per tile so that
adjacent tiles agree in their overlaps, and one global sign per connected group of tiles by the
rule a whole cloud's pieces follow (:func:`meshcurv.normals.orient.piece_signs`: closed groups
outward, open ones towards +z)."""

import os

import numpy as np

from ..normals.orient import orientation_note, piece_signs
from .grid import tile_name
from .work import read_json

__all__ = ["tile_flips"]


def tile_flips(work, names, note=False):
    """+1/-1 per tile so that tiles agree in their overlaps and each group takes the sign
    :func:`meshcurv.normals.orient.piece_signs` gives it.

    ``work``: the work folder (``normals/<tile>.npz|.json`` of every tile in ``names``).
    Reads the overlap data of one tile and its neighbors' border bands at a time, so the
    driver's memory is bounded by a few tiles' borders. With ``note``, also returns
    :func:`meshcurv.normals.orient.orientation_note` of the groups' rules.
    """
    if not names:
        return ({}, orientation_note([], [])) if note else {}
    votes = _overlap_votes(work, names)
    flips, n_comp, labels = _agreeing_flips(votes)
    text = _sign_groups(work, names, flips, n_comp, labels)
    flips = {nm: int(f) for nm, f in zip(names, flips)}
    return (flips, text) if note else flips


def _overlap_votes(work, names):
    """(n, n) symmetric CSR matrix of ``sum(n_A . n_B)`` over the points tiles A and B share
    (A's halo, B's border band); 0 where tiles share no point."""
    from scipy.sparse import coo_matrix

    pos = {n: i for i, n in enumerate(names)}

    def npz(name, *keys):
        with np.load(os.path.join(work, "normals", f"{name}.npz")) as z:
            return [z[k] for k in keys]

    rows, cols, votes = [], [], []
    for a in names:
        h_idx, h_nv, owner = npz(a, "halo_idx", "halo_normals", "halo_owner")
        for key in np.unique(owner, axis=0):
            b = tile_name(key)
            if b not in pos:
                continue
            sel = (owner == key).all(axis=1)
            b_idx, b_nv = npz(b, "band_idx", "band_normals")
            _, ia, ib = np.intersect1d(h_idx[sel], b_idx, assume_unique=True, return_indices=True)
            vote = float(np.nansum(np.einsum("ij,ij->i", h_nv[sel][ia], b_nv[ib])))
            if vote != 0.0:
                rows.append(pos[a])
                cols.append(pos[b])
                votes.append(vote)
    n = len(names)
    vote_m = coo_matrix((np.asarray(votes, dtype=np.float64), (rows, cols)), shape=(n, n)).tocsr()
    return vote_m + vote_m.T


def _agreeing_flips(vote_m):
    """Flips (n,) +1/-1 propagated along a maximum spanning tree of ``|votes|`` from the first
    tile of each group; also the number of groups and each tile's group label (n,)."""
    from scipy.sparse.csgraph import (breadth_first_order, connected_components,
                                      minimum_spanning_tree)

    n = vote_m.shape[0]
    # the spanning tree keeps the strongest agreements or disagreements (smallest 1 / |vote|)
    strength = vote_m.copy()
    strength.data = 1.0 / (np.abs(strength.data) + 1e-12)
    tree = minimum_spanning_tree(strength)
    tree = tree + tree.T
    n_comp, labels = connected_components(tree, directed=False)
    flips = np.ones(n)
    done = np.zeros(n, dtype=bool)
    for root in range(n):
        if done[root]:
            continue
        order, pred = breadth_first_order(tree, root, directed=False, return_predecessors=True)
        for i in order:
            if pred[i] >= 0:
                flips[i] = flips[pred[i]] * np.sign(vote_m[i, pred[i]])
            done[i] = True
    return flips, n_comp, labels


def _sign_groups(work, names, flips, n_comp, labels):
    """Flip (in place) each group of tiles as :func:`meshcurv.normals.orient.piece_signs`
    decides from the group's area-weighted sums (area, sum of n, sum of (p - centroid) . n),
    gathered from each tile's partial sums; returns the note of the rules taken."""
    st = np.array([read_json(os.path.join(work, "normals", f"{nm}.json"))["orient"]
                   for nm in names], dtype=np.float64).reshape(len(names), 9)
    area, count = np.zeros(n_comp), np.zeros(n_comp)
    normal_sum, score = np.zeros((n_comp, 3)), np.zeros(n_comp)
    for c in range(n_comp):
        g = labels == c
        area[c], count[c] = st[g, 7].sum(), st[g, 8].sum()
        if area[c] == 0:
            continue
        centroid = st[g, 4:7].sum(axis=0) / area[c]
        normal_sum[c] = flips[g] @ st[g, 1:4]
        score[c] = np.sum(flips[g] * (st[g, 0] - st[g, 1:4] @ centroid))
    sign, rule = piece_signs(area, normal_sum, score)
    flips *= sign[labels]
    return orientation_note(rule, count)
