"""Reading and writing geometry files for the command-line tool.

Readers return ``(points, faces)``: ``points (n, 3) float64`` and ``faces (f, 3) int64``
triangles (quads cut along a diagonal, larger polygons split into fans ``(v0, v_j, v_{j+1})``),
or ``faces = None`` for a point cloud. Supported:

=========================  =====================================================================
``.off``                   ASCII OFF (``OFF``/``COFF``/``NOFF``/``CNOFF``/``STOFF`` headers,
                           counts on the header line or the next, ``#`` comments)
``.obj``                   Wavefront OBJ: ``v`` and ``f`` lines (``f 1/2/3 ...``, negative
                           indices); everything else is ignored
``.ply``                   PLY ascii, binary_little_endian, binary_big_endian: vertex ``x, y, z``
                           of any numeric type, face list ``vertex_indices``/``vertex_index``
``.xyz .txt .csv .pts``    text columns (whitespace or comma separated); the first three are
                           ``x, y, z`` unless a header line names them (``id,x,y,z``,
                           ``X [m]``, ``lon,lat,elevation``); a point count line is skipped
                           (Leica ``.pts``: before each scan)
``.npy``                   an ``(n, 3)`` array (more columns: the first three are used)
``.npz``                   key ``points`` (and optional ``faces``), or a DEM: key ``elevation``
                           (rows, cols) with ``xmin, xmax, ymin, ymax`` (row 0 at ``ymin``;
                           ``dy < 0``: at the larger y) or the raster's ``transform``
                           (rasterio) or ``geotransform`` (GDAL)
``.asc``                   a DEM as an ESRI ASCII grid (GDAL's AAIGrid; ``ncols, nrows,
                           xllcorner, yllcorner, cellsize, NODATA_value``): its cells' centres;
                           without that header, x y z text columns (as ``.xyz``)
=========================  =====================================================================

Writers: :func:`write_mesh` for ``.obj`` (ASCII) and ``.ply`` (binary little endian).

Bulk data are parsed with numpy (``np.loadtxt``, structured dtypes on the raw bytes); only OBJ
files and binary PLY files with mixed polygon sizes use a Python loop over lines / faces.
Polygons are cut by their shape, whatever corner they start at (core.geometry.polygon_triangles):
quads along the shorter diagonal, larger polygons by their best ears (concave ones, e.g. an
L-shaped n-gon, in their plane: a loop over those only).
Every problem with a file raises :class:`~.errors.FileFormatError` naming the file.
Text (and PLY headers) may start with a UTF-8 byte-order mark; UTF-16 text is refused.
"""

from __future__ import annotations

import math
import os
import re
import struct
import warnings
import zipfile
import zlib
from pathlib import Path

import numpy as np

from .errors import FileFormatError, InvalidInputError
from .geometry import float32_rounding, polygon_triangles
from .parameterize import fill_value_rows, on_xy_grid

__all__ = ["READ_EXTENSIONS", "WRITE_EXTENSIONS", "is_dem", "is_raster", "read_geometry",
           "write_mesh"]

READ_EXTENSIONS = (".off", ".obj", ".ply", ".xyz", ".txt", ".csv", ".pts", ".npy", ".npz",
                   ".asc")
WRITE_EXTENSIONS = (".obj", ".ply")

PathLike = str | os.PathLike

# degrees of latitude -> metres (the value matplotlib's DEM examples use)
_METRES_PER_DEGREE = 111_200.0


class _MalformedError(Exception):
    """Internal: a parse problem; turned into FileFormatError with the file name."""


# --------------------------------------------------------------------------------------------
# Public API
# --------------------------------------------------------------------------------------------


def read_geometry(path: PathLike, *, keep_fill_values: bool = False
                  ) -> tuple[np.ndarray, np.ndarray | None]:
    """Read points and (optionally) faces from a file; the format follows the extension.

    Args:
        path: file to read (see the module docstring for the formats).
        keep_fill_values: a DEM (``.npz`` with ``elevation``) whose cells without data hold
            a common fill value (-9999 ...) and no ``nodata`` key is refused, since those
            cells would be fitted as terrain; with True its cells are returned as points
            (fill values and all) for the caller to find with
            :func:`core.parameterize.fill_value_rows` and leave out, as the command line's
            ``--drop-invalid`` does for any point cloud (it had refused the DEM before it
            saw the option: user test).

    Returns:
        ``(points, faces)``: ``points (n, 3) float64``; ``faces (f, 3) int64`` triangles with
        0-based indices, or None when the file holds no faces (a point cloud).

    Raises:
        FileFormatError: missing file, unknown extension, or malformed/truncated content.
    """
    p = Path(path)
    ext = p.suffix.lower()
    if p.is_dir():
        raise FileFormatError(f"{str(p)!r} is a folder; give the path of a file in it")
    if not p.is_file():
        raise FileFormatError(f"no such file: {str(p)!r}; check the path")
    if ext not in _READERS:
        raise FileFormatError(
            f"cannot read {p.name!r}: unknown file type {ext or '(no extension)'!r}; "
            f"supported: {', '.join(READ_EXTENSIONS)}"
        )
    try:
        # (a reader may add which columns the file stored in 32 bits: PLY can mix them)
        reader = _READERS[ext]
        points, faces, *single = (reader(p, keep_fill_values=keep_fill_values)
                                  if reader in (_read_npz, _read_asc) else reader(p))
    except _MalformedError as exc:
        raise FileFormatError(f"cannot read {p.name!r}: {exc}") from None
    except OSError as exc:
        raise FileFormatError(f"cannot read {p.name!r}: {exc.strerror or exc}") from None
    except (ValueError, IndexError, TypeError, struct.error, UnicodeDecodeError, EOFError,
            zipfile.BadZipFile, zlib.error) as exc:
        raise FileFormatError(f"cannot read {p.name!r}: malformed content ({exc})") from None
    coarse = float32_rounding(np.asarray(points), "export the file with 64-bit (double) "
                              "coordinates, or with an offset subtracted",
                              single[0] if single else None)
    if coarse is not None:  # (the API says so of float32 arrays; a file said nothing: user test)
        warnings.warn(f"{p.name}: {coarse}", RuntimeWarning, stacklevel=2)
    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    if faces is not None:
        faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        if len(faces) == 0:
            faces = None
        elif faces.min() < 0 or faces.max() >= len(points):
            raise FileFormatError(
                f"cannot read {p.name!r}: faces refer to vertices that do not exist (indices "
                f"{int(faces.min())}..{int(faces.max())}, but there are {len(points)} vertices)"
            )
    return points, faces


def is_raster(path: PathLike) -> bool:
    """Whether ``path`` is a DEM raster as :func:`read_geometry` reads it: an ``.asc`` with an
    ESRI ASCII grid's header, or an ``.npz`` with ``elevation`` (and no ``points``). Its
    points are heights over a grid of x and y, a height field along z whatever its slope,
    which the command line fits as such (``--projection z``): the best-fit plane of a sloping
    tile is tilted, and its surface reaches past the tile's straight edges (the Jacksboro DEM
    every third node, tilted 0.48 degrees: its tessellation 3.6 m past them, along z 1e-11).
    Looks at the header or the archive's names only; False for anything unreadable (which
    :func:`read_geometry` then names)."""
    p = Path(path)
    ext = p.suffix.lower()
    try:
        if ext == ".asc":
            with open(p, "rb") as fh:
                head = _strip_bom(fh.read(4096)).decode("utf-8", errors="replace")
            words = head.split()
            return bool(words) and words[0].lower() in _ASC_KEYS
        if ext == ".npz":
            with zipfile.ZipFile(p) as z:
                names = {n[:-4] if n.endswith(".npy") else n for n in z.namelist()}
            return "elevation" in names and "points" not in names
    except (OSError, zipfile.BadZipFile, ValueError, _MalformedError):
        return False
    return False


def is_dem(path: PathLike, points: np.ndarray) -> bool:
    """Whether the point cloud read from ``path`` is a DEM, heights over a grid of x and y,
    which the command line and Blender's Import Points fit along z: a raster file
    (:func:`is_raster`, whatever share of its cells has data) or points on a grid of x and y
    with one height per node (:func:`core.parameterize.on_xy_grid`: gridded XYZ text, as
    survey agencies publish DEM tiles)."""
    return is_raster(path) or on_xy_grid(points)


def write_mesh(path: PathLike, vertices: np.ndarray, faces: np.ndarray,
               uv: np.ndarray | None = None) -> None:
    """Write a polygon mesh as ``.obj`` (ASCII) or ``.ply`` (binary little endian).

    OBJ: ``v x y z`` lines with 17 significant digits (exact round trip of float64) and
    ``f i j k`` lines with 1-based indices. PLY: ``double x, y, z`` vertices and a face list
    ``uchar`` count / ``int`` indices. With ``uv``, a texture coordinate per vertex: OBJ
    ``vt u v`` lines (9 significant digits) and ``f i/i j/j k/k`` faces, PLY ``float s, t``
    vertex properties (what Blender, MeshLab and most tools read as a UV map).

    Args:
        path: output file; its extension chooses the format.
        vertices: ``(n, 3)`` coordinates.
        faces: ``(f, k)`` 0-based vertex indices, ``k >= 3`` (triangles, quads, ...).
        uv: ``(n, 2)`` texture coordinates of the vertices, or None.

    Raises:
        FileFormatError: unknown extension or the file cannot be written.
        InvalidInputError: bad arrays (shape, NaN, indices out of range).
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in WRITE_EXTENSIONS:
        raise FileFormatError(
            f"cannot write {p.name!r}: unknown mesh file type {ext or '(no extension)'!r}; "
            f"supported: {', '.join(WRITE_EXTENSIONS)}"
        )
    v = np.asarray(vertices, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 3:
        raise InvalidInputError(f"vertices must be an (N, 3) array; got shape {v.shape}")
    if not np.all(np.isfinite(v)):
        raise InvalidInputError("vertices have NaN or infinite coordinates; cannot write them")
    f = np.asarray(faces)
    if f.ndim != 2 or f.shape[1] < 3 or (f.size and not np.issubdtype(f.dtype, np.integer)):
        raise InvalidInputError(
            f"faces must be an (F, k) integer array with k >= 3; got shape {f.shape}, "
            f"type {f.dtype}"
        )
    if f.size and (f.min() < 0 or f.max() >= len(v)):
        raise InvalidInputError(
            f"face indices must be in 0..{len(v) - 1}; got {int(f.min())}..{int(f.max())}"
        )
    if f.shape[1] > 255:
        raise InvalidInputError("faces with more than 255 vertices cannot be written")
    if uv is not None:
        uv = np.asarray(uv, dtype=np.float64)
        if uv.shape != (len(v), 2) or not np.all(np.isfinite(uv)):
            raise InvalidInputError(
                f"uv must be a finite ({len(v)}, 2) array of texture coordinates, one per "
                f"vertex; got shape {uv.shape}"
                + ("" if uv.shape != (len(v), 2) else " with NaN or infinite values"))
    try:
        if ext == ".obj":
            _write_obj(p, v, f.astype(np.int64), uv)
        else:
            _write_ply(p, v, f.astype(np.int64), uv)
    except OSError as exc:
        raise FileFormatError(f"cannot write {str(p)!r}: {exc.strerror or exc}") from None


# --------------------------------------------------------------------------------------------
# Helpers
# --------------------------------------------------------------------------------------------


def _fan(polys: np.ndarray) -> np.ndarray:
    """Split ``(f, k)`` polygons into ``(f (k-2), 3)`` fan triangles ``(v0, v_j, v_{j+1})``."""
    polys = np.asarray(polys, dtype=np.int64)
    f, k = polys.shape
    if k < 3:
        return np.empty((0, 3), dtype=np.int64)
    j = np.arange(1, k - 1)
    first = np.broadcast_to(polys[:, :1], (f, k - 2))
    return np.stack([first, polys[:, j], polys[:, j + 1]], axis=-1).reshape(-1, 3)


def _fan_groups(groups: list[tuple[np.ndarray, np.ndarray]], verts: np.ndarray | None = None
                ) -> np.ndarray:
    """Fan triangles of polygons given in groups of equal size, in the original face order;
    with the vertices ``verts``, the polygons that are not convex are split by their own
    vertices instead (:func:`_concave_split`).

    Args:
        groups: ``(face_numbers (m,), polygons (m, k))`` per polygon size ``k``.
    """
    tris, where = [], []
    for ids, polys in groups:
        k = polys.shape[1]
        if k >= 3:
            tris.append(_fan(polys) if verts is None else _concave_split(verts, polys))
            where.append(np.repeat(ids, k - 2))
    if not tris:
        return np.empty((0, 3), dtype=np.int64)
    order = np.argsort(np.concatenate(where), kind="stable")
    return np.concatenate(tris)[order]


def _concave_split(verts: np.ndarray, polys: np.ndarray) -> np.ndarray:
    """Triangles ``(m (k-2), 3)`` of ``(m, k)`` polygons of the vertices ``verts``, cut by
    their shape whatever corner they start at (:func:`core.geometry.polygon_triangles`: quads
    along the shorter diagonal, larger polygons by their best ears, concave ones in their
    plane). A fan from the first vertex of a concave polygon overlaps itself: an L-shaped
    8-gon, as Blender's Dissolve Faces makes and its OBJ export writes, gave a flipped
    triangle and 575 control points instead of 150 (user test). Polygons with indices out of
    range keep their fans (refused afterwards)."""
    polys = np.asarray(polys, dtype=np.int64)
    m, k = polys.shape
    if k < 4 or m == 0 or polys.min() < 0 or polys.max() >= len(verts):
        return _fan(polys)
    return polygon_triangles(verts, polys)


def _loadtxt(lines: list[str], what: str, numbers=None, **kw) -> np.ndarray:
    """``np.loadtxt`` over a list of lines; problems become _MalformedError naming ``what``,
    the line quoted and, given ``numbers`` (the 1-based line numbers in the file of
    ``lines``), its number."""
    if not lines:
        return np.empty((0, len(kw.get("usecols", (0,)))))
    try:
        return np.loadtxt(lines, ndmin=2, comments=None, **kw)
    except ValueError as exc:
        msg = str(exc).split("\n")[0]
        # numpy counts the rows of ``lines`` (comments and a header left out), from 0 in a
        # conversion error and from 1 in a short line's: quote the line itself with its number
        # in the file instead (a file's line 11 was "row 8", and a short line 1501 "row 1501"
        # while a bad number on it had no number: user test)
        at = re.search(r" at row (\d+), column (\d+)", msg)
        short = re.search(r"invalid column index (\d+) at row (\d+) with (\d+) columns?", msg)
        row = None
        if at and int(at.group(1)) < len(lines):
            row = int(at.group(1))
            msg = f"{msg[: at.start()]} in column {at.group(2)}{msg[at.end():]}"
        elif short and 0 < int(short.group(2)) <= len(lines):
            row, k = int(short.group(2)) - 1, int(short.group(3))
            msg = (f"it has {k} column{'s' if k != 1 else ''}, and column "
                   f"{int(short.group(1)) + 1} is read")
        if row is not None:
            where = f" {numbers[row]}" if numbers is not None else ""
            raise _MalformedError(f"bad {what}{where} {lines[row].strip()[:60]!r}: {msg}"
                                  ) from None
        raise _MalformedError(f"bad {what}: {msg}") from None


def _polygons_from_lines(lines: list[str], what: str, first_col: int = 0,
                         verts: np.ndarray | None = None) -> np.ndarray:
    """Triangles of the polygons of :func:`_polygon_groups` (:func:`_fan_groups`)."""
    return _fan_groups(_polygon_groups(lines, what, first_col), verts)


def _polygon_groups(lines: list[str], what: str, first_col: int = 0) -> list:
    """Polygons from text lines ``... n i0 i1 ... i_{n-1} [extra]`` (count at ``first_col``):
    ``(line numbers, (m, n) indices)`` per count ``n``.

    Lines are grouped by their count (a loop over the few distinct polygon sizes only) and each
    group is parsed by ``np.loadtxt``; polygons with fewer than 3 vertices are dropped.
    """
    if not lines:
        return []
    counts = _loadtxt(lines, what, usecols=(first_col,), dtype=np.int64)[:, 0]
    if counts.min() < 0:
        raise _MalformedError(f"bad {what}: negative vertex count")
    # each index takes a character at least: a larger count (a damaged file) is refused
    # before it becomes the number of columns to read
    lengths = np.fromiter(map(len, lines), dtype=np.int64, count=len(lines))
    if (over := np.flatnonzero(counts > lengths)).size:
        raise _MalformedError(
            f"bad {what} {lines[over[0]].strip()[:40]!r}: it announces {counts[over[0]]} "
            "vertices but lists fewer"
        )
    arr = np.array(lines, dtype=object)
    groups = []
    for n in np.unique(counts[counts >= 3]):
        sel = np.flatnonzero(counts == n)
        cols = tuple(range(first_col + 1, first_col + 1 + int(n)))
        groups.append((sel, _loadtxt(list(arr[sel]), what, usecols=cols, dtype=np.int64)))
    return groups


_UTF8_BOM = b"\xef\xbb\xbf"
_UTF16_BOMS = (b"\xff\xfe", b"\xfe\xff")  # little and big endian (UTF-32 LE starts alike)


def _strip_bom(data: bytes) -> bytes:
    """The bytes of a text file without a leading UTF-8 byte-order mark (some Windows editors
    write one); UTF-16/32 text, which numbers cannot be parsed from byte by byte, is refused."""
    if data.startswith(_UTF16_BOMS):
        raise _MalformedError(
            "the file starts with a UTF-16 byte-order mark (UTF-16 text); "
            "save it as UTF-8 or ASCII"
        )
    return data[len(_UTF8_BOM) :] if data.startswith(_UTF8_BOM) else data


def _read_text(path: Path) -> str:
    """A text file decoded as UTF-8 (bad bytes replaced), without a byte-order mark."""
    return _strip_bom(path.read_bytes()).decode("utf-8", errors="replace")


def _text_lines(path: Path) -> list[str]:
    """Non-empty lines of a text file with ``#`` comments removed."""
    return _numbered_text_lines(path)[0]


def _numbered_text_lines(path: Path) -> tuple[list[str], list[int]]:
    """:func:`_text_lines` and their 1-based line numbers in the file (for messages)."""
    text = _read_text(path)
    text = re.sub(r"#[^\n]*", "", text)
    numbered = [(k, ln) for k, ln in enumerate(text.splitlines(), 1) if ln.strip()]
    return [ln for _, ln in numbered], [k for k, _ in numbered]


# --------------------------------------------------------------------------------------------
# OFF
# --------------------------------------------------------------------------------------------

_OFF_HEADER = re.compile(r"^(ST)?(C)?(N)?(4)?(n)?OFF$")


def _read_off(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """ASCII OFF: ``OFF``, ``V F E``, ``V`` vertex lines, ``F`` lines ``n i0 ... i_{n-1}``."""
    lines, numbers = _numbered_text_lines(path)
    if not lines:
        raise _MalformedError("the file is empty")
    head = lines[0].split()
    m = _OFF_HEADER.match(head[0])
    if not m:
        raise _MalformedError(f"the first line must be 'OFF', not {lines[0].strip()[:40]!r}")
    if m.group(4) or m.group(5):
        raise _MalformedError(f"{head[0]} (not 3D) files are not supported; use plain OFF")
    if "BINARY" in (t.upper() for t in head[1:]):
        raise _MalformedError("binary OFF is not supported; save the file as ASCII OFF")
    rest = head[1:]
    body = 1
    if not rest:
        if len(lines) < 2:
            raise _MalformedError("the vertex/face counts are missing after 'OFF'")
        rest, body = lines[1].split(), 2
    try:
        nv, nf = int(rest[0]), int(rest[1])
    except (ValueError, IndexError):
        raise _MalformedError(
            f"bad counts line {' '.join(rest)[:40]!r}; expected 'V F E'"
        ) from None
    if nv < 0 or nf < 0:
        raise _MalformedError("negative vertex or face count")
    if len(lines) < body + nv + nf:
        found = len(lines) - body
        raise _MalformedError(
            f"the header announces {nv} vertices and {nf} faces, but only {found} data lines "
            "follow (the file is truncated)"
        )
    verts = _loadtxt(lines[body : body + nv], "vertex line", numbers[body : body + nv],
                     usecols=(0, 1, 2))
    faces = _polygons_from_lines(lines[body + nv : body + nv + nf], "face line", verts=verts)
    return verts, (faces if nf else None)


# --------------------------------------------------------------------------------------------
# OBJ
# --------------------------------------------------------------------------------------------


def _obj_records(lines: list[str]):
    """``(line number, record)`` of an OBJ file's lines: a line ending in a backslash goes on
    in the next one (the OBJ format's continuation, with which exporters wrap long faces;
    such a file was refused: user test), numbered by its first line."""
    start, held = 0, []
    for lineno, line in enumerate(lines, 1):
        body = line.rstrip()
        if body.endswith("\\") and "#" not in body:
            start = start or lineno
            held.append(body[:-1])
            continue
        if held:
            yield start, " ".join(held + [line])
            start, held = 0, []
        else:
            yield lineno, line
    if held:
        yield start, " ".join(held)


def _read_obj(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """Wavefront OBJ: ``v x y z [w | r g b]`` and ``f a b c ...`` where ``a`` may be ``i``,
    ``i/t``, ``i//n`` or ``i/t/n``, 1-based, negative = relative to the vertices read so far.
    Other statements (``vt``, ``vn``, ``g``, ``usemtl``, ``l``, ...) are ignored. One loop over
    the ``v``/``f`` lines (a backslash at a line's end continues it); coordinates are converted
    in bulk by ``np.loadtxt``."""
    coords: list[str] = []
    coord_lines: list[int] = []  # their line numbers, for messages
    polys: list[list[int]] = []
    text = _read_text(path)
    for lineno, raw in _obj_records(text.splitlines()):
        parts = raw.split("#", 1)[0].split()
        if not parts or parts[0] not in ("v", "f"):
            continue
        if parts[0] == "v":
            if len(parts) < 4:
                raise _MalformedError(f"line {lineno}: a vertex needs x, y, z: {raw.strip()!r}")
            coords.append(" ".join(parts[1:4]))
            coord_lines.append(lineno)
            continue
        try:
            idx = [int(t.split("/", 1)[0]) for t in parts[1:]]
        except ValueError:
            raise _MalformedError(f"line {lineno}: bad face {raw.strip()!r}") from None
        nv = len(coords)
        idx = [i - 1 if i > 0 else nv + i for i in idx]  # 1-based, or relative if negative
        if any(i < 0 or i >= nv for i in idx):
            raise _MalformedError(
                f"line {lineno}: the face refers to a vertex not defined before it"
            )
        if len(idx) >= 3:
            polys.append(idx)
    verts = _loadtxt(coords, "vertex line", coord_lines, usecols=(0, 1, 2))
    if not polys:
        return verts, None
    by_size: dict[int, list[int]] = {}
    for i, poly in enumerate(polys):  # group by polygon size to fan-split in bulk
        by_size.setdefault(len(poly), []).append(i)
    groups = [
        (np.array(ids), np.array([polys[i] for i in ids], dtype=np.int64))
        for ids in by_size.values()
    ]
    return verts, _fan_groups(groups, verts)


def _write_obj(path: Path, v: np.ndarray, f: np.ndarray, uv: np.ndarray | None = None) -> None:
    """ASCII OBJ, bulk formatted with ``np.savetxt``; with ``uv`` a ``vt`` per vertex, the
    faces ``f i/i j/j ...``."""
    with open(path, "w", encoding="ascii", newline="\n") as fh:
        fh.write("# written by TCB Surface\n")
        np.savetxt(fh, v, fmt="v %.17g %.17g %.17g")
        if uv is not None:
            np.savetxt(fh, uv, fmt="vt %.9g %.9g")
        if len(f):
            if uv is None:
                np.savetxt(fh, f + 1, fmt="f" + " %d" * f.shape[1])
            else:
                np.savetxt(fh, np.repeat(f + 1, 2, axis=1), fmt="f" + " %d/%d" * f.shape[1])


# --------------------------------------------------------------------------------------------
# PLY
# --------------------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip


class _PlyElement:
    """One ``element`` of a PLY header: name, count, and its properties in order.

    ``props`` holds ``(name, dtype)`` for scalars and ``(name, (count_dtype, item_dtype))`` for
    lists (dtype strings without byte order).
    """

    def __init__(self, name: str, count: int) -> None:
        self.name, self.count = name, count
        self.props: list[tuple[str, str | tuple[str, str]]] = []

    def has_list(self) -> bool:
        return any(isinstance(t, tuple) for _, t in self.props)

    def min_record_size(self) -> int:
        """Bytes of the smallest binary record: the scalars and the lists' counts (an empty
        list has no items)."""
        return sum(np.dtype(t[0] if isinstance(t, tuple) else t).itemsize for _, t in self.props)


def _ply_header(data: bytes) -> tuple[str, list[_PlyElement], int]:
    """Parse the header; return the format, the elements, and the byte offset of the body."""
    if not data.startswith(b"ply"):
        raise _MalformedError("not a PLY file (it does not start with 'ply')")
    end = re.search(rb"end_header[ \t]*\r?\n", data)
    if end is None:
        raise _MalformedError("the header has no 'end_header' line (truncated or not PLY)")
    fmt = None
    elements: list[_PlyElement] = []
    for raw in data[: end.start()].decode("ascii", errors="replace").splitlines()[1:]:
        t = raw.split()
        if not t or t[0] in ("comment", "obj_info"):
            continue
        if t[0] == "format" and len(t) >= 2:
            fmt = t[1]
        elif t[0] == "element" and len(t) == 3:
            try:
                elements.append(_PlyElement(t[1], int(t[2])))
            except ValueError:
                raise _MalformedError(f"bad header line {raw.strip()!r}") from None
            if elements[-1].count < 0:
                raise _MalformedError(
                    f"bad header line {raw.strip()!r}: an element count cannot be negative"
                )
        elif t[0] == "property" and elements:
            try:
                if t[1] == "list" and len(t) == 5:
                    elements[-1].props.append((t[4], (_PLY_TYPES[t[2]], _PLY_TYPES[t[3]])))
                elif len(t) == 3:
                    elements[-1].props.append((t[2], _PLY_TYPES[t[1]]))
                else:
                    raise KeyError(raw)
            except KeyError:
                raise _MalformedError(f"bad header line {raw.strip()!r}") from None
        else:
            raise _MalformedError(f"bad header line {raw.strip()!r}")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise _MalformedError(f"unknown PLY format {fmt!r}")
    return fmt, elements, end.end()


def _ply_vertices_and_faces(
    tables: dict[str, dict[str, np.ndarray]],
) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Pick ``x, y, z`` of ``vertex`` and the triangles of ``face`` from the parsed tables,
    and which of the three are 32-bit floats (for ``float32_rounding``: x and y may be float
    and z double)."""
    vt = tables.get("vertex")
    if vt is None:
        raise _MalformedError("there is no 'vertex' element")
    missing = [c for c in "xyz" if c not in vt]
    if missing:
        raise _MalformedError(f"the vertex element has no property {', '.join(missing)}")
    single = np.array([vt[c].dtype == np.float32 for c in "xyz"])
    verts = np.column_stack([vt["x"], vt["y"], vt["z"]])  # (float32 kept: read_geometry)
    if verts.dtype != np.float32:
        verts = verts.astype(np.float64)
    ft = tables.get("face")
    if ft is None:
        return verts, None, single
    return verts, _fan_groups(ft.get("__polygons__", []), verts), single


def _face_list_name(el: _PlyElement) -> str | None:
    names = [n for n, t in el.props if isinstance(t, tuple)]
    for want in ("vertex_indices", "vertex_index"):
        if want in names:
            return want
    return None


def _read_ply(path: Path) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """PLY (ascii, binary_little_endian, binary_big_endian)."""
    data = _strip_bom(path.read_bytes())
    fmt, elements, offset = _ply_header(data)
    tables: dict[str, dict[str, np.ndarray]] = {}
    if fmt == "ascii":
        lines = [
            ln for ln in data[offset:].decode("ascii", errors="replace").splitlines() if ln.strip()
        ]
        pos = 0
        for el in elements:
            block = lines[pos : pos + el.count]
            if len(block) < el.count:
                raise _MalformedError(
                    f"the {el.name!r} element announces {el.count} lines but only "
                    f"{len(block)} follow (the file is truncated)"
                )
            pos += el.count
            if el.name in ("vertex", "face"):
                tables[el.name] = _ply_ascii_element(el, block)
    else:
        endian = "<" if fmt == "binary_little_endian" else ">"
        for el in elements:
            table, offset = _ply_binary_element(el, data, offset, endian)
            if el.name in ("vertex", "face"):
                tables[el.name] = table
            if "vertex" in tables and "face" in tables:
                break  # nothing after vertices and faces is needed
    return _ply_vertices_and_faces(tables)


def _ply_ascii_element(el: _PlyElement, block: list[str]) -> dict[str, np.ndarray]:
    """Columns of an ASCII element. Scalars before the first list have fixed columns; for a
    face element the list ``vertex_indices`` is parsed by polygon size (see
    :func:`_polygons_from_lines`)."""
    out: dict[str, np.ndarray] = {}
    fixed = []
    for name, t in el.props:
        if isinstance(t, tuple):
            break
        fixed.append(name)
    if fixed and block:
        cols = _loadtxt(block, f"{el.name} line", usecols=tuple(range(len(fixed))))
        for c, name in enumerate(fixed):
            out[name] = cols[:, c]
    elif fixed:
        for name in fixed:
            out[name] = np.empty(0)
    if el.name == "face":
        lname = _face_list_name(el)
        if lname is None:
            raise _MalformedError("the face element has no list 'vertex_indices' / 'vertex_index'")
        first = [n for n, _ in el.props].index(lname)
        if first != len(fixed):
            raise _MalformedError("a list property before 'vertex_indices' is not supported")
        out["__polygons__"] = _polygon_groups(block, "face line", first_col=first)
    return out


def _ply_binary_element(
    el: _PlyElement, data: bytes, offset: int, endian: str
) -> tuple[dict[str, np.ndarray], int]:
    """Read one binary element at ``offset``; return its columns and the offset after it.

    Elements of scalars and elements whose lists all have the same length are read with one
    structured dtype (``np.frombuffer``). Lists of varying length (e.g. mixed triangles and
    quads) need the record offsets, found by a loop over records; the indices are then
    gathered in bulk per polygon size.
    """
    if el.count == 0:
        return {}, offset
    # before anything is allocated for the announced count: do the records fit at all?
    least = el.min_record_size() * el.count
    if offset + least > len(data):
        raise _MalformedError(
            f"the {el.name!r} data are truncated: {el.count} records need at least {least} "
            f"bytes, {max(len(data) - offset, 0)} present"
        )
    if not el.has_list():
        dt = np.dtype([(n, endian + t) for n, t in el.props])
        arr = _frombuffer(data, dt, el.count, offset, el.name)
        return {n: arr[n] for n in arr.dtype.names}, offset + dt.itemsize * el.count

    # first record: list lengths, to try a fixed-size layout
    sizes = []
    pos = offset
    for _, t in el.props:
        if isinstance(t, tuple):
            cdt = np.dtype(endian + t[0])
            if pos + cdt.itemsize > len(data):
                raise _MalformedError(f"the {el.name!r} data are truncated")
            n = int(np.frombuffer(data, cdt, 1, pos)[0])
            if n < 0:
                raise _MalformedError(f"the {el.name!r} data hold a negative list length {n}")
            sizes.append(n)
            pos += cdt.itemsize + n * np.dtype(t[1]).itemsize
        else:
            pos += np.dtype(t).itemsize
    fields = []
    li = 0
    for name, t in el.props:
        if isinstance(t, tuple):
            fields.append((name + "__n", endian + t[0]))
            fields.append((name, endian + t[1], (sizes[li],)))
            li += 1
        else:
            fields.append((name, endian + t))
    dt = np.dtype(fields)
    fits = offset + dt.itemsize * el.count <= len(data)
    arr = np.frombuffer(data, dt, el.count, offset) if fits else None
    list_names = [name for name, t in el.props if isinstance(t, tuple)]
    uniform = arr is not None and all(
        np.all(arr[name + "__n"] == s) for name, s in zip(list_names, sizes, strict=True)
    )
    out: dict[str, np.ndarray] = {}
    if uniform:
        for name, _ in el.props:
            out[name] = arr[name]
        end = offset + dt.itemsize * el.count
    else:
        out, end = _ply_binary_ragged(el, data, offset, endian)
    if el.name == "face":
        lname = _face_list_name(el)
        if lname is None:
            raise _MalformedError("the face element has no list 'vertex_indices' / 'vertex_index'")
        idx = out[lname]
        if isinstance(idx, np.ndarray):
            out["__polygons__"] = [(np.arange(el.count), idx.reshape(el.count, -1))]
        else:  # ragged: size -> (face numbers, (m, size) indices)
            out["__polygons__"] = list(idx.values())
    return out, end


def _ply_binary_ragged(el: _PlyElement, data: bytes, offset: int, endian: str) -> tuple[dict, int]:
    """Binary element with lists of varying length: loop over records to find offsets."""
    n = el.count
    total = len(data)
    # per property: offsets (and counts for lists) of every record
    starts = {name: np.empty(n, dtype=np.int64) for name, _ in el.props}
    counts = {name: np.empty(n, dtype=np.int64) for name, t in el.props if isinstance(t, tuple)}
    layout = []
    for name, t in el.props:
        if isinstance(t, tuple):
            c = np.dtype(endian + t[0])
            layout.append(
                (
                    name,
                    True,
                    struct.Struct(endian + c.char).unpack_from,
                    c.itemsize,
                    np.dtype(t[1]).itemsize,
                )
            )
        else:
            layout.append((name, False, None, np.dtype(t).itemsize, 0))
    pos = offset
    try:
        for r in range(n):
            for name, is_list, unpack, size, item in layout:
                starts[name][r] = pos
                if is_list:
                    k = unpack(data, pos)[0]
                    if k < 0:
                        raise _MalformedError(
                            f"the {el.name!r} data hold a negative list length {k}"
                        )
                    counts[name][r] = k
                    pos += size + k * item
                else:
                    pos += size
    except struct.error:
        raise _MalformedError(f"the {el.name!r} data are truncated") from None
    if pos > total:
        raise _MalformedError(f"the {el.name!r} data are truncated")
    buf = np.frombuffer(data, np.uint8)
    out: dict = {}
    for name, t in el.props:
        if isinstance(t, tuple):
            item = np.dtype(endian + t[1])
            csize = np.dtype(t[0]).itemsize
            groups = {}
            for k in np.unique(counts[name]):
                ids = np.flatnonzero(counts[name] == k)
                k = int(k)
                byte = (
                    starts[name][ids, None, None]
                    + csize
                    + np.arange(k)[None, :, None] * item.itemsize
                    + np.arange(item.itemsize)[None, None, :]
                )
                raw = np.ascontiguousarray(buf[byte]).view(item).reshape(len(ids), k)
                groups[k] = (ids, raw.astype(np.int64))
            out[name] = groups
        else:
            dt = np.dtype(endian + t)
            byte = starts[name][:, None] + np.arange(dt.itemsize)[None, :]
            out[name] = np.ascontiguousarray(buf[byte]).view(dt).reshape(n)
    return out, pos


def _frombuffer(data: bytes, dt: np.dtype, count: int, offset: int, what: str) -> np.ndarray:
    need = dt.itemsize * count
    if offset + need > len(data):
        raise _MalformedError(
            f"the {what!r} data are truncated: {need} bytes expected, "
            f"{max(len(data) - offset, 0)} present"
        )
    return np.frombuffer(data, dt, count, offset)


def _write_ply(path: Path, v: np.ndarray, f: np.ndarray, uv: np.ndarray | None = None) -> None:
    """Binary little-endian PLY: ``double x, y, z`` (with ``uv``: and ``float s, t``); face
    list ``uchar`` count, ``int`` index."""
    header = (
        "ply\nformat binary_little_endian 1.0\ncomment written by TCB Surface\n"
        f"element vertex {len(v)}\nproperty double x\nproperty double y\nproperty double z\n"
        + ("property float s\nproperty float t\n" if uv is not None else "")
        + f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n"
    )
    if uv is not None:
        rows = np.empty(len(v), dtype=np.dtype([("p", "<f8", (3,)), ("t", "<f4", (2,))]))
        rows["p"], rows["t"] = v, uv
        v = rows
    k = f.shape[1]
    rec = np.empty(len(f), dtype=np.dtype([("n", "u1"), ("i", "<i4", (k,))]))
    rec["n"] = k
    rec["i"] = f
    with open(path, "wb") as fh:
        fh.write(header.encode("ascii"))
        fh.write(v.tobytes() if uv is not None else np.ascontiguousarray(v, dtype="<f8").tobytes())
        fh.write(rec.tobytes())


# --------------------------------------------------------------------------------------------
# Point clouds: text columns, .npy, .npz
# --------------------------------------------------------------------------------------------


_COUNT_LINE = re.compile(r"\s*\d+\s*")


def _skip_point_counts(lines: list[str], numbers: list[int]) -> tuple[list[str], list[int]]:
    """The lines (and their line numbers ``numbers``) without the point counts of a Leica
    ``.pts`` file: a first line holding a lone integer, and, in a file of several scans one
    after the other, the count before each scan (found by following the counts). A count
    beyond the lines left means a truncated file; lines after the counted ones are kept as
    points."""
    pos, kept = 0, []
    while pos < len(lines) and _COUNT_LINE.fullmatch(lines[pos]):
        n = int(lines[pos])
        if pos + 1 + n > len(lines):
            raise _MalformedError(
                f"a point count line says {n} points but {len(lines) - pos - 1} lines follow "
                "(the file is truncated)"
            )
        kept.append(range(pos + 1, pos + 1 + n))
        pos += 1 + n
    if pos == 0:
        return lines, numbers
    rows = [k for scan in kept for k in scan] + list(range(pos, len(lines)))
    return [lines[k] for k in rows], [numbers[k] for k in rows]


def _read_xyz(path: Path) -> tuple[np.ndarray, None]:
    """Text columns: whitespace, comma or semicolon separated; the first three are x, y, z
    (with semicolons, or between whitespace, a decimal comma is read as a point: a
    spreadsheet's CSV or a scanner's export in many locales). A first line holding a lone
    integer is a point count (Leica ``.pts``) and is skipped."""
    lines, numbers = _skip_point_counts(*_numbered_text_lines(path))
    if not lines:
        raise _MalformedError("the file has no data lines")
    data = lines[1:3] or lines[:1]  # the separator of the data lines (line 0 may be a header)
    if all(";" in ln for ln in data):
        delim = ";"
        if any("," in ln for ln in lines[1:]):  # decimal commas (a header's do not count)
            lines = lines[:1] + [ln.replace(",", ".") for ln in lines[1:]]
            if not any(c.isalpha() for c in lines[0]):
                lines[0] = lines[0].replace(",", ".")
    elif (all(_decimal_comma_fields(ln) for ln in data)
          and any("," in ln for ln in lines[:3])):
        # whitespace columns with decimal commas ('1,5 2,0 3,25': a European locale's export;
        # read as commas, its first line was taken for a header and the next one refused)
        delim = None
        lines = [ln.replace(",", ".") if _decimal_comma_fields(ln) else ln for ln in lines]
    else:
        # from the data lines (a header 'x, y, z' over whitespace columns had made the
        # commas the separator, and every line was refused: user test)
        delim = "," if any("," in ln for ln in data) else None
    cols = (0, 1, 2)
    try:
        [float(t) for t in (lines[0].split(delim))[:3]]
    except ValueError:
        header, lines = lines[0], lines[1:]  # a header line such as 'x,y,z'
        numbers = numbers[1:]
        if lines and len(header.split(delim)) == len(lines[0].split(delim)):
            cols = _header_columns(header, delim)  # (its names, when they line up)
    if not lines:
        raise _MalformedError("the file has no data lines")
    if len(lines[0].split(delim)) < 3:  # (a header's columns: as many as the data's)
        raise _MalformedError("each line needs at least three numbers (x, y, z)")
    return _loadtxt(lines, "line", numbers, usecols=cols, delimiter=delim), None


_DECIMAL_COMMA = re.compile(r"[+-]?\d+(,\d+)?([eE][+-]?\d+)?")


def _decimal_comma_fields(line: str) -> bool:
    """The line holds at least three whitespace-separated numbers, which may be written with a
    decimal comma ('1,5 2 -3,25e2'); comma-separated values ('1, 2, 3', '1,2,3') do not."""
    fields = line.split()
    return len(fields) >= 3 and all(_DECIMAL_COMMA.fullmatch(f) for f in fields)


# header names of the coordinate columns (lowercase, after units such as '[m]' are cut off):
# the letters first, then the words GIS exports use
_AXIS_NAMES = (("x", "lon", "long", "longitude", "easting", "east"),
               ("y", "lat", "latitude", "northing", "north"),
               ("z", "elev", "elevation", "height", "alt", "altitude", "h"))


def _header_columns(header: str, delim: str | None) -> tuple[int, int, int]:
    """The columns of x, y, z that a text file's header line names (``x``, ``X [m]``,
    ``//X`` as CloudCompare writes it, ``point_x``, ``lon``/``lat``/``elevation`` ...), or the
    first three when it names none of them. A header ``id,x,y,z`` (GIS exports; pandas'
    ``to_csv`` writes ``,x,y,z``) had been read as x = id, y = x, z = y and fitted with no
    word (user test). Names that agree with the first three columns keep them (``x,y,depth``,
    ``E N H``, ``lon,lat,value``); one that names some coordinates elsewhere but not all three
    is refused: which column is the third cannot be told. The caller uses it only when the
    header has as many fields as the data lines (``X [m] Y [m] Z [m]`` separated by spaces
    has more: the first three columns; review)."""
    names = [re.match(r"[\s\"'/#]*(\w*)", f).group(1).lower() for f in header.split(delim)]
    names = [n[-2:].lstrip("_") if re.fullmatch(r"\w+_[xyz]", n) else n for n in names]
    found = [next((names.index(w) for w in words if w in names), None) for words in _AXIS_NAMES]
    if all(a is None or a == k for k, a in enumerate(found)):
        return (0, 1, 2)
    if any(a is None for a in found) or len(set(found)) < 3:
        named = ", ".join(f"{'xyz'[k]} in column {a + 1}" for k, a in enumerate(found)
                          if a is not None)
        raise _MalformedError(
            f"the header line {header.strip()[:60]!r} names {named} but not all three "
            "coordinates: name the columns x, y and z (or remove the header to use the "
            "first three columns)")
    return tuple(found)


_NPY_MAGIC = b"\x93NUMPY"
_ZIP_MAGIC = (b"PK\x03\x04", b"PK\x05\x06")  # a zip's first entry, or an empty zip


def _check_npy_size(fh, size: int, what: str) -> None:
    """Refuse a ``.npy`` stream whose header announces more data than the ``size`` bytes it
    has (a truncated file), before numpy allocates the announced array. ``fh`` is at the
    magic string; format 3.0 headers (rare) are left to numpy."""
    version = np.lib.format.read_magic(fh)
    if version == (1, 0):
        shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
    elif version == (2, 0):
        shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
    else:
        return
    if dtype.hasobject:
        return  # refused by np.load(allow_pickle=False)
    need = math.prod(shape) * dtype.itemsize
    have = size - fh.tell()
    if need > have:
        raise _MalformedError(
            f"{what} is truncated: its header announces shape {shape} of {dtype} ({need} bytes) "
            f"but {have} bytes follow"
        )


def _read_npy(path: Path) -> tuple[np.ndarray, None]:
    """An array saved by ``np.save``: an empty, truncated or foreign file is refused before
    numpy reads it (numpy would raise EOFError, or try to unpickle it)."""
    with open(path, "rb") as fh:
        magic = fh.read(len(_NPY_MAGIC))
        if not magic:
            raise _MalformedError("the file is empty")
        if magic != _NPY_MAGIC:
            hint = "; it is a zip archive: name it .npz" if magic.startswith(_ZIP_MAGIC) else ""
            raise _MalformedError(f"not a NumPy .npy file (no .npy header){hint}")
        fh.seek(0)
        _check_npy_size(fh, os.fstat(fh.fileno()).st_size, "the array")
        fh.seek(0)
        arr = np.load(fh, allow_pickle=False)
    return _points_array(arr, "the array"), None


def _points_array(arr: np.ndarray, what: str) -> np.ndarray:
    """The first three columns of an ``(N, k >= 3)`` array of real numbers, as float64. A wide
    array (more columns than rows, more than 3) is refused as transposed: points are rows."""
    if np.iscomplexobj(arr):
        raise _MalformedError(
            f"{what} holds complex numbers ({arr.dtype}); coordinates must be real numbers"
        )
    if arr.ndim == 2 and arr.shape[0] < arr.shape[1] and arr.shape[1] > 3:
        raise _MalformedError(
            f"{what} has shape {arr.shape}: it looks transposed (points must be rows, an "
            "(N, 3) array); save its transpose, array.T"
        )
    if arr.ndim != 2 or arr.shape[1] < 3 or not np.issubdtype(arr.dtype, np.number):
        raise _MalformedError(
            f"{what} must be an (N, 3) array of numbers; got shape {arr.shape}, type {arr.dtype}"
        )
    return arr[:, :3] if arr.dtype == np.float32 else arr[:, :3].astype(np.float64)


def _npz_array(z, key: str) -> np.ndarray:
    """Array ``key`` of an open ``.npz``, its size checked against its member's first."""
    name = key + ".npy"
    if name not in z.zip.namelist():
        raise _MalformedError(f"{key!r} is not a NumPy array (the member {key!r} has no .npy)")
    with z.zip.open(name) as fh:
        _check_npy_size(fh, z.zip.getinfo(name).file_size, repr(key))
    return z[key]


def _read_npz(path: Path, keep_fill_values: bool = False
              ) -> tuple[np.ndarray, np.ndarray | None]:
    """``points`` (+ optional ``faces``), or a DEM (``elevation`` + ``xmin..ymax``; with
    ``keep_fill_values`` see :func:`read_geometry`). A file that is not a zip archive, or a
    damaged or truncated one, is refused with a message."""
    with open(path, "rb") as fh:
        magic = fh.read(len(_NPY_MAGIC))
    if not magic:
        raise _MalformedError("the file is empty")
    if not magic.startswith(_ZIP_MAGIC):
        hint = "; it is a single array: name it .npy" if magic == _NPY_MAGIC else ""
        raise _MalformedError(f"not a NumPy .npz file (not a zip archive){hint}")
    try:
        with np.load(path, allow_pickle=False) as z:
            keys = set(z.files)
            if "points" in keys:
                pts = _points_array(_npz_array(z, "points"), "'points'")
                if "faces" not in keys:
                    return pts, None
                f = _npz_array(z, "faces")
                if f.ndim != 2 or f.shape[1] < 3:
                    raise _MalformedError(
                        f"'faces' must be an (F, 3) integer array; got shape {f.shape}")
                # whole numbers stored as floats are indices too, as fit_surface takes them
                # (the reader had refused them naming the shape, which was right: user test)
                if not np.issubdtype(f.dtype, np.integer):
                    if not np.issubdtype(f.dtype, np.floating):
                        raise _MalformedError(
                            f"'faces' must hold whole vertex indices; got values of type "
                            f"{f.dtype}")
                    bad = ~(np.isfinite(f) & (f == np.round(f)) & (np.abs(f) < 2.0**53))
                    if bad.any():  # (1e20 had passed and been cast to -9.2e18: review)
                        raise _MalformedError(
                            f"'faces' must hold whole vertex indices; got {f[bad].flat[0]!r} "
                            f"({int(bad.sum())} such values)")
                return pts, _concave_split(pts, f.astype(np.int64))
            if "elevation" in keys:
                return _dem_points({k: _npz_array(z, k) for k in keys},
                                   keep_fill_values), None
    except (zipfile.BadZipFile, zlib.error, EOFError) as exc:
        raise _MalformedError(f"the zip archive is damaged or truncated ({exc})") from None
    raise _MalformedError(
        f"expected key 'points' (and optional 'faces') or a DEM with 'elevation'; found keys "
        f"{sorted(keys)}"
    )


def _is_number(word: str) -> bool:
    try:
        float(word)
    except ValueError:
        return False
    return True


# the header keys of an ESRI ASCII grid (lower case)
_ASC_KEYS = ("ncols", "nrows", "xllcorner", "yllcorner", "xllcenter", "yllcenter", "cellsize",
             "dx", "dy", "nodata_value")


def _read_asc(path: Path, keep_fill_values: bool = False
              ) -> tuple[np.ndarray, np.ndarray | None]:
    """An ESRI ASCII grid (``.asc``, GDAL's AAIGrid: what GIS tools export a DEM as): a header
    of ``ncols``, ``nrows``, ``xllcorner``/``yllcorner`` (the lower-left corner of the
    lower-left cell) or ``xllcenter``/``yllcenter`` (its centre), ``cellsize`` (or GDAL's
    ``dx`` and ``dy``) and an optional ``NODATA_value``, one ``key value`` per line in any
    case, then ``nrows`` rows of ``ncols`` heights, the first row the northern edge. The
    nodes are the cells' centres, as the DEM ``.npz`` with a ``geotransform`` reads them
    (:func:`_dem_points`: units, no-data cells and fill values alike)."""
    lines = _read_text(path).splitlines()
    first = next((ln.split() for ln in lines if ln.split()), [""])
    if first[0].lower() not in _ASC_KEYS:
        # (.asc is also what CloudCompare, Geomagic and Leica call x y z text: read as such)
        return _read_xyz(path)
    header: dict[str, float] = {}
    start = 0
    for start, line in enumerate(lines):
        parts = line.split()
        if not parts:
            continue
        key = parts[0].lower()
        if key not in _ASC_KEYS:
            break
        if len(parts) != 2:
            raise _MalformedError(f"line {start + 1}: expected '{parts[0]} <number>'")
        try:
            header[key] = float(parts[1])
        except ValueError:
            raise _MalformedError(f"line {start + 1}: {parts[0]} must be a number, got "
                                  f"{parts[1]!r}") from None
    else:
        start = len(lines)
    missing = [k for k in ("ncols", "nrows") if k not in header]
    if "cellsize" not in header and not {"dx", "dy"} <= header.keys():
        missing.append("cellsize")
    for axis in "xy":
        if f"{axis}llcorner" not in header and f"{axis}llcenter" not in header:
            missing.append(f"{axis}llcorner")
    if missing:
        raise _MalformedError(f"not an ESRI ASCII grid: its header has no {', '.join(missing)} "
                              "(ncols, nrows, xllcorner, yllcorner, cellsize, NODATA_value)")
    cols, rows = header["ncols"], header["nrows"]
    if not (np.isfinite([cols, rows]).all() and cols == int(cols) and rows == int(rows)
            and cols >= 2 and rows >= 2):
        raise _MalformedError(f"ncols and nrows must be whole numbers of at least 2; got "
                              f"{cols:g} and {rows:g}")
    cols, rows = int(cols), int(rows)
    dx = header.get("dx", header.get("cellsize"))
    dy = header.get("dy", header.get("cellsize"))
    if not (dx > 0 and dy > 0 and np.isfinite([dx, dy]).all()):
        raise _MalformedError(f"the cell size must be positive; got {dx:g} x {dy:g}")
    x0 = header["xllcorner"] if "xllcorner" in header else header["xllcenter"] - dx / 2
    y0 = header["yllcorner"] if "yllcorner" in header else header["yllcenter"] - dy / 2
    body = "\n".join(lines[start:])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # (it stops at a bad value: below)
        values = np.fromstring(body, dtype=np.float64, sep=" ")  # (no string per value)
    if values.size != rows * cols:
        bad = next((w for w in body.split() if not _is_number(w)), None)  # (errors only)
        if bad is not None:
            raise _MalformedError(f"the heights after the header must be numbers; got {bad!r}")
        short = " (truncated?)" if values.size < rows * cols else ""
        raise _MalformedError(f"the header says {rows} rows of {cols} heights ({rows * cols}), "
                              f"but {values.size} follow it{short}")
    grid = {"elevation": values.reshape(rows, cols),
            "geotransform": np.array([x0, dx, 0.0, y0 + rows * dy, 0.0, -dy])}
    if "nodata_value" in header:
        grid["nodata"] = np.array(header["nodata_value"])
    return _dem_points(grid, keep_fill_values), None


def _dem_points(z: dict[str, np.ndarray], keep_fill_values: bool = False) -> np.ndarray:
    """Grid points of a DEM: ``elevation`` (rows, cols), bounds ``xmin, xmax, ymin, ymax``.

    Column ``j`` is at ``x = linspace(xmin, xmax, cols)[j]`` and row ``i`` at
    ``y = linspace(ymin, ymax, rows)[i]`` as stored (the jacksboro file stores the northern
    latitude as ``ymin``: its row 0 is the northern edge, so the order is kept, not sorted).
    With optional cell sizes ``dx``, ``dy`` that say the bounds are the grid's outer edges
    (``cols dx = |xmax - xmin|``: a pixel-registered grid, as the jacksboro file is) the
    nodes are the cells' centres, ``xmin + (j + 1/2) (xmax - xmin) / cols``; a cell size
    that fits neither (nor ``(cols - 1) dx``) is an error. A negative cell size says which
    way the rows (columns) run whatever the order of the bounds: ``dy < 0``, as GDAL writes
    a north-up raster, puts row 0 at the larger y (a north-up grid saved with ``ymin <
    ymax`` and a positive ``dy`` was read mirrored north-south: user test).

    Instead of the bounds, the raster's affine transform: ``transform`` as rasterio gives it
    (``a, b, c, d, e, f``, 6 or 9 numbers: ``x = a col + b row + c``, ``y = d col + e row +
    f`` at the cells' corners) or ``geotransform`` as GDAL gives it (``c, a, b, f, d, e``);
    the nodes are the cells' centres (``col = j + 1/2``, ``row = i + 1/2``).

    Geographic grids (bounds in degrees: |x| <= 180, |y| <= 90, and an elevation range larger
    than 10x the extent in degrees, i.e. heights in metres) are converted to metres relative to
    the south-west corner, ``x' = (x - x0) * 111200 cos(lat_mid)``, ``y' = (y - y0) * 111200``;
    an optional key ``units`` (``'degrees'`` or ``'metres'``) overrides the guess. Non-finite
    elevations (no data) are skipped, and so are values equal to an optional ``nodata`` key.
    Without that key, cells at a common fill value far below all others are refused
    (:func:`_refuse_fill_values`), or with ``keep_fill_values`` returned as points for the
    caller to leave out; they are no relief in the guess of the units either way.
    """
    elev = np.asarray(z["elevation"])
    if elev.ndim != 2 or min(elev.shape) < 2 or not np.issubdtype(elev.dtype, np.number):
        raise _MalformedError(f"'elevation' must be a 2D grid of numbers; got shape {elev.shape}")
    rows, cols = elev.shape
    affine = _dem_affine(z)
    if affine is not None:
        a, b, c, d, e, f = affine
        jj, ii = np.meshgrid(np.arange(cols) + 0.5, np.arange(rows) + 0.5)
        gx, gy = a * jj + b * ii + c, d * jj + e * ii + f
        corners = np.array([[a * u + b * v + c, d * u + e * v + f]
                            for u in (0, cols) for v in (0, rows)])
        (xmin, ymin), (xmax, ymax) = corners.min(axis=0), corners.max(axis=0)
    else:
        try:
            xmin, xmax, ymin, ymax = (float(z[k]) for k in ("xmin", "xmax", "ymin", "ymax"))
        except KeyError as exc:
            raise _MalformedError(
                f"the DEM needs keys xmin, xmax, ymin, ymax (or the raster's transform); {exc} "
                "is missing") from None
        except (TypeError, ValueError):
            raise _MalformedError("the DEM bounds xmin, xmax, ymin, ymax must be numbers") from None
        gx, gy = np.meshgrid(_dem_nodes(xmin, xmax, cols, z.get("dx"), "x"),
                             _dem_nodes(ymin, ymax, rows, z.get("dy"), "y"))
    h = elev.astype(np.float64)
    fill = np.zeros(h.shape, dtype=bool)  # cells at a fill value, without a 'nodata' key
    if "nodata" not in z:
        finite = np.isfinite(h)
        if not keep_fill_values:
            _refuse_fill_values(h[finite])
        found = fill_value_rows(h[finite].reshape(-1, 1))
        if found is not None:
            fill[finite] = found[0]
    units = str(z["units"]) if "units" in z else "auto"
    if units not in ("auto", "degrees", "metres", "meters"):
        raise _MalformedError(f"unknown DEM units {units!r}; use 'degrees' or 'metres'")
    if units == "auto":
        extent = max(abs(xmax - xmin), abs(ymax - ymin))
        finite = h[np.isfinite(h) & ~fill]
        if "nodata" in z:  # (its -9999 made a small metric grid's relief look like metres)
            finite = finite[finite != float(z["nodata"])]
        relief = float(np.ptp(finite)) if finite.size else 0.0
        geographic = (
            max(abs(xmin), abs(xmax)) <= 180.0
            and max(abs(ymin), abs(ymax)) <= 90.0
            and relief > 10.0 * extent
        )
        units = "degrees" if geographic else "metres"
    if units == "degrees":
        lat_mid = np.radians(0.5 * (ymin + ymax))
        gx = (gx - min(xmin, xmax)) * _METRES_PER_DEGREE * np.cos(lat_mid)
        gy = (gy - min(ymin, ymax)) * _METRES_PER_DEGREE
        # said, with the origin: the result is in metres from it, not on the map (user test)
        warnings.warn(
            f"the DEM's bounds are in degrees: its nodes were converted to metres east and "
            f"north of its south-west corner (longitude {min(xmin, xmax):.6f}, latitude "
            f"{min(ymin, ymax):.6f}; {_METRES_PER_DEGREE:g} m per degree of latitude, times "
            f"cos({np.degrees(lat_mid):.4f} deg) of longitude), so the surface is in those "
            "units; save the DEM with units='metres' and projected bounds to keep map "
            "coordinates", RuntimeWarning, stacklevel=2)
    pts = np.column_stack([gx.ravel(), gy.ravel(), h.ravel()])
    keep = np.isfinite(pts[:, 2])
    if "nodata" in z:
        keep &= pts[:, 2] != float(z["nodata"])
    return pts[keep]


def _dem_affine(z: dict) -> tuple | None:
    """The DEM's ``transform`` (rasterio's order) or ``geotransform`` (GDAL's) as rasterio's
    ``(a, b, c, d, e, f)``, or None when it has neither."""
    for key in ("transform", "geotransform"):
        if key not in z:
            continue
        try:
            t = np.asarray(z[key], dtype=np.float64).ravel()
        except (TypeError, ValueError):
            t = np.zeros(0)
        sizes, order = ((6, 9), "a, b, c, d, e, f as rasterio gives it") if key == "transform" \
            else ((6,), "as GDAL gives it")
        if len(t) not in sizes or not np.isfinite(t).all():
            raise _MalformedError(f"the DEM's {key} must be {' or '.join(map(str, sizes))} "
                                  f"finite numbers ({order})")
        if key == "transform" and (t[1] or t[3]) and not (t[2] or t[4]):
            # rotated in rasterio's order, axis-aligned in GDAL's: GetGeoTransform()'s six
            # numbers saved as 'transform' (review: read as a grid of 500 km cells)
            raise _MalformedError(
                "the DEM's transform looks like GDAL's geotransform (origin x, cell width, 0, "
                "origin y, 0, cell height): save it as 'geotransform', or give rasterio's "
                "transform (a, b, c, d, e, f)")
        a, b, c, d, e, f = t[:6] if key == "transform" else t[[1, 2, 0, 4, 5, 3]]
        if a * e - b * d == 0:
            raise _MalformedError(f"the DEM's {key} maps the grid onto a line (zero determinant)")
        return a, b, c, d, e, f
    return None


def _dem_nodes(lo: float, hi: float, count: int, cell, axis: str) -> np.ndarray:
    """The ``count`` node coordinates of a DEM axis with bounds ``lo``, ``hi`` (in the order
    stored) and an optional cell size ``cell``: the bounds themselves are the first and last
    nodes, unless ``count cell`` spans them (the bounds are the outer cell edges: the nodes
    are the cells' centres). The user test found the jacksboro grid stretched by 1/402 and
    1/343 (75 m over the tile) when its edges were taken for nodes."""
    if cell is None:
        return np.linspace(lo, hi, count)
    try:
        cell = float(np.asarray(cell))
    except (TypeError, ValueError):
        raise _MalformedError(f"the DEM cell size d{axis} must be a number") from None
    if cell < 0:  # the nodes run towards the smaller coordinate (GDAL's north-up rows)
        lo, hi = max(lo, hi), min(lo, hi)
    cell = abs(cell)
    span = hi - lo
    tol = 1e-6 * max(abs(span), 1e-300)
    if abs(count * cell - abs(span)) <= tol:  # the bounds are the outer edges of the cells
        return lo + (np.arange(count) + 0.5) * (span / count)
    if abs((count - 1) * cell - abs(span)) <= tol:  # the bounds are the first and last nodes
        return np.linspace(lo, hi, count)
    raise _MalformedError(
        f"the DEM cell size d{axis} = {cell:g} fits neither its {count} cells between "
        f"{axis}min and {axis}max ({abs(span):g} / {count} = {abs(span) / count:g}) nor its "
        f"{count} nodes ({abs(span):g} / {count - 1} = {abs(span) / max(count - 1, 1):g}); "
        f"correct d{axis} or the bounds, or leave d{axis} out"
    )


# fill values of DEM formats (GDAL/ESRI -9999, SRTM -32768, float32 lowest) for cells without data
def _refuse_fill_values(h: np.ndarray) -> None:
    """A DEM without a ``nodata`` key whose lowest elevation is a common fill value far (over
    1000 units) below all others: its cells have no data, and fitted as terrain they would pull
    the surface down and set the diagonal a relative tolerance is measured against."""
    found = fill_value_rows(np.asarray(h, dtype=np.float64).reshape(-1, 1))
    if found is not None:
        rows, _, low, lowest = found
        raise _MalformedError(
            f"{int(rows.sum())} of the DEM's {rows.size} cells are {low:g}, far below all "
            f"others (lowest {lowest:g}): a no-data fill value; store it as the key 'nodata' "
            f"(np.savez(..., nodata={low:g})) or set those cells to NaN"
        )


_READERS = {
    ".off": _read_off,
    ".obj": _read_obj,
    ".ply": _read_ply,
    ".xyz": _read_xyz,
    ".txt": _read_xyz,
    ".csv": _read_xyz,
    ".pts": _read_xyz,
    ".npy": _read_npy,
    ".npz": _read_npz,
    ".asc": _read_asc,
}
