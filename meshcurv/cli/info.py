"""``meshcurv info``: the geometry of a file and, for an annotated one, its curvature statistics."""

import numpy as np

from .. import io, shape
from ..result import Status

__all__ = ["info_text"]


def info_text(path):
    """Text summary of a file: geometry and, for annotated files, curvature statistics."""
    data = io.read(path)
    n = len(data.vertices)
    kind = "point cloud" if data.is_point_cloud else f"mesh, {len(data.faces)} faces"
    lines = [f"{path}: {n} vertices ({kind}), bounding-box diagonal "
             f"{io.bbox_diagonal(data.vertices):.6g}"]
    if "k1" not in data.fields or "k2" not in data.fields:
        lines.append("not annotated (no k1, k2 vertex properties); "
                     f"run: meshcurv annotate {path} -o OUT.ply")
        return "\n".join(lines)
    valid = (np.asarray(data.fields["valid"]).astype(bool) if "valid" in data.fields
             else np.isfinite(data.fields["k1"]))
    lines.append(f"valid: {int(valid.sum())} of {n} ({100.0 * valid.mean():.1f} %)")
    if "status" in data.fields and not valid.all():
        lines.append("no estimate: " + _status_counts(data.fields["status"]))
    header = f"{'field':<12}{'min':>12}{'p2':>12}{'median':>12}{'p98':>12}{'max':>12}{'mean':>12}"
    lines.append(header)
    for name in shape.FIELDS:
        if name not in data.fields:
            continue
        x = np.asarray(data.fields[name], dtype=np.float64)[valid]
        x = x[np.isfinite(x)]
        if x.size == 0:
            lines.append(f"{name:<12}{'(no valid values)':>24}")
            continue
        stats = [x.min(), *np.percentile(x, [2, 50, 98]), x.max(), x.mean()]
        lines.append(f"{name:<12}" + "".join(f"{s:>12.5g}" for s in stats))
    if "n_neighbors" in data.fields:
        nb = np.asarray(data.fields["n_neighbors"])[valid]
        if nb.size:
            lines.append(f"neighbors per vertex: median {np.median(nb):.0f}, "
                         f"min {nb.min()}, max {nb.max()}")
    return "\n".join(lines)



def _status_counts(status):
    """``"12 TOO_FEW_HALF_SETS, 3 NO_POSITION"``: the rows without an estimate by reason, most
    frequent first (codes this version does not know are counted as ``status N``)."""
    codes, counts = np.unique(np.asarray(status, dtype=np.int64), return_counts=True)
    known = {int(s): s.name for s in Status}
    parts = [(c, known.get(int(k), f"status {int(k)}")) for k, c in zip(codes, counts)
             if int(k) != Status.OK]
    return ", ".join(f"{c} {name}" for c, name in sorted(parts, key=lambda p: -p[0]))
