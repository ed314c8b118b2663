"""Reading and writing geometry files: every format round-trips, polygons are split into fans,
and malformed, truncated or missing files raise FileFormatError naming the problem."""

from __future__ import annotations

import io
import re
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.errors import FileFormatError, InvalidInputError
from core.geometry import quad_triangles
from core.meshio import read_geometry, write_mesh

DATA = Path(__file__).resolve().parents[2] / "data"

# a unit square split as a quad (0, 1, 2, 3) plus a triangle (1, 4, 2): 5 vertices
VERTS = np.array(
    [[0.0, 0.0, 0.0], [1.0, 0.0, 0.5], [1.0, 1.0, 0.25], [0.0, 1.0, -0.125], [2.0, 0.5, 1.0]]
)
ROWS = VERTS.tolist()  # Python floats: repr() gives the shortest exact decimal
# the quad as a fan (0, 1, 2), (0, 2, 3); then the triangle
TRIS = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 2]])


def ply_header(fmt: str, vertex_props: list[str], n_faces: int, face_props: list[str]) -> bytes:
    lines = ["ply", f"format {fmt} 1.0", "comment made by hand", f"element vertex {len(VERTS)}"]
    lines += [f"property {p}" for p in vertex_props]
    lines += [f"element face {n_faces}"] + [f"property {p}" for p in face_props]
    return ("\n".join(lines + ["end_header"]) + "\n").encode("ascii")


# ---------------------------------------------------------------------------------------------
# round trips through write_mesh
# ---------------------------------------------------------------------------------------------


@settings(max_examples=25, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n=st.integers(3, 60),
    k=st.sampled_from([3, 4]),
    ext=st.sampled_from([".obj", ".ply"]),
)
def test_written_meshes_read_back_equal(
    tmp_path_factory: pytest.TempPathFactory, seed: int, n: int, k: int, ext: str
) -> None:
    rng = np.random.default_rng(seed)
    verts = rng.normal(size=(n, 3)) * 10.0 ** rng.integers(-5, 6)
    faces = rng.integers(0, n, size=(2 * n, k))
    path = tmp_path_factory.mktemp("rt") / f"mesh{ext}"
    write_mesh(path, verts, faces)
    pts, tris = read_geometry(path)
    np.testing.assert_array_equal(pts, verts)  # bit-exact coordinates
    if k == 3:
        np.testing.assert_array_equal(tris, faces)
        return
    # a quad is split along one of its diagonals, keeping its winding: the fan's where it is
    # convex, else by ear clipping (_concave_split); in the local order of its four corners
    # (distinct here) each triangle runs forwards and the two cover all four
    pairs = tris.reshape(-1, 2, 3)
    distinct = np.array([len(set(f)) == 4 for f in faces])  # (repeated corners: no order)
    local = np.argmax(pairs[distinct][..., None] == faces[distinct][:, None, None, :], axis=-1)
    steps = (np.roll(local, -1, axis=-1) - local) % 4
    assert (steps.sum(axis=-1) == 4).all()
    assert all(set(p.ravel()) == {0, 1, 2, 3} for p in local)


def test_sample_off_files_read_with_announced_counts() -> None:
    for name, nv, nf in [
        ("nefertiti", 299, 562),
        ("three_peaks", 1907, 3671),
        ("patch-01", 735, 1396),
    ]:
        pts, faces = read_geometry(DATA / f"{name}.off")
        assert pts.shape == (nv, 3) and pts.dtype == np.float64
        assert faces.shape == (nf, 3) and faces.dtype == np.int64
        assert faces.min() == 0 and faces.max() == nv - 1


def test_write_mesh_rejects_unknown_extension_and_bad_arrays(tmp_path: Path) -> None:
    with pytest.raises(FileFormatError, match=r"\.obj, \.ply"):
        write_mesh(tmp_path / "m.stl", VERTS, TRIS)
    with pytest.raises(InvalidInputError, match="face indices"):
        write_mesh(tmp_path / "m.obj", VERTS, TRIS + 10)
    with pytest.raises(InvalidInputError, match=r"\(N, 3\)"):
        write_mesh(tmp_path / "m.ply", VERTS[:, :2], TRIS)
    with pytest.raises(FileFormatError, match="cannot write"):
        write_mesh(tmp_path / "no" / "such" / "dir" / "m.obj", VERTS, TRIS)


def test_write_mesh_with_texture_coordinates(tmp_path: Path) -> None:
    """``uv=``: OBJ ``vt`` lines, one per vertex, and faces ``i/i``; PLY ``float s, t`` after
    the coordinates; both read back as the same mesh (the reader takes the vertex index of
    ``i/j``), the texture coordinates to 9 digits and float32; bad ``uv`` refused."""
    uv = np.array([[0.0, 0.0], [0.5, 0.0], [0.5, 0.5], [0.0, 0.5], [1.0, 0.25]]) + 1e-3
    write_mesh(tmp_path / "m.obj", VERTS, TRIS, uv=uv)
    text = (tmp_path / "m.obj").read_text().splitlines()
    vt = np.array([[float(x) for x in line.split()[1:]] for line in text if line[:3] == "vt "])
    faces = [line.split()[1:] for line in text if line[:2] == "f "]
    assert np.abs(vt - uv).max() < 1e-9 and len(faces) == len(TRIS)
    assert all(a == b for face in faces for a, b in (c.split("/") for c in face))
    for ext in ("obj", "ply"):
        if ext == "ply":
            write_mesh(tmp_path / "m.ply", VERTS, TRIS, uv=uv)
        pts, tris = read_geometry(tmp_path / f"m.{ext}")
        np.testing.assert_array_equal(pts, VERTS)
        np.testing.assert_array_equal(tris, TRIS)
    raw = (tmp_path / "m.ply").read_bytes()
    head, body = raw.split(b"end_header\n", 1)
    assert b"property double z\nproperty float s\nproperty float t\nelement face" in head
    rows = np.frombuffer(body[: len(VERTS) * 32], dtype=[("p", "<f8", (3,)), ("t", "<f4", (2,))])
    np.testing.assert_array_equal(rows["p"], VERTS)
    np.testing.assert_array_equal(rows["t"], uv.astype(np.float32))
    for bad in (uv[:4], np.c_[uv, uv[:, :1]], np.where(uv > 0.5, np.nan, uv)):
        with pytest.raises(InvalidInputError, match="uv must be a finite"):
            write_mesh(tmp_path / "m.obj", VERTS, TRIS, uv=bad)


# ---------------------------------------------------------------------------------------------
# OFF
# ---------------------------------------------------------------------------------------------


def assert_reads_the_sample_mesh(path: Path, text: str) -> None:
    path.write_text(text)
    pts, faces = read_geometry(path)
    np.testing.assert_array_equal(pts, VERTS)
    np.testing.assert_array_equal(faces, TRIS)


def test_off_with_counts_on_header_comments_polygons_and_colours(tmp_path: Path) -> None:
    text = (
        "OFF 5 2 0  # counts on the header line\n"
        "# a comment line\n\n"
        + "\n".join(" ".join(repr(c) for c in v) for v in ROWS)
        + "\n4 0 1 2 3 255 0 0\n"  # quad with a colour
        "3 1 4 2\n"
    )
    assert_reads_the_sample_mesh(tmp_path / "a.off", text)


def test_coff_and_point_only_off(tmp_path: Path) -> None:
    body = "\n".join(" ".join(map(repr, v)) + " 0.5 0.5 0.5 1" for v in ROWS)
    (tmp_path / "c.off").write_text(f"COFF\n5 0 0\n{body}\n")
    pts, faces = read_geometry(tmp_path / "c.off")
    np.testing.assert_array_equal(pts, VERTS)
    assert faces is None


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("OFF\n5 2 0\n0 0 0\n1 0 0\n1 1 0\n3 0 1 2\n", "truncated"),  # too few vertex lines
        ("OFF\n3 1 0\n0 0 0\n1 zero 0\n0 1 0\n3 0 1 2\n", "vertex line"),  # text in a number
        ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "do not exist"),  # index out of range
        ("PLY\n3 1 0\n", "first line must be 'OFF'"),
        ("OFF\nthree 1 0\n", "counts"),
        ("", "empty"),
    ],
)
def test_malformed_off_raises_file_format_error(tmp_path: Path, text: str, problem: str) -> None:
    (tmp_path / "bad.off").write_text(text)
    with pytest.raises(FileFormatError, match=problem) as info:
        read_geometry(tmp_path / "bad.off")
    assert "bad.off" in str(info.value)


# ---------------------------------------------------------------------------------------------
# OBJ
# ---------------------------------------------------------------------------------------------


def test_obj_with_slashes_quads_negative_indices_and_other_statements(tmp_path: Path) -> None:
    text = (
        "# exported\nmtllib x.mtl\no thing\n"
        + "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in ROWS[:4])
        + "vt 0 0\nvt 1 0\nvn 0 0 1\nusemtl red\ns off\n"
        "f 1/1/1 2/2/1 3/1/1 4//1\n"  # quad with texture/normal indices
        f"v {ROWS[4][0]!r} {ROWS[4][1]!r} {ROWS[4][2]!r} 1.0\n"  # optional w
        "f -4 -1 -3  # relative indices: 2 5 3\n"
        "l 1 2\n"
    )
    assert_reads_the_sample_mesh(tmp_path / "a.obj", text)


def test_obj_records_continued_on_the_next_line(tmp_path: Path) -> None:
    """A backslash at the end of a line continues it (the OBJ format; exporters wrap long
    faces so): such a file was refused with "bad face 'f 1 2 \\'" (user test). A comment
    ending in one does not swallow the next line; errors name the record's first line."""
    text = (
        "# exported \\\n"
        + "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in ROWS[:4])
        + "f 1 2 \\\n   3 4\n"
        + f"v {ROWS[4][0]!r} \\\n{ROWS[4][1]!r} {ROWS[4][2]!r}\n"
        + "f 2 5 \\  \n 3\n"
    )
    assert_reads_the_sample_mesh(tmp_path / "a.obj", text)
    (tmp_path / "b.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 \\\n 2 9\n")
    with pytest.raises(FileFormatError, match="line 4: the face refers to a vertex not defined"):
        read_geometry(tmp_path / "b.obj")


def test_obj_without_faces_is_a_point_cloud(tmp_path: Path) -> None:
    (tmp_path / "p.obj").write_text("".join(f"v {x} {y} {z}\n" for x, y, z in ROWS))
    pts, faces = read_geometry(tmp_path / "p.obj")
    assert faces is None and pts.shape == (5, 3)


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n", "not defined"),
        ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 two 3\n", "bad face"),
        ("v 0 0\n", "needs x, y, z"),
        ("v 0 0 zero\n", "vertex line"),
    ],
)
def test_malformed_obj_raises_file_format_error(tmp_path: Path, text: str, problem: str) -> None:
    (tmp_path / "bad.obj").write_text(text)
    with pytest.raises(FileFormatError, match=problem):
        read_geometry(tmp_path / "bad.obj")


# ---------------------------------------------------------------------------------------------
# PLY
# ---------------------------------------------------------------------------------------------


def test_ascii_ply_with_extra_properties_and_vertex_index(tmp_path: Path) -> None:
    head = ply_header(
        "ascii",
        ["float x", "float y", "float z", "float nx", "uchar red"],
        2,
        ["list uchar int vertex_index", "uchar flags"],
    )
    body = "".join(f"{x!r} {y!r} {z!r} 0 0 1 200\n" for x, y, z in ROWS)
    body += "4 0 1 2 3 7\n3 1 4 2 0\n"
    (tmp_path / "a.ply").write_bytes(head + body.encode())
    pts, faces = read_geometry(tmp_path / "a.ply")
    np.testing.assert_array_equal(pts, VERTS)
    np.testing.assert_array_equal(faces, TRIS)


@pytest.mark.parametrize("endian", ["<", ">"])
@pytest.mark.parametrize("mixed", [False, True])
def test_binary_ply_structured_read(tmp_path: Path, endian: str, mixed: bool) -> None:
    """Binary little/big endian; float32 coordinates with extra properties; faces all quads
    (fixed-size fast path) or quads and triangles (ragged path); uint indices, ushort count."""
    fmt = "binary_little_endian" if endian == "<" else "binary_big_endian"
    vdt = np.dtype(
        [
            ("x", endian + "f4"),
            ("red", "u1"),
            ("y", endian + "f4"),
            ("z", endian + "f4"),
            ("q", endian + "f8"),
        ]
    )
    v = np.zeros(len(VERTS), vdt)
    v["x"], v["y"], v["z"] = VERTS.T
    faces = [[0, 1, 2, 3], [1, 4, 2]] if mixed else [[0, 1, 2, 3], [1, 4, 2, 0]]
    head = ply_header(
        fmt,
        ["float x", "uchar red", "float y", "float z", "double q"],
        len(faces),
        ["uchar flags", "list ushort uint vertex_indices"],
    )
    fbytes = b"".join(
        np.array([9], "u1").tobytes()
        + np.array([len(f)], endian + "u2").tobytes()
        + np.array(f, endian + "u4").tobytes()
        for f in faces
    )
    (tmp_path / "b.ply").write_bytes(head + v.tobytes() + fbytes)
    pts, tris = read_geometry(tmp_path / "b.ply")
    np.testing.assert_array_equal(pts, VERTS.astype(np.float32).astype(np.float64))
    expected = TRIS if mixed else np.array([[0, 1, 2], [0, 2, 3], [1, 4, 2], [1, 2, 0]])
    np.testing.assert_array_equal(tris, expected)


def test_binary_ply_with_integer_coordinates_and_no_faces(tmp_path: Path) -> None:
    head = (
        b"ply\nformat binary_little_endian 1.0\nelement vertex 3\n"
        b"property short x\nproperty short y\nproperty int z\nend_header\n"
    )
    v = np.array([(1, 2, 3), (-4, 5, 6), (7, 8, -9)], [("x", "<i2"), ("y", "<i2"), ("z", "<i4")])
    (tmp_path / "i.ply").write_bytes(head + v.tobytes())
    pts, faces = read_geometry(tmp_path / "i.ply")
    np.testing.assert_array_equal(pts, [[1, 2, 3], [-4, 5, 6], [7, 8, -9]])
    assert faces is None


def test_truncated_binary_ply_raises_file_format_error(tmp_path: Path) -> None:
    write_mesh(tmp_path / "m.ply", VERTS, TRIS)
    data = (tmp_path / "m.ply").read_bytes()
    body = data.index(b"end_header\n") + len(b"end_header\n")
    for keep in (len(data) - 5, body + 50):  # inside the face data, inside the vertex data
        (tmp_path / "t.ply").write_bytes(data[:keep])
        with pytest.raises(FileFormatError, match="truncated"):
            read_geometry(tmp_path / "t.ply")
    # mixed polygon sizes (ragged layout), truncated in the last face
    write_mesh(tmp_path / "q.ply", VERTS, np.array([[0, 1, 2, 3]]))
    quad = (tmp_path / "q.ply").read_bytes()
    head = quad[: quad.index(b"end_header")].replace(b"element face 1", b"element face 2")
    tri = np.array([3], "u1").tobytes() + np.array([1, 4, 2], "<i4").tobytes()
    ragged = head + quad[quad.index(b"end_header") :] + tri
    (tmp_path / "r.ply").write_bytes(ragged)
    np.testing.assert_array_equal(read_geometry(tmp_path / "r.ply")[1], TRIS)
    (tmp_path / "r.ply").write_bytes(ragged[:-2])
    with pytest.raises(FileFormatError, match="truncated"):
        read_geometry(tmp_path / "r.ply")


@pytest.mark.parametrize(
    ("data", "problem"),
    [
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\n", "end_header"),
        (b"ply\nformat binary_middle_endian 1.0\nend_header\n", "unknown PLY format"),
        (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty quad x\nend_header\n", "bad header"),
        (
            b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\n"
            b"property float z\nend_header\n0 0 0\n",
            "truncated",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
            b"property float z\nend_header\n0 zero 0\n",
            "vertex line",
        ),
        (
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n"
            b"end_header\n0 0\n",
            "no property z",
        ),
        (b"solid stl\n", "not a PLY file"),
    ],
)
def test_malformed_ply_raises_file_format_error(tmp_path: Path, data: bytes, problem: str) -> None:
    (tmp_path / "bad.ply").write_bytes(data)
    with pytest.raises(FileFormatError, match=problem):
        read_geometry(tmp_path / "bad.ply")


def binary_ply(n_vertices: int | str, n_faces: int | str, count_type: str = "uchar") -> bytes:
    """A little-endian PLY header announcing the given counts, then VERTS as floats and one
    triangle: a 103-byte body whatever the counts say."""
    head = (
        f"ply\nformat binary_little_endian 1.0\nelement vertex {n_vertices}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {n_faces}\nproperty list {count_type} int vertex_indices\nend_header\n"
    ).encode()
    count = np.array([3], {"uchar": "u1", "int": "<i4"}[count_type]).tobytes()
    return head + VERTS.astype("<f4").tobytes() + count + np.array([0, 1, 2], "<i4").tobytes()


@pytest.mark.parametrize(
    ("name", "data", "problem"),
    [
        ("f.ply", binary_ply(5, 10**12), r"'face' data are truncated: 1000000000000 records"),
        ("f.ply", binary_ply(5, 10**12, "int"), r"'face' data are truncated"),
        ("v.ply", binary_ply(10**12, 1), r"'vertex' data are truncated"),
        ("n.ply", binary_ply(-5, 1), "'element vertex -5': an element count cannot be negative"),
        ("n.ply", binary_ply(5, -1), "'element face -1': an element count cannot be negative"),
        (
            "l.ply",
            binary_ply(5, 1, "int").replace(np.array([3], "<i4").tobytes() + b"\0" * 4,
                                            np.array([-3], "<i4").tobytes() + b"\0" * 4),
            "negative list length -3",
        ),
        (
            "a.ply",
            b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
            b"property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
            b"end_header\n0 0 0\n1 0 0\n0 1 0\n1000000000000 0 1 2\n",
            "announces 1000000000000 vertices but lists fewer",
        ),
        ("a.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n1000000000000 0 1 2\n", "lists fewer"),
    ],
    ids=["faces-count-uchar", "faces-count-int", "vertex-count", "negative-vertex-count",
         "negative-face-count", "negative-list-length", "ascii-ply-polygon", "off-polygon"],
)
def test_counts_beyond_the_data_are_refused_before_allocating(
    tmp_path: Path, name: str, data: bytes, problem: str
) -> None:
    """Element counts and polygon sizes are checked against the bytes or columns present
    before anything of that size is allocated (a huge count was a MemoryError), and negative
    counts are refused (np.frombuffer took -1 as 'all')."""
    (tmp_path / name).write_bytes(data)
    with pytest.raises(FileFormatError, match=problem) as info:
        read_geometry(tmp_path / name)
    assert str(info.value).startswith(f"cannot read {name!r}: ")


# ---------------------------------------------------------------------------------------------
# point clouds: text, npy, npz (points / DEM)
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("name", "text"),
    [
        ("p.xyz", "".join(f"{x!r} {y!r}\t{z!r} 0.1 0.2\n" for x, y, z in ROWS)),
        ("p.csv", "x,y,z,intensity\n" + "".join(f"{x!r}, {y!r}, {z!r}, 7\n" for x, y, z in ROWS)),
        ("p.txt", "# scan\n" + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in ROWS)),
    ],
    ids=["xyz-extra-columns", "csv-with-header", "txt-with-comment"],
)
def test_text_point_clouds(tmp_path: Path, name: str, text: str) -> None:
    (tmp_path / name).write_text(text)
    pts, faces = read_geometry(tmp_path / name)
    np.testing.assert_array_equal(pts, VERTS)
    assert faces is None


BOM_TEXTS = {
    "p.obj": "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in ROWS) + "f 1 2 3 4\nf 2 5 3\n",
    "p.csv": "".join(f"{x!r},{y!r},{z!r}\n" for x, y, z in ROWS),
    "p.xyz": "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in ROWS),
    "p.off": "OFF\n5 2 0\n" + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in ROWS)
    + "4 0 1 2 3\n3 1 4 2\n",
    "p.ply": "ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
    "property float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n"
    + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in ROWS) + "4 0 1 2 3\n3 1 4 2\n",
}


@pytest.mark.parametrize("name", list(BOM_TEXTS))
def test_a_utf8_byte_order_mark_is_skipped(tmp_path: Path, name: str) -> None:
    """A leading UTF-8 byte-order mark (Windows editors write one): every point is read, the
    first one too (it was skipped in an OBJ, and taken for a header in a headerless CSV)."""
    (tmp_path / name).write_bytes(b"\xef\xbb\xbf" + BOM_TEXTS[name].encode())
    pts, faces = read_geometry(tmp_path / name)
    np.testing.assert_array_equal(pts, VERTS)
    if name.endswith((".obj", ".off", ".ply")):
        np.testing.assert_array_equal(faces, TRIS)


@pytest.mark.parametrize("encoding", ["utf-16", "utf-16-le", "utf-16-be"])
@pytest.mark.parametrize("name", ["p.xyz", "p.obj", "p.off", "p.ply"])
def test_utf16_text_is_refused_with_a_message(tmp_path: Path, name: str, encoding: str) -> None:
    """UTF-16 text (with its byte-order mark) is refused with a message saying what to do."""
    text = BOM_TEXTS[name]
    data = text.encode(encoding)
    if encoding != "utf-16":  # the -le/-be codecs write no mark: add the usual one
        data = "\ufeff".encode(encoding) + data
    (tmp_path / name).write_bytes(data)
    with pytest.raises(FileFormatError, match="UTF-16 .*save it as UTF-8 or ASCII") as info:
        read_geometry(tmp_path / name)
    assert name in str(info.value)


def test_leica_pts_point_counts_are_skipped(tmp_path: Path) -> None:
    """Leica .pts: a point count line (before each scan), then 'x y z intensity r g b' lines;
    the points are read, the counts are not taken for points or refused as short lines."""
    rows = [f"{x!r} {y!r} {z!r} -1200 10 20 30\n" for x, y, z in ROWS]
    (tmp_path / "one.pts").write_text("5\n" + "".join(rows))
    (tmp_path / "two.pts").write_text("3\n" + "".join(rows[:3]) + "2\n" + "".join(rows[3:]))
    for name in ("one.pts", "two.pts"):
        pts, faces = read_geometry(tmp_path / name)
        np.testing.assert_array_equal(pts, VERTS)
        assert faces is None
    (tmp_path / "cut.pts").write_text("8\n" + "".join(rows))
    with pytest.raises(FileFormatError, match="says 8 points but 5 lines follow .*truncated"):
        read_geometry(tmp_path / "cut.pts")


def test_semicolon_separated_columns_with_decimal_points_or_commas(tmp_path: Path) -> None:
    """A spreadsheet's CSV in many locales: 'x;y;z' columns, decimal commas (user test: "each
    line needs at least three numbers" for lines of three numbers)."""
    (tmp_path / "dot.csv").write_text("x;y;z\n" + "".join(f"{x!r};{y!r};{z!r}\n" for x, y, z in ROWS))
    (tmp_path / "comma.csv").write_text(
        "".join(f"{x!r};{y!r};{z!r}\n".replace(".", ",") for x, y, z in ROWS))
    for name in ("dot.csv", "comma.csv"):
        pts, faces = read_geometry(tmp_path / name)
        np.testing.assert_array_equal(pts, VERTS)
        assert faces is None
    # a semicolon in a header does not make a whitespace file semicolon-separated (review)
    rows = "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in ROWS)
    (tmp_path / "head.xyz").write_text("X Y Z; metres\n" + rows)
    np.testing.assert_array_equal(read_geometry(tmp_path / "head.xyz")[0], VERTS)


def test_whitespace_columns_with_decimal_commas(tmp_path: Path) -> None:
    """A European locale's export: '1,5 2,0 -3,25e2' (whitespace columns, decimal commas),
    with or without a header; its first line had been taken for a header and the next one
    refused. Comma-separated files with spaces after the commas are read as before."""
    rows = "".join(f"{x!r}\t{y!r} {z!r}\n".replace(".", ",") for x, y, z in ROWS)
    big = "".join(f"{x!r} {y!r} {100 * z:.6e}\n".replace(".", ",") for x, y, z in ROWS)
    (tmp_path / "plain.xyz").write_text(rows)
    (tmp_path / "head.xyz").write_text("X Y Z\n" + rows)
    (tmp_path / "exp.xyz").write_text(big)
    for name in ("plain.xyz", "head.xyz"):
        np.testing.assert_array_equal(read_geometry(tmp_path / name)[0], VERTS)
    np.testing.assert_allclose(read_geometry(tmp_path / "exp.xyz")[0], VERTS * [1, 1, 100])
    (tmp_path / "spaced.csv").write_text("".join(f"{x!r}, {y!r}, {z!r}\n" for x, y, z in ROWS))
    (tmp_path / "ints.csv").write_text("1, 2, 3\n4, 5, 6\n7, 8, 9\n")
    (tmp_path / "before.csv").write_text("10 ,20 ,30\n1 ,2 ,3\n4 ,5 ,6\n")  # (review)
    np.testing.assert_array_equal(read_geometry(tmp_path / "before.csv")[0],
                                  [[10, 20, 30], [1, 2, 3], [4, 5, 6]])
    np.testing.assert_array_equal(read_geometry(tmp_path / "spaced.csv")[0], VERTS)
    np.testing.assert_array_equal(read_geometry(tmp_path / "ints.csv")[0],
                                  [[1, 2, 3], [4, 5, 6], [7, 8, 9]])


def test_text_in_a_number_column_raises_file_format_error(tmp_path: Path) -> None:
    (tmp_path / "p.xyz").write_text("0 0 0\n1 0 0\n1 one 0\n")
    with pytest.raises(FileFormatError, match="p.xyz"):
        read_geometry(tmp_path / "p.xyz")
    (tmp_path / "q.csv").write_text("0,0\n1,0\n")
    with pytest.raises(FileFormatError, match="three numbers"):
        read_geometry(tmp_path / "q.csv")
    # after a comment and a header, the bad line is quoted (numpy's "row 8" was line 11)
    good = "".join(f"{k} {k} {k}\n" for k in range(8))
    (tmp_path / "h.xyz").write_text("# scan\nx y z\n" + good + "8 8 3,5\n9 9 9\n")
    with pytest.raises(FileFormatError, match=r"bad line 11 '8 8 3,5': could not convert "
                                              r"string '3,5' to float64 in column 3"):
        read_geometry(tmp_path / "h.xyz")
    # a short line by the same number (it was "row 9", 1-based among the data rows, while a
    # bad number had no number at all: user test), blank lines and a point count counted too
    (tmp_path / "s.xyz").write_text("# scan\nx y z\n\n" + good + "8 8\n9 9 9\n")
    with pytest.raises(FileFormatError, match=r"bad line 12 '8 8': it has 2 columns, and "
                                              r"column 3 is read"):
        read_geometry(tmp_path / "s.xyz")
    (tmp_path / "c.pts").write_text("10\n" + good + "8 8 x\n9 9 9\n")
    with pytest.raises(FileFormatError, match=r"bad line 10 '8 8 x'"):
        read_geometry(tmp_path / "c.pts")
    (tmp_path / "m.off").write_text("OFF\n# a comment\n3 1 0\n0 0 0\n1 0 zero\n0 1 0\n"
                                    "3 0 1 2\n")
    with pytest.raises(FileFormatError, match=r"bad vertex line 5 '1 0 zero'"):
        read_geometry(tmp_path / "m.off")
    (tmp_path / "m.obj").write_text("# obj\nv 0 0 0\nvt 0 0\nv 1 0 O\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(FileFormatError, match=r"bad vertex line 4 '1 0 O'"):
        read_geometry(tmp_path / "m.obj")


def test_npy_and_npz_points_and_faces(tmp_path: Path) -> None:
    np.save(tmp_path / "p.npy", VERTS)
    pts, faces = read_geometry(tmp_path / "p.npy")
    np.testing.assert_array_equal(pts, VERTS)
    assert faces is None
    np.savez(tmp_path / "m.npz", points=VERTS, faces=np.array([[0, 1, 2, 3], [1, 4, 2, 0]]))
    pts, faces = read_geometry(tmp_path / "m.npz")
    np.testing.assert_array_equal(faces, [[0, 1, 2], [0, 2, 3], [1, 4, 2], [1, 2, 0]])
    # whole numbers stored as floats are indices, as fit_surface takes them (user test); others
    # are refused by their type
    np.savez(tmp_path / "f.npz", points=VERTS, faces=np.array([[0, 1, 2, 3], [1, 4, 2, 0]], float))
    assert read_geometry(tmp_path / "f.npz")[1].tolist() == faces.tolist()
    np.savez(tmp_path / "h.npz", points=VERTS, faces=np.array([[0, 1, 2.5]]))
    with pytest.raises(FileFormatError, match=r"whole vertex indices; got 2.5 \(1 such values\)"):
        read_geometry(tmp_path / "h.npz")
    np.savez(tmp_path / "g.npz", points=VERTS, faces=np.array([[0, 1, 1e20]]))
    with pytest.raises(FileFormatError, match=r"whole vertex indices; got 1e\+20"):
        read_geometry(tmp_path / "g.npz")
    np.save(tmp_path / "bad.npy", VERTS[:, :2])
    with pytest.raises(FileFormatError, match=r"\(N, 3\)"):
        read_geometry(tmp_path / "bad.npy")
    np.savez(tmp_path / "other.npz", stuff=VERTS)
    with pytest.raises(FileFormatError, match="'stuff'"):
        read_geometry(tmp_path / "other.npz")


@pytest.mark.parametrize("shape", [(3, 2000), (4, 50), (2, 50)])
def test_a_transposed_array_is_refused_as_transposed(tmp_path: Path, shape: tuple) -> None:
    """An array with points as columns, (3, N): refused as transposed (it was read as 3
    points, and the fit said 'at least 10 points are needed; got 3')."""
    arr = np.random.default_rng(0).random(shape)
    np.save(tmp_path / "t.npy", arr)
    np.savez(tmp_path / "t.npz", points=arr)
    for name in ("t.npy", "t.npz"):
        with pytest.raises(FileFormatError, match=rf"{re.escape(str(shape))}: it looks transposed"):
            read_geometry(tmp_path / name)
    np.save(tmp_path / "ok.npy", arr.T)  # the transpose is read, its first three columns
    if shape[0] >= 3:
        np.testing.assert_array_equal(read_geometry(tmp_path / "ok.npy")[0], arr.T[:, :3])


def test_a_complex_array_is_refused(tmp_path: Path) -> None:
    """Complex coordinates are refused, not read with their imaginary parts dropped."""
    arr = VERTS + 1j
    np.save(tmp_path / "c.npy", arr)
    np.savez(tmp_path / "c.npz", points=arr)
    for name in ("c.npy", "c.npz"):
        with pytest.raises(FileFormatError, match="complex numbers .*must be real"):
            read_geometry(tmp_path / name)


def npy_bytes(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, arr)
    return buf.getvalue()


def npz_bytes(**arrays: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.savez(buf, **arrays)
    return buf.getvalue()


def huge_npy_header() -> bytes:
    """A .npy header announcing 10**12 x 3 doubles, followed by 24 bytes."""
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(
        buf, {"descr": "<f8", "fortran_order": False, "shape": (10**12, 3)}
    )
    return buf.getvalue() + bytes(24)


def zip_bytes(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name, data in members.items():
            z.writestr(name, data)
    return buf.getvalue()


def damaged_member() -> bytes:
    """An uncompressed .npz whose last coordinate byte is changed: its CRC no longer fits."""
    data = bytearray(npz_bytes(points=VERTS))
    at = bytes(data).index(VERTS.tobytes()) + VERTS.nbytes - 1
    data[at] ^= 0xFF
    return bytes(data)


@pytest.mark.parametrize(
    ("name", "data", "problem"),
    [
        ("p.npy", b"", "the file is empty"),
        ("p.npy", npy_bytes(VERTS)[:-7], r"truncated: .*shape \(5, 3\) of float64"),
        ("p.npy", huge_npy_header(), r"truncated: .*\(1000000000000, 3\)"),
        ("p.npy", b"x y z\n0 0 0\n", "not a NumPy .npy file"),
        ("p.npy", npz_bytes(points=VERTS), "zip archive: name it .npz"),
        ("m.npz", b"", "the file is empty"),
        ("m.npz", b"PK\x03\x04garbage" * 10, "damaged or truncated"),
        ("m.npz", npz_bytes(points=VERTS)[:200], "damaged or truncated"),
        ("m.npz", damaged_member(), "damaged or truncated"),
        ("m.npz", npy_bytes(VERTS), "single array: name it .npy"),
        ("m.npz", zip_bytes({"points.npy": huge_npy_header()}), r"'points' is truncated"),
        ("m.npz", zip_bytes({"points": VERTS.tobytes()}), "'points' is not a NumPy array"),
    ],
    ids=["npy-empty", "npy-truncated", "npy-huge-shape", "npy-text", "npy-is-zip", "npz-empty",
         "npz-garbage", "npz-truncated", "npz-bad-crc", "npz-is-npy", "npz-huge-shape",
         "npz-raw-member"],
)
def test_corrupt_npy_and_npz_raise_file_format_error(
    tmp_path: Path, name: str, data: bytes, problem: str
) -> None:
    """Empty, truncated, damaged or foreign .npy/.npz files: FileFormatError naming the file
    and the problem (not numpy's EOFError, BadZipFile or MemoryError)."""
    (tmp_path / name).write_bytes(data)
    with pytest.raises(FileFormatError, match=problem) as info:
        read_geometry(tmp_path / name)
    assert str(info.value).startswith(f"cannot read {name!r}: ")


def test_dem_npz_becomes_grid_points_in_metres() -> None:
    # said, with the origin (the conversion had been silent: user test)
    with pytest.warns(RuntimeWarning, match=r"the DEM's bounds are in degrees: its nodes were "
                      r"converted to metres east and north of its south-west corner \(longitude "
                      r"-84.41375\d, latitude 36.44625\d"):
        pts, faces = read_geometry(DATA / "jacksboro_fault_dem.npz")
    assert faces is None and pts.shape == (344 * 403, 3)
    with np.load(DATA / "jacksboro_fault_dem.npz") as z:
        elev = z["elevation"]
    np.testing.assert_array_equal(pts[:, 2], elev.ravel())
    # 3 arc-second grid: about 74 m (x, at 36.6 deg N) by 93 m (y), in metres from the SW
    # corner. Its bounds are the outer edges of its cells (403 dx = xmax - xmin), so the nodes
    # are the cells' centres, dx apart and half a cell in (the user test found the grid
    # stretched by 1/402 and 1/343 when the edges were taken for nodes: 75 m over the tile)
    with np.load(DATA / "jacksboro_fault_dem.npz") as z:
        cell, lat = float(z["dx"]), np.radians(0.5 * (float(z["ymin"]) + float(z["ymax"])))
    mx, my = 111200.0 * cell * np.cos(lat), 111200.0 * cell  # the cell in metres
    dx = np.diff(np.unique(pts[:, 0]))
    dy = np.diff(np.unique(pts[:, 1]))
    np.testing.assert_allclose(dx, mx, rtol=1e-9)
    np.testing.assert_allclose(dy, my, rtol=1e-9)
    assert 70 < mx < 78 and 89 < my < 97
    np.testing.assert_allclose(pts[:, :2].min(axis=0), [mx / 2, my / 2], rtol=1e-9)
    # row 0 is the northern edge (the file stores the northern latitude as 'ymin')
    assert pts[0, 1] == pts[:, 1].max()


def test_small_dem_in_metres_with_nodata(tmp_path: Path) -> None:
    elev = np.array([[1.0, 2.0, np.nan], [4.0, -9999.0, 6.0]])
    np.savez(
        tmp_path / "d.npz",
        elevation=elev,
        xmin=1000.0,
        xmax=1020.0,
        ymin=500.0,
        ymax=510.0,
        nodata=-9999.0,
    )
    pts, _ = read_geometry(tmp_path / "d.npz")
    np.testing.assert_array_equal(
        pts, [[1000, 500, 1], [1010, 500, 2], [1000, 510, 4], [1020, 510, 6]]
    )
    # bounds that could be degrees: the nodata value is no relief (review: -9999 made this
    # 60 m grid a geographic one, converted to metres from degrees)
    np.savez(tmp_path / "e.npz", elevation=elev, xmin=10.0, xmax=70.0, ymin=20.0, ymax=30.0,
             nodata=-9999.0)
    np.testing.assert_array_equal(read_geometry(tmp_path / "e.npz")[0][:, 0], [10, 40, 10, 70])


def test_dem_cell_sizes_say_where_the_nodes_are(tmp_path: Path) -> None:
    """``dx``/``dy`` that fill the bounds with the cells: nodes at the cells' centres; that
    fill them with the gaps between nodes: nodes on the bounds; that fit neither: refused."""
    elev = np.arange(6.0).reshape(2, 3)
    bounds = dict(xmin=1000.0, xmax=1030.0, ymin=500.0, ymax=520.0)
    np.savez(tmp_path / "edges.npz", elevation=elev, dx=10.0, dy=10.0, **bounds)
    pts, _ = read_geometry(tmp_path / "edges.npz")
    np.testing.assert_array_equal(np.unique(pts[:, 0]), [1005, 1015, 1025])
    np.testing.assert_array_equal(np.unique(pts[:, 1]), [505, 515])
    np.savez(tmp_path / "nodes.npz", elevation=elev, dx=15.0, dy=20.0, **bounds)
    pts, _ = read_geometry(tmp_path / "nodes.npz")
    np.testing.assert_array_equal(np.unique(pts[:, 0]), [1000, 1015, 1030])
    np.testing.assert_array_equal(np.unique(pts[:, 1]), [500, 520])
    np.savez(tmp_path / "bad.npz", elevation=elev, dx=12.0, **bounds)
    with pytest.raises(FileFormatError, match=r"the DEM cell size dx = 12 fits neither its 3 "
                                              r"cells between xmin and xmax"):
        read_geometry(tmp_path / "bad.npz")


def test_a_north_up_dem_is_read_the_right_way_round(tmp_path: Path) -> None:
    """A raster as GDAL and rasterio give it (row 0 the northern edge): with a negative ``dy``,
    with its affine ``transform`` (rasterio's order, 6 or 9 numbers) or ``geotransform``
    (GDAL's), or with ``ymin`` the northern edge, the hill is where it is; with ``ymin < ymax``
    and a positive ``dy`` the rows run north from ``ymin`` (user test: a north-up grid saved
    so was read mirrored, which stays the documented reading)."""
    rows, cols, d, x0, y0 = 5, 6, 10.0, 500_000.0, 4_200_000.0
    elev = np.zeros((rows, cols))
    elev[1, 4] = 100.0  # row 1 from the north, column 4 from the west
    top = (x0 + 4.5 * d, y0 + (rows - 1.5) * d)
    edges = dict(xmin=x0, xmax=x0 + cols * d, ymin=y0, ymax=y0 + rows * d, dx=d)
    north = y0 + rows * d
    cases = {
        "dy": dict(edges, dy=-d),
        "ymin north": dict(edges, ymin=north, ymax=y0, dy=d),
        "transform": dict(transform=np.array([d, 0.0, x0, 0.0, -d, north])),
        "affine 3x3": dict(transform=np.array([d, 0.0, x0, 0.0, -d, north, 0.0, 0.0, 1.0])),
        "geotransform": dict(geotransform=np.array([x0, d, 0.0, north, 0.0, -d])),
        "south up": dict(edges, dy=d),
    }
    for name, keys in cases.items():
        np.savez(tmp_path / "dem.npz", elevation=elev, **keys)
        pts, _ = read_geometry(tmp_path / "dem.npz")
        assert len(pts) == rows * cols, name
        np.testing.assert_allclose(np.unique(pts[:, 0]), x0 + d * (np.arange(cols) + 0.5))
        np.testing.assert_allclose(np.unique(pts[:, 1]), y0 + d * (np.arange(rows) + 0.5))
        want = top if name != "south up" else (top[0], y0 + 1.5 * d)
        np.testing.assert_allclose(pts[np.argmax(pts[:, 2]), :2], want, err_msg=name)
    gdal = np.array([x0, d, 0.0, north, 0.0, -d])
    for keys, words in ((dict(transform=np.arange(5.0)), "transform must be 6 or 9 finite"),
                        (dict(transform=gdal), "looks like GDAL's geotransform"),
                        (dict(geotransform=np.array([x0, d, 0, north, 0, 0.0])),
                         "zero determinant")):
        np.savez(tmp_path / "bad.npz", elevation=elev, **keys)
        with pytest.raises(FileFormatError, match=words):
            read_geometry(tmp_path / "bad.npz")


def test_an_esri_ascii_grid_is_read_as_its_cells_centres(tmp_path: Path) -> None:
    """A DEM as GIS tools export it, an ESRI ASCII grid (.asc: a header of ncols, nrows, the
    lower-left corner or centre, the cell size and NODATA_value, then the rows from the
    north), is read as the same raster with its geotransform in a .npz: the cells' centres,
    the hill where it is, no-data cells left out; GDAL's dx / dy for oblong cells; a header
    or body that is not a grid is refused with words; a file without the header is x y z
    text, as other tools write .asc clouds (review)."""
    rows, cols, d, x0, y0 = 5, 6, 10.0, 500_000.0, 4_200_000.0
    elev = np.arange(rows * cols, dtype=float).reshape(rows, cols) % 7
    elev[1, 4] = 100.0  # row 1 from the north, column 4 from the west
    north = y0 + rows * d
    np.savez(tmp_path / "dem.npz", elevation=elev,
             geotransform=np.array([x0, d, 0.0, north, 0.0, -d]))
    want, _ = read_geometry(tmp_path / "dem.npz")
    body = "\n".join(" ".join(f"{v:g}" for v in row) for row in elev)

    def write(name, head, text=body):
        (tmp_path / name).write_text(head + "\n" + text + "\n")
        return tmp_path / name

    corner = f"ncols {cols}\nnrows {rows}\nxllcorner {x0}\nyllcorner {y0}\ncellsize {d}"
    centre = (f"NCOLS {cols}\nNROWS {rows}\nXLLCENTER {x0 + d / 2}\nYLLCENTER {y0 + d / 2}\n"
              f"CELLSIZE {d}")
    for path in (write("a.asc", corner), write("b.asc", centre)):
        pts, faces = read_geometry(path)
        assert faces is None
        np.testing.assert_allclose(pts, want, err_msg=path.name)
    np.testing.assert_allclose(want[np.argmax(want[:, 2]), :2],
                               (x0 + 4.5 * d, y0 + (rows - 1.5) * d))
    holed = elev.copy()
    holed[2, 1] = -9999.0
    text = "\n".join(" ".join(f"{v:g}" for v in row) for row in holed)
    pts, _ = read_geometry(write("c.asc", corner + "\nNODATA_value -9999", text))
    assert len(pts) == rows * cols - 1 and pts[:, 2].min() >= 0
    with pytest.raises(FileFormatError, match="far below all others"):  # (no NODATA_value)
        read_geometry(write("d.asc", corner, text))
    oblong = f"ncols {cols}\nnrows {rows}\nxllcorner {x0}\nyllcorner {y0}\ndx {d}\ndy {2 * d}"
    pts, _ = read_geometry(write("e.asc", oblong))
    np.testing.assert_allclose(np.unique(pts[:, 1]), y0 + 2 * d * (np.arange(rows) + 0.5))
    for head, text, words in (
            (corner.replace("cellsize", "# cellsize"), body, "its header has no cellsize"),
            (corner, body.rsplit(" ", 1)[0], "5 rows of 6 heights \\(30\\), but 29 follow"),
            (corner.replace("nrows 5", "nrows 5.5"), body, "whole numbers of at least 2"),
            (corner.replace(f"cellsize {d}", "cellsize -1"), body, "must be positive"),
            (corner, body.replace("100", "1OO"), "must be numbers"),
            (corner.replace("ncols 6", "ncols inf"), body, "whole numbers of at least 2")):
        with pytest.raises(FileFormatError, match=words):
            read_geometry(write("bad.asc", head, text))
    # without the header, .asc is x y z text (as CloudCompare and others export clouds)
    (tmp_path / "cloud.asc").write_text("1 2 3\n4 5 6\n7 8 9.5\n")
    pts, faces = read_geometry(tmp_path / "cloud.asc")
    assert faces is None and np.array_equal(pts, [[1, 2, 3], [4, 5, 6], [7, 8, 9.5]])


def test_a_dem_fill_value_without_a_nodata_key_is_refused(tmp_path: Path) -> None:
    """-9999 cells of a DEM saved without its 'nodata' key were fitted as terrain 10 km deep
    ("tolerance reached" on a garbage surface); a real low elevation is kept."""
    elev = np.array([[101.0, 102.0, -9999.0], [104.0, -9999.0, 106.0]])
    bounds = dict(xmin=1000.0, xmax=1020.0, ymin=500.0, ymax=510.0)
    np.savez(tmp_path / "d.npz", elevation=elev, **bounds)
    with pytest.raises(FileFormatError, match=r"2 of the DEM's 6 cells are -9999, far below all "
                       r"others \(lowest 101\): a no-data fill value; store it as the key "
                       r"'nodata'"):
        read_geometry(tmp_path / "d.npz")
    np.savez(tmp_path / "ok.npz", elevation=np.where(elev < 0, 50.0, elev), **bounds)
    assert len(read_geometry(tmp_path / "ok.npz")[0]) == 6
    np.savez(tmp_path / "deep.npz", elevation=np.where(elev < 0, -9999.0, -9000.0), **bounds)
    assert len(read_geometry(tmp_path / "deep.npz")[0]) == 6  # a trench, not a fill value



def test_a_dem_fill_value_is_kept_for_the_caller_with_keep_fill_values(tmp_path: Path) -> None:
    """keep_fill_values returns a DEM's fill cells as points (the CLI's --drop-invalid leaves
    them out), and they do not make degree-sized bounds look geographic."""
    elev = np.array([[101.0, 102.0, -9999.0], [104.0, -9999.0, 106.0]])
    np.savez(tmp_path / "d.npz", elevation=elev, xmin=10.0, xmax=12.0, ymin=5.0, ymax=6.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no conversion from degrees
        pts, faces = read_geometry(tmp_path / "d.npz", keep_fill_values=True)
    assert faces is None and len(pts) == 6
    assert (pts[:, 2] == -9999.0).sum() == 2
    assert pts[:, 0].max() == 12.0  # metres as stored
    with pytest.raises(FileFormatError, match="no-data fill value"):
        read_geometry(tmp_path / "d.npz")

# ---------------------------------------------------------------------------------------------
# paths
# ---------------------------------------------------------------------------------------------


def test_missing_file_and_unknown_extension(tmp_path: Path) -> None:
    with pytest.raises(FileFormatError, match="no such file"):
        read_geometry(tmp_path / "nothing.off")
    (tmp_path / "model.stl").write_text("solid x\n")
    with pytest.raises(FileFormatError, match=r"unknown file type '\.stl'.*\.off.*\.ply"):
        read_geometry(tmp_path / "model.stl")
    # FileFormatError is an InvalidInputError and a ValueError
    with pytest.raises(ValueError):
        read_geometry(tmp_path / "nothing.obj")


def test_files_of_coarsely_rounded_32_bit_coordinates_are_named(tmp_path: Path) -> None:
    """A 20 m patch at UTM coordinates stored as 32-bit floats (the usual binary PLY export)
    is already rounded to 0.5 m there: fit_surface warned of float32 arrays, but a file
    read by read_geometry (the CLI) said nothing (user test). Float64 files, and 32-bit ones
    near the origin, give no warning; the points are float64 either way."""
    import warnings

    xy = np.random.default_rng(0).random((400, 2)) * 20
    local = np.c_[xy, 0.1 * np.sin(xy[:, 0])]
    far = local + [512345.0, 4212345.0, 100.0]
    header = ("ply\nformat binary_little_endian 1.0\nelement vertex 400\nproperty float x\n"
              "property float y\nproperty float z\nend_header\n").encode()
    for name, pts, warned in (("far.ply", far, True), ("near.ply", local, False)):
        (tmp_path / name).write_bytes(header + pts.astype("<f4").tobytes())
        np.save(tmp_path / name.replace(".ply", ".npy"), pts.astype(np.float32))
        for f in (name, name.replace(".ply", ".npy")):
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                got, _ = read_geometry(tmp_path / f)
            said = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
            assert got.dtype == np.float64 and len(got) == 400
            assert bool(said) == warned, said
            if warned:
                assert said[0].startswith(f"{f}: the points are 32-bit floats, which far from "
                                          "the origin are 0.5 apart") and "64-bit" in said[0]
    np.save(tmp_path / "double.npy", far)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        read_geometry(tmp_path / "double.npy")
    # x and y in 32 bits, z in 64 (review): the same warning, naming the columns; a 32-bit
    # column near the origin (z here) is no matter
    for types, warned in ((("float", "float", "double"), True),
                          (("double", "double", "float"), False)):
        head = "ply\nformat binary_little_endian 1.0\nelement vertex 400\n" + "".join(
            f"property {t} {c}\n" for t, c in zip(types, "xyz")) + "end_header\n"
        rec = np.zeros(400, dtype=[(c, "<f4" if t == "float" else "<f8")
                                   for t, c in zip(types, "xyz")])
        for j, c in enumerate("xyz"):
            rec[c] = far[:, j]
        (tmp_path / "mixed.ply").write_bytes(head.encode() + rec.tobytes())
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            got, _ = read_geometry(tmp_path / "mixed.ply")
        said = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
        assert bool(said) == warned, said
        np.testing.assert_array_equal(got[:, 2], rec["z"].astype(np.float64))
        if warned:
            assert said[0].startswith("mixed.ply: the points' x and y are 32-bit floats, which "
                                      "far from the origin are 0.5 apart")


@pytest.mark.parametrize(
    ("header", "order", "extra"),
    [
        ("id,x,y,z", (1, 2, 3), 1),  # GIS exports: an id first
        (",x,y,z", (1, 2, 3), 1),  # pandas' to_csv: an unnamed index column
        ("//X,Y,Z,R,G,B", (0, 1, 2), 0),  # CloudCompare
        ("name;X [m];Y [m];Z [m]", (1, 2, 3), 1),
        ("fid,point_x,point_y,point_z", (1, 2, 3), 1),  # ArcGIS
        ("id,lon,lat,elevation", (1, 2, 3), 1),
        ("z,y,x", (2, 1, 0), 0),
        ("a,b,c", (0, 1, 2), 0),  # no names: the first three
    ],
)
def test_a_text_header_that_names_the_columns_chooses_them(tmp_path: Path, header, order,
                                                           extra) -> None:
    """A header ``id,x,y,z`` had been skipped and x = id, y = x, z = y read (user test: a
    grid fitted "perfectly" over the wrong axes, exit 0)."""
    delim = ";" if ";" in header else ","
    cols = len(header.split(delim))
    rows = []
    for k, (x, y, z) in enumerate(ROWS):
        row = [7.0 + k] * cols
        for axis, at in enumerate(order):
            row[at] = (x, y, z)[axis]
        rows.append(delim.join(repr(v) for v in row) + "\n")
    (tmp_path / "p.csv").write_text(header + "\n" + "".join(rows))
    pts, _ = read_geometry(tmp_path / "p.csv")
    np.testing.assert_array_equal(pts, VERTS)
    # a header naming only some of the three is refused: the third cannot be told
    named = ["id", "x", "y"] + ["v"] * (cols - 3)  # (as many fields as the data)
    (tmp_path / "q.csv").write_text(delim.join(named) + "\n" + "".join(rows))
    with pytest.raises(FileFormatError, match=r"names x in column 2, y in column 3 but not all "
                                              r"three coordinates: name the columns x, y and z"):
        read_geometry(tmp_path / "q.csv")


@pytest.mark.parametrize("ext", [".obj", ".off", ".ply"])
def test_a_concave_polygon_is_split_by_its_own_vertices(tmp_path: Path, ext: str) -> None:
    """An L-shaped 8-gon (Blender's Dissolve Faces; its OBJ export writes n-gons) fan-split
    from a vertex next to its reflex corner gave a flipped triangle overlapping the others
    (user test: 575 control points instead of 150): it is ear-clipped in its plane, keeping
    its winding; quads are cut along their shorter diagonal (core.geometry.quad_triangles)."""
    g = np.arange(4.0)
    x, y = np.meshgrid(g, g)
    verts = np.c_[x.ravel(), y.ravel(), 0.1 * x.ravel() * y.ravel()]
    v = lambda i, j: 4 * i + j  # noqa: E731  (row i, column j)
    # the L over cells (0,0), (0,1), (1,0) counter-clockwise from next to its reflex corner
    ell = [v(1, 2), v(1, 1), v(2, 1), v(2, 0), v(1, 0), v(0, 0), v(0, 1), v(0, 2)]
    quad = [v(1, 1), v(1, 2), v(2, 2), v(2, 1)]  # (convex)
    polys = [ell, quad]
    if ext == ".obj":
        text = "".join(f"v {a!r} {b!r} {c!r}\n" for a, b, c in verts)
        text += "".join("f " + " ".join(str(i + 1) for i in p) + "\n" for p in polys)
    elif ext == ".off":
        text = f"OFF\n{len(verts)} {len(polys)} 0\n"
        text += "".join(f"{a!r} {b!r} {c!r}\n" for a, b, c in verts)
        text += "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys)
    else:
        text = (f"ply\nformat ascii 1.0\nelement vertex {len(verts)}\nproperty double x\n"
                "property double y\nproperty double z\nelement face 2\n"
                "property list uchar int vertex_indices\nend_header\n")
        text += "".join(f"{a!r} {b!r} {c!r}\n" for a, b, c in verts)
        text += "".join(f"{len(p)} " + " ".join(map(str, p)) + "\n" for p in polys)
    (tmp_path / f"m{ext}").write_text(text)
    pts, tris = read_geometry(tmp_path / f"m{ext}")
    assert len(tris) == 6 + 2
    a, b, c = (pts[tris[:, k], :2] for k in range(3))
    area = 0.5 * ((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    assert (area > 0).all() and area[:6].sum() == pytest.approx(3.0)  # none flipped
    np.testing.assert_array_equal(tris[6:], quad_triangles(pts, np.array([quad])))
    assert set(np.intersect1d(*tris[6:]).tolist()) == {v(1, 2), v(2, 1)}  # (sqrt 2 < 2.09)


def test_a_comma_header_over_whitespace_columns_is_read(tmp_path) -> None:
    # the separator came from the header too: every data line was refused (user test)
    for header, want in (("x, y, z", [1.0, 2.0, 3.0]), ("id, x, y, z", [2.0, 3.0, 4.0])):
        src = tmp_path / "h.xyz"
        cols = 4 if header.startswith("id") else 3
        rows = "\n".join(" ".join(str(v + i) for v in range(1, cols + 1)) for i in range(5))
        src.write_text(f"{header}\n{rows}\n")
        pts, _ = read_geometry(src)
        assert pts.shape == (5, 3) and pts[0].tolist() == want
