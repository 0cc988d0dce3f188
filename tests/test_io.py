"""meshcurv.io, the dispatcher: readers keep vertex order, every format module's table is
registered, writes are atomic, bad files fail with the file name, the format modules import
neither the dispatcher nor their soft dependencies; meshcurv.shape colour maps."""

import ast
import os
import pathlib
import subprocess
import sys

import numpy as np
import pytest

from meshcurv import io, shape
from meshcurv.io import las, obj, off, ply, stl, xyz

FORMATS = (ply, obj, off, stl, xyz, las)
IO_DIR = pathlib.Path(io.__file__).parent


def test_text_and_trimesh_readers_keep_vertex_order(tmp_path):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 0, 0], [5, 5, 5], [1, 1, 0.5]], float)
    f = np.array([[2, 0, 1], [3, 5, 2]])
    # OBJ with a duplicate position (3 == 1) and an unreferenced vertex (4): both kept, in order
    obj = tmp_path / "a.obj"
    obj.write_text("".join(f"v {a} {b} {c}\n" for a, b, c in v)
                   + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f))
    off = tmp_path / "a.off"
    off.write_text(f"OFF\n{len(v)} {len(f)} 0\n" + "".join(f"{a} {b} {c}\n" for a, b, c in v)
                   + "".join(f"3 {a} {b} {c}\n" for a, b, c in f))
    # ModelNet's OFF files write the vertex count against the keyword
    glued = tmp_path / "glued.off"
    glued.write_text(off.read_text().replace("OFF\n", "OFF", 1))
    for path in (obj, off, glued):
        data = io.read(str(path))
        np.testing.assert_array_equal(data.vertices, v)
        np.testing.assert_array_equal(data.faces, f)
    n = np.tile([0.0, 0.0, 1.0], (len(v), 1))
    xyz = tmp_path / "a.xyz"
    np.savetxt(xyz, np.column_stack([v, n]))
    data = io.read(str(xyz))
    np.testing.assert_array_equal(data.vertices, v)
    np.testing.assert_array_equal(data.normals, n)
    pts = tmp_path / "a.pts"  # Leica PTS: count line, x y z intensity
    pts.write_text(f"{len(v)}\n" + "".join(f"{a},{b},{c},7\n" for a, b, c in v))
    data = io.read(str(pts))
    np.testing.assert_array_equal(data.vertices, v)
    assert data.normals is None and (data.fields["intensity"] == 7).all()


def test_xyz_as_cloudcompare_and_windows_tools_write_it(tmp_path):
    # x y z r g b: the colours were taken for normals (k from -5 to 4 on a sphere of k 0.5);
    # a column header, 9 columns, a byte-order mark and a latin-1 comment were refused
    rng = np.random.default_rng(0)
    v = rng.normal(size=(50, 3))
    rgb = rng.integers(1, 256, (50, 3)).astype(float)
    n = v / np.linalg.norm(v, axis=1, keepdims=True)
    rows = lambda *cols: "".join(" ".join(f"{x:.17g}" for x in r) + "\n"
                                 for r in np.column_stack(cols))
    cases = {
        "rgb.xyz": (rows(v, rgb), None, rgb),
        "header.xyz": ("//X Y Z R G B Nx Ny Nz\n" + rows(v, rgb, n), n, rgb),
        "normals_first.xyz": (rows(v, n, rgb), n, rgb),
        "float_colours.xyz": (rows(v, rgb / 255.0, n), n, rgb / 255.0),
        "bom.xyz": ("\ufeff# Scan von M\u00fcller\n" + rows(v, n), n, None),
        "bom_only.xyz": ("\ufeff" + rows(v, n), n, None),
    }
    for name, (text, normals, colours) in cases.items():
        path = tmp_path / name
        path.write_bytes(text.encode("utf-8" if name.startswith("bom") else "latin-1"))
        data = io.read(str(path))
        np.testing.assert_array_equal(data.vertices, v, err_msg=name)
        if normals is None:
            assert data.normals is None, name
        else:
            np.testing.assert_array_equal(data.normals, normals, err_msg=name)
        if colours is not None:
            got = np.column_stack([data.fields[c] for c in ("red", "green", "blue")])
            np.testing.assert_array_equal(got, colours, err_msg=name)
    # 9 columns where neither triple tells itself apart (no 0-255 colours, no unit normals)
    (tmp_path / "ambiguous.xyz").write_text(rows(v, rgb / 255.0, 2 * n))
    with pytest.raises(io.MeshFileError, match="neither x y z r g b nx ny nz"):
        io.read(str(tmp_path / "ambiguous.xyz"))
    # axis-aligned unit normals are whole numbers too: still normals
    axes = np.tile([0.0, 0.0, 1.0], (50, 1))
    (tmp_path / "axes.xyz").write_text(rows(v, axes))
    np.testing.assert_array_equal(io.read(str(tmp_path / "axes.xyz")).normals, axes)


def test_atomic_write_removes_the_temporary_file_on_failure(tmp_path):
    target = tmp_path / "out.ply"

    def failing(tmp):
        with open(tmp, "wb") as fh:
            fh.write(b"half a file")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        io.atomic_write(str(target), failing)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("name, content, message", [
    ("missing.ply", None, "no such file"),
    ("mesh.abc", b"whatever", "unsupported"),
    ("corrupt.ply", b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty "
                    b"double x\nend_header\n\x00\x01", "not a valid PLY"),
    ("garbage.ply", b"\x89PNG\r\n\x1a\n" + bytes(range(256)), "not a valid PLY"),
    ("empty.xyz", b"", "no vertices"),
    ("nan.xyz", b"nan nan nan\nnan 1 2\n", "finite"),
    ("columns.xyz", b"1 2\n3 4\n", "columns"),
])
def test_bad_files_raise_meshfileerror_naming_the_file(tmp_path, name, content, message):
    path = tmp_path / name
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(io.MeshFileError, match=message) as exc:
        io.read(str(path))
    assert str(exc.value).startswith(str(path))


def test_every_format_table_is_registered_by_its_extension():
    readers = {ext: f for m in FORMATS for ext, f in m.readers.items()}
    writers = {ext: f for m in FORMATS for ext, f in getattr(m, "writers", {}).items()}
    assert io.READERS == readers and io.WRITERS == writers
    assert all(ext == io.file_extension("a" + ext) for ext in {**readers, **writers})


def test_writing_an_extension_without_a_writer_names_the_writable_ones(tmp_path):
    with pytest.raises(io.MeshFileError, match=r"cannot write '\.obj'.*\.las, \.laz, \.ply"):
        io.write(str(tmp_path / "x.obj"), io.MeshData(np.zeros((1, 3))), None)


def _imports(path):
    """``(level, module, names)`` of each import statement of the file ``path``, function-level
    ones included (``import a.b`` as ``(0, None, ["a.b"])``)."""
    tree = ast.parse(path.read_text())
    return [(n.level, n.module, [a.name for a in n.names]) if isinstance(n, ast.ImportFrom)
            else (0, None, [a.name for a in n.names])
            for n in ast.walk(tree) if isinstance(n, (ast.Import, ast.ImportFrom))]


def test_format_modules_import_neither_the_dispatcher_nor_an_adapter():
    siblings = {p.stem for p in IO_DIR.glob("*.py")} - {"__init__"}
    for path in IO_DIR.glob("*.py"):
        if path.stem == "__init__":
            continue
        for level, module, names in _imports(path):
            where = (path.name, level, module, names)
            if level == 1:  # from .data import ...: a sibling module, never the package
                assert module in siblings, where
            elif level == 2:  # from .. import shape / from ..result import ...: the core only
                assert not {module, *names} & {"io", "cli", "tiled", "batch"}, where
            else:  # third-party only (numpy, laspy, ...), never meshcurv by absolute name
                assert level == 0 and not any(
                    n.startswith("meshcurv") for n in [module or "", *names]), where


def test_importing_the_package_loads_no_parser_library():
    code = ("import sys, meshcurv.io; print(sorted(m for m in ('laspy', 'plyfile', 'trimesh', "
            "'numba', 'scipy', 'lazrs') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout
    assert out.strip() == "[]"


def test_las_files_without_laspy_fail_at_use_with_the_install_hint(tmp_path):
    path = tmp_path / "a.las"
    path.write_bytes(b"LASF" + bytes(400))
    code = ("import sys; sys.modules['laspy'] = None\n"
            "from meshcurv import io\n"
            "try:\n    io.read(sys.argv[1])\nexcept io.MeshFileError as exc:\n    print(exc)")
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True,
                         text=True, check=True).stdout
    assert out.strip() == f"{path}: LAS/LAZ files need laspy and lazrs (pip install 'meshcurv[las]')"


def test_check_distinct_refuses_the_input_under_another_name(tmp_path):
    src = tmp_path / "in.ply"
    src.write_bytes(b"x")
    os.link(src, tmp_path / "hard.ply")
    for same in (tmp_path / "." / "in.ply", tmp_path / "hard.ply"):
        with pytest.raises(io.MeshFileError, match="refusing to overwrite the input"):
            io.check_distinct(str(src), str(same))
    io.check_distinct(str(src), str(tmp_path / "out.ply"))


def test_colorize_shape_index_uses_the_fixed_scale_and_grey_for_invalid():
    rgb = shape.colorize(np.array([-1.0, 1.0, 0.0, np.nan, 7.0]), "shape_index", "RGB")
    # MeshLab's RGB ramp: red at the low end, blue at the high end, green in the middle
    np.testing.assert_array_equal(rgb, [[255, 0, 0], [0, 0, 255], [0, 255, 0],
                                        list(shape.INVALID_COLOR), [0, 0, 255]])


def test_color_range_clips_outliers_at_percentiles():
    values = np.r_[np.linspace(0.0, 1.0, 1000), 1e6, np.nan]
    lo, hi = shape.color_range(values, "k1", clamp=2.0)
    assert 0.0 < lo < 0.05 and 0.95 < hi < 1.05  # the single 1e6 outlier does not stretch it
    assert shape.color_range(values, "shape_index") == (-1.0, 1.0)
