"""What every format module shares: :class:`MeshData` (the geometry read from a file), the
:class:`MeshFileError` readers and writers raise, and small helpers on both (first line of an
error, usable normals, bounding-box diagonal, file extension, silencing the parsing libraries).
"""

import contextlib
import logging
import os
import warnings
from dataclasses import dataclass, field as dc_field

import numpy as np

__all__ = ["MeshData", "MeshFileError", "first_line", "usable_normals", "bbox_diagonal",
           "file_extension", "quiet_libraries", "radius_suffix", "split_radius_suffix",
           "suffix_radius_text"]


class MeshFileError(ValueError):
    """A file that cannot be read or written; the message starts with the file name."""


@dataclass
class MeshData:
    """Geometry of a mesh or point cloud as read from a file; one row per vertex, file order.

    vertices : (n, 3) float64, model units
    faces : (m, 3) int64, or None for a point cloud
    normals : (n, 3) float64 from the file, or None
    fields : dict of other per-vertex properties, name -> (n,) array (PLY only; e.g. the
        curvature fields of an annotated file)
    path : the file it came from
    notes : one line each on what of the file ``fields`` could not hold (e.g. a LAS dimension
        of 64-bit integers beyond 2^53, which no PLY property holds exactly)
    """

    vertices: np.ndarray
    faces: np.ndarray = None
    normals: np.ndarray = None
    fields: dict = dc_field(default_factory=dict)
    path: str = ""
    notes: tuple = ()

    @property
    def is_point_cloud(self):
        """True when there are no faces."""
        return self.faces is None or len(self.faces) == 0


def usable_normals(normals):
    """Whether ``normals`` ((n, 3) or None) is a full set of finite, non-zero normals, fit to
    hand to the estimator as given normals (e.g. from a file or a MeshLab mesh)."""
    return bool(normals is not None and np.isfinite(normals).all()
                and (np.linalg.norm(normals, axis=1) > 1e-12).all())


def first_line(exc):
    """The first line of an exception's message (its type name when it has none)."""
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def bbox_diagonal(vertices):
    """Length of the bounding-box diagonal of the finite rows of (n, 3) ``vertices``, model units.

    The reference length of percentage radii (``2%``), as in MeshLab's ``PercentageValue``.

    >>> bbox_diagonal([[0, 0, 0], [3, 4, 0], [float("nan"), 9, 9]])
    5.0
    """
    v = np.asarray(vertices, dtype=np.float64)
    v = v[np.isfinite(v).all(axis=1)]
    if len(v) == 0:
        return 0.0
    return float(np.linalg.norm(v.max(axis=0) - v.min(axis=0)))


# Field names of a file annotated at several radii: ``<field>_r<radius>`` with the radius in its
# shortest decimal form and only letters, digits and "_" (a name PDAL's expressions, laspy's
# attributes and Python accept; "." and "%" are not): "." -> "p", "-" -> "m", "%" -> "pct".
_SUFFIX_CODES = {".": "p", "-": "m", "+": ""}


def radius_suffix(value, percent=False):
    """The suffix naming the fields of one radius in a file annotated at several radii.

    ``value`` : float > 0, the radius as given (model units, or percent of the bounding-box
    diagonal when ``percent``). The suffix is ``_r`` + its shortest decimal form (the shortest
    that reads back as the same float) with "." written "p" and "-" written "m", + ``pct`` for
    a percentage: distinct radii get distinct suffixes, and equal ones (0.5, 0.50, 5e-1) the
    same.

    >>> radius_suffix(0.5), radius_suffix(2.0), radius_suffix(2.0, percent=True)
    ('_r0p5', '_r2', '_r2pct')
    >>> radius_suffix(1e-05)
    '_r1em05'
    """
    text = repr(float(value))
    if text.endswith(".0"):
        text = text[:-2]
    return "_r" + "".join(_SUFFIX_CODES.get(c, c) for c in text) + ("pct" if percent else "")


def split_radius_suffix(name):
    """``(field, suffix)`` of a field name: ``"k1_r0p5"`` -> ``("k1", "_r0p5")``; a name
    without a radius suffix (see :func:`radius_suffix`) -> ``(name, "")``.

    >>> split_radius_suffix("shape_index_r2pct"), split_radius_suffix("k1")
    (('shape_index', '_r2pct'), ('k1', ''))
    """
    field, sep, tail = name.rpartition("_r")
    if (sep and field and tail[:1].isdigit() and tail.isascii() and tail.isalnum()
            and tail == tail.lower()):
        return field, sep + tail
    return name, ""


def suffix_radius_text(suffix):
    """The radius a suffix of :func:`radius_suffix` names, as a user writes it.

    >>> suffix_radius_text("_r0p5"), suffix_radius_text("_r2pct"), suffix_radius_text("_r1em05")
    ('0.5', '2%', '1e-05')
    """
    text = suffix[2:]
    percent = text.endswith("pct")
    text = (text[:-3] if percent else text).replace("p", ".").replace("m", "-")
    return text + ("%" if percent else "")


def file_extension(path):
    """The extension of ``path``, lower case with its dot (``"scan.LAZ"`` -> ``".laz"``), the
    key of the reader and writer tables; ``""`` when there is none.

    >>> file_extension("scan.LAZ"), file_extension("README")
    ('.laz', '')
    """
    return os.path.splitext(str(path))[1].lower()


@contextlib.contextmanager
def quiet_libraries():
    """Silence warnings and the loggers of the parsing libraries while a file is read: their
    complaints about a corrupt file become the reader's one-line MeshFileError instead."""
    loggers = [logging.getLogger(name) for name in ("plyfile", "laspy")]
    levels = [lg.level for lg in loggers]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for lg in loggers:  # the level, not ``disabled``: it also holds for child loggers
            lg.setLevel(logging.CRITICAL + 1)
        try:
            yield
        finally:
            for lg, level in zip(loggers, levels):
                lg.setLevel(level)
