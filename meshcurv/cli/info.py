"""``meshcurv info``: the geometry of a file and, for an annotated one, its curvature statistics."""

import numpy as np

from .. import io, shape
from ..result import Status

__all__ = ["info_text"]


def info_text(path):
    """Text summary of a file: geometry and, for annotated files, curvature statistics (per
    radius for a file annotated at several radii, each under a line naming the radius)."""
    data = io.read(path)
    n = len(data.vertices)
    kind = "point cloud" if data.is_point_cloud else f"mesh, {len(data.faces)} faces"
    diagonal = io.bbox_diagonal(data.vertices)
    lines = [f"{path}: {n} vertices ({kind}), bounding-box diagonal {diagonal:.6g}"]
    suffixes = _radius_suffixes(data.fields)
    if not suffixes:
        lines.append("not annotated (no k1, k2 vertex properties); "
                     f"run: meshcurv annotate {path} -o OUT.ply")
        return "\n".join(lines)
    width = max(12, max(len(name + s) for name in shape.FIELDS for s in suffixes) + 1)
    for suffix in suffixes:
        if suffix:
            text = io.suffix_radius_text(suffix)
            if text.endswith("%"):  # of the diagonal of these very points
                text += f" = {float(text[:-1]) / 100.0 * diagonal:.6g}"
            lines.append(f"radius {text} (fields k1{suffix} ...):")
        lines.extend(_radius_lines(data.fields, suffix, n, width))
    return "\n".join(lines)


def _radius_suffixes(fields):
    """The radius suffixes of the annotated fields in ``fields`` (``""`` for plain ``k1``,
    ``"_r0p5"`` for ``k1_r0p5``), in file order: those with both ``k1`` and ``k2``."""
    found = [io.split_radius_suffix(name)[1] for name in fields
             if io.split_radius_suffix(name)[0] == "k1"]
    return [s for s in found if "k2" + s in fields]


def _radius_lines(fields, suffix, n, width):
    """The lines of :func:`info_text` on the fields of one radius, named ``<field><suffix>``,
    of a file with ``n`` vertices: valid count, reasons, statistics per field (names in a
    column of ``width`` characters), neighbors."""
    lines = []
    k1 = fields["k1" + suffix]
    valid = (np.asarray(fields["valid" + suffix]).astype(bool) if "valid" + suffix in fields
             else np.isfinite(k1))
    lines.append(f"valid: {int(valid.sum())} of {n} ({100.0 * valid.mean():.1f} %)")
    if "status" + suffix in fields and not valid.all():
        lines.append("no estimate: " + _status_counts(fields["status" + suffix]))
    header = f"{'field':<{width}}" + "".join(f"{c:>12}" for c in
                                             ("min", "p2", "median", "p98", "max", "mean"))
    lines.append(header)
    for name in shape.FIELDS:
        if name + suffix not in fields:
            continue
        x = np.asarray(fields[name + suffix], dtype=np.float64)[valid]
        x = x[np.isfinite(x)]
        if x.size == 0:
            lines.append(f"{name + suffix:<{width}}{'(no valid values)':>24}")
            continue
        stats = [x.min(), *np.percentile(x, [2, 50, 98]), x.max(), x.mean()]
        lines.append(f"{name + suffix:<{width}}" + "".join(f"{s:>12.5g}" for s in stats))
    if "n_neighbors" + suffix in fields:
        nb = np.asarray(fields["n_neighbors" + suffix])[valid]
        if nb.size:
            lines.append(f"neighbors per vertex: median {np.median(nb):.0f}, "
                         f"min {nb.min()}, max {nb.max()}")
    return lines


def _status_counts(status):
    """``"12 TOO_FEW_HALF_SETS, 3 NO_POSITION"``: the rows without an estimate by reason, most
    frequent first (codes this version does not know are counted as ``status N``)."""
    codes, counts = np.unique(np.asarray(status, dtype=np.int64), return_counts=True)
    known = {int(s): s.name for s in Status}
    parts = [(c, known.get(int(k), f"status {int(k)}")) for k, c in zip(codes, counts)
             if int(k) != Status.OK]
    return ", ".join(f"{c} {name}" for c, name in sorted(parts, key=lambda p: -p[0]))
