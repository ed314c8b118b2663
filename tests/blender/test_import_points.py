"""Import Points (File > Import > TCB Points): point files Blender cannot import (.xyz text
columns, an ESRI ASCII grid DEM, NumPy arrays) read by the engine's reader and made a vertex
mesh that Fit Surface takes as it is; map coordinates far from the world origin keep the file's
precision (the object at an offset, the vertices relative to it)."""

from __future__ import annotations

import importlib
import re
import sys
import warnings
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scenes import ADDON, core_module, fit, grid, positions, select, spline_of  # noqa: E402

UTM = np.array([350000.0, 4100000.0, 0.0])
CORNER = UTM + [0.37, 0.21, 0.0]  # (not on float32's lattice there: 1/32 and 1/2 apart)


def meshio():
    """The installed engine's reader module."""
    return importlib.import_module(ADDON + ".core.meshio")


def import_points(bpy, path, *selected, **props):
    with bpy.context.temp_override(**select(bpy, *selected)):
        return bpy.ops.tcb.import_points(filepath=str(path), **props)


def import_into(bpy, name, path, exclude=False):
    """import_points with a new collection ``name`` the active one (excluded from the view
    layer with ``exclude``), the scene's collection active again after."""
    bpy.context.scene.collection.children.link(bpy.data.collections.new(name))
    layer = bpy.context.view_layer.layer_collection.children[name]
    bpy.context.view_layer.active_layer_collection = layer
    layer.exclude = exclude
    try:
        return import_points(bpy, path)
    finally:
        bpy.context.view_layer.active_layer_collection = bpy.context.view_layer.layer_collection


def world(obj) -> np.ndarray:
    """The object's vertices in world space, in float64 (its matrix applied in numpy)."""
    m = np.array(obj.matrix_world, dtype=np.float64)
    return positions(obj) @ m[:3, :3].T + m[:3, 3]


def read(path):
    """The installed engine's reading of ``path`` (points, faces)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return meshio().read_geometry(path)


def heights(x, y):
    return 3.0 * np.sin(x / 40.0) * np.cos(y / 55.0) + 0.01 * x


def write_asc(path, rows=14, cols=17, x0=CORNER[0], y0=CORNER[1], cell=10.0, fill=None):
    """An ESRI ASCII grid of :func:`heights` (row 0 the northern edge); ``fill``: a cell at
    -9999 (no NODATA_value in the header when ``fill == "bare"``)."""
    j, i = np.meshgrid(np.arange(cols), np.arange(rows))
    z = heights((j + 0.5) * cell, (rows - i - 0.5) * cell) + 100.0
    if fill is not None:
        z[3, 4] = -9999.0
    head = (f"ncols {cols}\nnrows {rows}\nxllcorner {x0:.3f}\nyllcorner {y0:.3f}\n"
            f"cellsize {cell:g}\n" + ("" if fill == "bare" else "NODATA_value -9999\n"))
    path.write_text(head + "\n".join(" ".join(f"{v:.6f}" for v in r) for r in z) + "\n")
    return path


def assert_georeferenced_exactly(obj, expected):
    """World coordinates equal the file's within 1e-6 relative, and within 1e-6 of the data's
    extent (32-bit floats at 4.1e6 are 0.5 apart: only vertices relative to an origin near the
    data pass this)."""
    got = world(obj)
    assert got.shape == expected.shape
    assert np.allclose(got, expected, rtol=1e-6, atol=0)
    extent = float(np.ptp(expected, axis=0).max())
    assert np.abs(got - expected).max() <= 1e-6 * extent


def test_menu_entry_and_file_filter_cover_the_reader(installed, addon):
    bpy = installed
    ops = sys.modules[ADDON + ".tcb_addon.operators"]
    assert set(ops.POINT_EXTENSIONS) == set(meshio().READ_EXTENSIONS)
    glob = bpy.ops.tcb.import_points.get_rna_type().properties["filter_glob"].default
    assert set(glob.split(";")) == {f"*{e}" for e in ops.POINT_EXTENSIONS}
    assert "TCB_OT_import_points" in ops.menu_import.__code__.co_names
    assert bpy.ops.tcb.import_points.get_rna_type().name == "Import Points"


def test_an_xyz_file_becomes_a_vertex_mesh_that_fit_surface_fits(clean_scene, tmp_path, capfd):
    bpy = clean_scene
    rng = np.random.default_rng(1)
    xy = rng.random((600, 2)) * 100.0
    pts = np.c_[xy, heights(xy[:, 0], xy[:, 1])]
    path = tmp_path / "scan.xyz"
    path.write_text("X Y Z\n" + "\n".join(f"{x:.9f} {y:.9f} {z:.9f}" for x, y, z in pts) + "\n")
    other = bpy.data.objects.new("Other", None)
    bpy.context.scene.collection.objects.link(other)
    capfd.readouterr()
    assert import_points(bpy, path, other) == {"FINISHED"}
    assert "Imported 600 points from scan.xyz" in capfd.readouterr().out

    obj = bpy.context.view_layer.objects.active
    assert obj.name == "scan" and obj.type == "MESH" and obj.tcb.role == "NONE"
    assert obj.select_get() and not other.select_get()
    assert obj.name in bpy.context.scene.collection.objects  # (the active collection)
    assert len(obj.data.vertices) == 600 and len(obj.data.polygons) == 0
    assert np.array_equal(np.array(obj.matrix_world), np.eye(4))  # near the origin: no offset
    assert_georeferenced_exactly(obj, read(path)[0])
    assert np.allclose(world(obj), pts, rtol=1e-6, atol=1e-6)

    # Fit Surface takes it as it is (a point cloud)
    assert fit(bpy, obj) == {"FINISHED"}
    surface = bpy.context.view_layer.objects.active
    assert surface.tcb.role == "SURFACE"
    assert [s.object for s in surface.tcb.sources] == [obj]


def test_a_utm_dem_keeps_the_file_s_precision_and_fits(clean_scene, tmp_path, capfd):
    bpy = clean_scene
    path = write_asc(tmp_path / "dem.asc", fill="nodata")
    expected = read(path)[0]
    assert len(expected) == 14 * 17 - 1  # (the NODATA cell is no point)
    # the grid's first node (the north-west cell's centre), independently of the reader
    assert np.allclose(expected[0], [CORNER[0] + 5.0, CORNER[1] + 13.5 * 10.0,
                                     heights(5.0, 135.0) + 100.0])
    # a layer collection made active: the object goes there
    capfd.readouterr()
    assert import_into(bpy, "Survey", path) == {"FINISHED"}
    out = capfd.readouterr().out
    assert f"Imported {len(expected)} points from dem.asc" in out and "far from the world" in out

    obj = bpy.context.view_layer.objects.active
    assert obj.name == "dem" and obj.select_get()
    assert obj.users_collection[0] == bpy.data.collections["Survey"]
    assert len(obj.data.vertices) == len(expected)
    origin = np.array(obj.matrix_world.translation)
    assert np.abs(origin - expected.mean(axis=0)).max() < 100.0  # the object is at the data
    assert np.abs(positions(obj)).max() < 200.0  # its vertices relative to it
    assert_georeferenced_exactly(obj, expected)
    # (stored as they are, in 32-bit floats 0.5 apart at 4.1e6, the vertices would miss that
    # bound a hundredfold: 0.04 here)
    assert np.abs(expected.astype(np.float32) - expected).max() > 100 * 1e-6 * 170.0

    assert fit(bpy, obj) == {"FINISHED"}
    surface = bpy.context.view_layer.objects.active
    assert surface.tcb.role == "SURFACE" and surface.tcb.rms < 0.05


def test_reader_warnings_become_warning_reports(clean_scene, tmp_path, capfd):
    """A float32 array of map coordinates (the reader says it is rounded), a DEM whose
    no-data cells have no NODATA_value and a text file with a NaN row (left out, with a
    warning; refused with Leave Out Invalid Points off)."""
    bpy = clean_scene
    rng = np.random.default_rng(2)
    xy = rng.random((300, 2)) * 50.0
    pts = (np.c_[xy, heights(xy[:, 0], xy[:, 1])] + UTM).astype(np.float32)
    npy = tmp_path / "coarse.npy"
    np.save(npy, pts)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        meshio().read_geometry(npy)
    said = str(caught[0].message)
    assert "32-bit floats" in said
    capfd.readouterr()
    assert import_points(bpy, npy) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Imported 300 points from coarse.npy" in out
    assert f"Warning: {said}" in out
    obj = bpy.context.view_layer.objects.active
    assert_georeferenced_exactly(obj, pts.astype(np.float64))

    bare = write_asc(tmp_path / "bare.asc", rows=8, cols=9, fill="bare")
    capfd.readouterr()
    assert import_points(bpy, bare) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Imported 71 points from bare.asc" in out
    assert "Warning: bare.asc: left out 1 point with z = -9999" in out
    obj = bpy.context.view_layer.objects.active
    assert obj.name == "bare" and len(obj.data.vertices) == 71
    assert world(obj)[:, 2].min() > 90.0
    before = len(bpy.data.objects), len(bpy.data.meshes)
    with pytest.raises(RuntimeError, match="-9999.*turn on Leave Out Invalid Points"):
        import_points(bpy, bare, drop_invalid=False)
    assert (len(bpy.data.objects), len(bpy.data.meshes)) == before

    # a NaN row of a text file; the active collection excluded: the scene's takes the object
    gaps = tmp_path / "gaps.csv"
    gaps.write_text("x,y,z\n0,0,1\n1,0,2\nnan,1,2\n0,1,3\n1,1,4\n")
    capfd.readouterr()
    assert import_into(bpy, "Excluded", gaps, exclude=True) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Imported 4 points from gaps.csv" in out
    assert "Warning: gaps.csv: left out 1 point with NaN or infinite coordinates" in out
    obj = bpy.context.view_layer.objects.active
    assert obj.name == "gaps" and obj.users_collection[0] == bpy.context.scene.collection
    assert np.array_equal(world(obj), [[0, 0, 1], [1, 0, 2], [0, 1, 3], [1, 1, 4]])
    before = len(bpy.data.objects), len(bpy.data.meshes)
    with pytest.raises(RuntimeError, match="gaps.csv: 1 of the 5 points has NaN or infinite "
                       "coordinates; turn on Leave Out Invalid Points"):
        import_points(bpy, gaps, drop_invalid=False)
    assert (len(bpy.data.objects), len(bpy.data.meshes)) == before


def test_a_mesh_file_far_from_the_origin_keeps_its_triangles_and_precision(clean_scene,
                                                                          tmp_path):
    """An OBJ (which Blender's importer would store in 32-bit floats around the world origin,
    its axes turned) is read as the engine reads it: triangles, the file's axes, an offset."""
    bpy = clean_scene
    verts, quads = grid(10, size=40.0, f=lambda x, y: 0.01 * x * y)
    verts = verts + CORNER
    path = tmp_path / "tile.obj"
    path.write_text("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in verts)
                    + "".join("f " + " ".join(str(i + 1) for i in q) + "\n" for q in quads))
    assert import_points(bpy, path) == {"FINISHED"}
    obj = bpy.context.view_layer.objects.active
    assert obj.name == "tile" and len(obj.data.vertices) == 100
    assert len(obj.data.polygons) == 2 * len(quads)
    assert_georeferenced_exactly(obj, verts)
    assert fit(bpy, obj) == {"FINISHED"}


def test_a_malformed_file_is_refused_with_the_reader_s_words_and_nothing_is_made(
        clean_scene, tmp_path):
    bpy = clean_scene
    core = core_module()
    short = write_asc(tmp_path / "short.asc", rows=6, cols=6)
    short.write_text(short.read_text().rsplit("\n", 3)[0] + "\n")  # two rows cut off
    letters = tmp_path / "letters.xyz"
    letters.write_text("1 2 3\n4 5 6\n7 eight 9\n")
    empty = tmp_path / "empty.csv"
    empty.write_text("")
    unknown = tmp_path / "scan.las"
    unknown.write_bytes(b"LASF")
    before = (len(bpy.data.objects), len(bpy.data.meshes), len(bpy.data.collections))
    for path in (short, letters, empty, unknown, tmp_path / "missing.xyz", tmp_path):
        with pytest.raises(core.FileFormatError) as said:
            meshio().read_geometry(path)
        with pytest.raises(RuntimeError, match=re.escape(str(said.value))):
            import_points(bpy, path)
        assert (len(bpy.data.objects), len(bpy.data.meshes),
                len(bpy.data.collections)) == before
    with pytest.raises(RuntimeError, match="No file chosen"):
        import_points(bpy, "")
    assert (len(bpy.data.objects), len(bpy.data.meshes), len(bpy.data.collections)) == before


def write_xyz(path, n, seed=3):
    """``n`` points of :func:`heights` as x y z text columns."""
    xy = np.random.default_rng(seed).random((n, 2)) * 80.0
    pts = np.c_[xy, heights(xy[:, 0], xy[:, 1])]
    path.write_text("\n".join(f"{x:.9f} {y:.9f} {z:.9f}" for x, y, z in pts) + "\n")
    return path


def import_files(bpy, directory, names, *selected, invoke=False):
    """Import Points as the file browser's multiple selection, or a drop (``invoke``), calls
    it: a directory and the files' names, no filepath."""
    args = ("INVOKE_DEFAULT",) if invoke else ()
    with bpy.context.temp_override(**select(bpy, *selected)):
        return bpy.ops.tcb.import_points(*args, directory=str(directory),
                                         files=[{"name": n} for n in names])


def counts(bpy):
    return len(bpy.data.objects), len(bpy.data.meshes), len(bpy.data.collections)


def test_several_files_make_an_object_each_all_selected_the_last_active(clean_scene, tmp_path,
                                                                         capfd):
    bpy = clean_scene
    write_xyz(tmp_path / "north.xyz", 50)
    write_asc(tmp_path / "dem.asc", rows=8, cols=9)
    other = bpy.data.objects.new("Other", None)
    bpy.context.scene.collection.objects.link(other)
    capfd.readouterr()
    assert import_files(bpy, tmp_path, ["north.xyz", "dem.asc"], other) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Imported 50 points from north.xyz" in out and "Imported 72 points from dem.asc" in out
    assert "Imported 2 files as north, dem" in out
    north, dem = bpy.data.objects["north"], bpy.data.objects["dem"]
    assert len(north.data.vertices) == 50 and len(dem.data.vertices) == 72
    assert_georeferenced_exactly(north, read(tmp_path / "north.xyz")[0])
    assert_georeferenced_exactly(dem, read(tmp_path / "dem.asc")[0])
    assert north.select_get() and dem.select_get() and not other.select_get()
    assert bpy.context.view_layer.objects.active == dem
    # one file of the browser's selection: as filepath alone (no summary of files)
    capfd.readouterr()
    assert import_files(bpy, tmp_path, ["north.xyz"]) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "Imported 50 points from north.xyz" in out and "files" not in out
    assert bpy.context.view_layer.objects.active.name == "north.001"


def test_a_refused_file_among_several_is_named_and_the_others_are_imported(clean_scene,
                                                                          tmp_path, capfd):
    bpy = clean_scene
    write_xyz(tmp_path / "good.xyz", 40)
    (tmp_path / "letters.xyz").write_text("1 2 3\n4 5 6\n7 eight 9\n")
    before = counts(bpy)
    capfd.readouterr()
    # (an ERROR report makes bpy.ops raise, though the operator finished: the good file is in)
    with pytest.raises(RuntimeError, match="letters.xyz") as said:
        import_files(bpy, tmp_path, ["letters.xyz", "good.xyz", "missing.csv"])
    assert "missing.csv" in str(said.value)
    out = capfd.readouterr().out
    assert "Imported 40 points from good.xyz" in out
    assert ("Imported 1 of 3 files, as good; refused letters.xyz, missing.csv (the errors "
            "above say why)") in out
    assert counts(bpy) == (before[0] + 1, before[1] + 1, before[2])
    good = bpy.data.objects["good"]
    assert len(good.data.vertices) == 40 and good.select_get()
    assert bpy.context.view_layer.objects.active == good
    assert [o.name for o in bpy.data.objects] == ["good"]

    # none imported: cancelled, nothing made
    with pytest.raises(RuntimeError, match="None of the 2 files was imported"):
        import_files(bpy, tmp_path, ["letters.xyz", "missing.csv"])
    assert counts(bpy) == (before[0] + 1, before[1] + 1, before[2])


def test_files_dropped_on_the_3d_viewport_are_imported(clean_scene, tmp_path, capfd):
    """The file handler claims the point formats Blender does not import itself (.obj and .ply
    are Blender's; a .npz may be a spline, which Import Points hands to Import Spline) and
    hands a drop to Import Points, whose
    invoke shows a dialog of its options for the dropped files instead of opening the file
    browser (with a window: checked on stand-ins, background mode has none) and imports them
    (at once in background mode)."""
    bpy = clean_scene
    ops = sys.modules[ADDON + ".tcb_addon.operators"]
    handlers = [h for h in bpy.types.FileHandler.__subclasses__()
                if h.bl_idname == "TCB_FH_import_points"]
    assert len(handlers) == 1 and bpy.types.TCB_FH_import_points is handlers[0]
    handler = handlers[0]
    assert handler.bl_import_operator == "tcb.import_points"
    claimed = set(handler.bl_file_extensions.split(";"))
    assert claimed == set(ops.POINT_EXTENSIONS) - {".obj", ".ply"}
    assert {".xyz", ".txt", ".csv", ".pts", ".npy", ".npz", ".asc", ".off"} <= claimed

    class Area:
        def __init__(self, kind):
            self.type = kind

    class Context:
        def __init__(self, area, mode="OBJECT"):
            self.area, self.mode = area, mode

    assert handler.poll_drop(Context(Area("VIEW_3D")))
    assert not handler.poll_drop(Context(Area("TEXT_EDITOR")))
    assert not handler.poll_drop(Context(Area("VIEW_3D"), "EDIT_MESH"))  # (Import's poll)
    assert not handler.poll_drop(Context(None))

    write_xyz(tmp_path / "a.xyz", 30)
    np.save(tmp_path / "b.npy", np.random.default_rng(4).random((25, 3)))
    capfd.readouterr()
    assert import_files(bpy, tmp_path, ["a.xyz", "b.npy"], invoke=True) == {"FINISHED"}
    assert "Imported 2 files as a, b" in capfd.readouterr().out
    a, b = bpy.data.objects["a"], bpy.data.objects["b"]
    assert len(a.data.vertices) == 30 and len(b.data.vertices) == 25
    assert a.select_get() and b.select_get() and bpy.context.view_layer.objects.active == b

    # with a window: the dialog for a drop, the file browser for File > Import
    calls = []
    wm = SimpleNamespace(invoke_props_dialog=lambda op, **kw: calls.append(("dialog", kw))
                         or {"RUNNING_MODAL"},
                         fileselect_add=lambda op: calls.append(("browser", {})))
    context = SimpleNamespace(window=object(), window_manager=wm)
    dropped = SimpleNamespace(directory=str(tmp_path), files=[SimpleNamespace(name="a.xyz")],
                              filepath="")
    assert ops.TCB_OT_import_points.invoke(dropped, context, None) == {"RUNNING_MODAL"}
    assert calls == [("dialog", {"title": "Import Points: a.xyz", "confirm_text": "Import"})]
    calls.clear()
    menu = SimpleNamespace(directory="", files=[], filepath="")
    assert ops.TCB_OT_import_points.invoke(menu, context, None) == {"RUNNING_MODAL"}
    assert [c[0] for c in calls] == ["browser"]


# a sloping DEM tile (17 degrees along x): on its tilted best-fit plane the fitted surface
# reached more than 1 m past the tile's straight edges; along its z it ends at them
SLOPE_ROWS, SLOPE_COLS, SLOPE_CELL = 30, 40, 10.0


def slope_points():
    """The cell centres of the sloping tile, row 0 the northern edge (as the .asc reads)."""
    j, i = np.meshgrid(np.arange(SLOPE_COLS), np.arange(SLOPE_ROWS))
    z = 100.0 + 3.0 * j + 4.0 * np.sin(j / 6.0) + 3.0 * np.cos(i / 5.0)
    x, y = (j + 0.5) * SLOPE_CELL, (SLOPE_ROWS - i - 0.5) * SLOPE_CELL
    return np.c_[x.ravel(), y.ravel(), z.ravel()], z


def write_slope(path, jitter=False):
    """The sloping tile as an ESRI ASCII grid (``.asc``) or as .xyz text columns; with
    ``jitter`` the surface at its nodes moved by up to a quarter cell in x and y (scattered
    points: no grid)."""
    pts, z = slope_points()
    if jitter:
        xy = pts[:, :2] + np.random.default_rng(7).uniform(-0.25, 0.25, (len(pts), 2)) * SLOPE_CELL
        xy = np.clip(xy, 0.5 * SLOPE_CELL, [(SLOPE_COLS - 0.5) * SLOPE_CELL,
                                             (SLOPE_ROWS - 0.5) * SLOPE_CELL])
        j, i = xy[:, 0] / SLOPE_CELL - 0.5, SLOPE_ROWS - 0.5 - xy[:, 1] / SLOPE_CELL
        pts = np.c_[xy, 100.0 + 3.0 * j + 4.0 * np.sin(j / 6.0) + 3.0 * np.cos(i / 5.0)]
    if path.suffix == ".asc":
        head = (f"ncols {SLOPE_COLS}\nnrows {SLOPE_ROWS}\nxllcorner 0\nyllcorner 0\n"
                f"cellsize {SLOPE_CELL:g}\n")
        path.write_text(head + "\n".join(" ".join(f"{v:.9f}" for v in r) for r in z) + "\n")
    else:
        path.write_text("\n".join(f"{x:.9f} {y:.9f} {h:.9f}" for x, y, h in pts) + "\n")
    return path


def past_the_tile(xy) -> float:
    """How far points' x, y reach past the rectangle of the tile's cell centres (negative:
    inside it)."""
    lo = np.array([0.5, 0.5]) * SLOPE_CELL
    hi = np.array([SLOPE_COLS - 0.5, SLOPE_ROWS - 0.5]) * SLOPE_CELL
    return float(max((lo - xy[:, :2]).max(), (xy[:, :2] - hi).max()))


def fit_slope(bpy, obj, **props):
    """Fit Surface on the tile with the default Projection (Auto), kept quick."""
    props.setdefault("max_control_points", 150)
    props.setdefault("max_iterations", 2)
    assert fit(bpy, obj, **props) == {"FINISHED"}
    surface = bpy.context.view_layer.objects.active
    assert surface.tcb.role == "SURFACE"
    return surface


def test_a_dem_raster_is_fitted_along_its_z_and_keeps_its_straight_edges(clean_scene, tmp_path,
                                                                        capfd):
    """Import Points marks an object made of a DEM raster; Fit Surface with Projection Auto
    fits it along its z (the report says so), so that a sloping tile's surface ends at the
    tile's edges, and Refine keeps that projection."""
    bpy = clean_scene
    path = write_slope(tmp_path / "slope.asc")
    assert meshio().is_raster(path)
    capfd.readouterr()
    assert import_points(bpy, path) == {"FINISHED"}
    out = capfd.readouterr().out
    assert f"Imported {SLOPE_ROWS * SLOPE_COLS} points from slope.asc" in out
    assert "a DEM raster: Fit Surface fits it along its z" in out
    obj = bpy.context.view_layer.objects.active
    assert obj["tcb_raster"] is True or obj["tcb_raster"] == 1
    assert np.allclose(world(obj), read(path)[0], atol=1e-4)

    surface = fit_slope(bpy, obj)
    out = capfd.readouterr().out
    assert "'slope' is a DEM raster (Import Points): fitted along its z" in out
    assert "the Projection setting chooses another" in out
    spline = spline_of(surface)
    assert spline.report.get("projection_given")
    axis = spline.parameterization.axes[2]
    assert abs(abs(axis[2]) - 1.0) < 1e-9
    verts = world(surface)
    assert len(verts) > 100 and past_the_tile(verts) < 1e-3

    # Refine continues along the same direction (the stored parameterization's)
    with bpy.context.temp_override(**select(bpy, surface)):
        assert bpy.ops.tcb.refine(max_control_points=200, max_iterations=2) == {"FINISHED"}
    refined = spline_of(surface)
    assert abs(abs(refined.parameterization.axes[2][2]) - 1.0) < 1e-9
    assert past_the_tile(world(surface)) < 1e-3


def test_scattered_points_of_the_tile_keep_auto_s_tilted_plane(clean_scene, tmp_path, capfd):
    """The tile's nodes as .xyz text (a gridded XYZ export) are a DEM raster too; the same
    surface at scattered points is not: Projection Auto chooses the best-fit plane, tilted
    with the slope, and the surface reaches past the tile's edges."""
    bpy = clean_scene
    grid_text = write_slope(tmp_path / "nodes.xyz")
    assert not meshio().is_raster(grid_text)  # (the file's type: text columns)
    assert import_points(bpy, grid_text) == {"FINISHED"}
    assert bpy.context.view_layer.objects.active["tcb_raster"]
    path = write_slope(tmp_path / "slope.xyz", jitter=True)
    capfd.readouterr()
    assert import_points(bpy, path) == {"FINISHED"}
    assert "DEM raster" not in capfd.readouterr().out
    obj = bpy.context.view_layer.objects.active
    assert "tcb_raster" not in obj
    surface = fit_slope(bpy, obj)
    assert "DEM raster" not in capfd.readouterr().out
    assert not spline_of(surface).report.get("projection_given")
    assert past_the_tile(world(surface)) > 1.0


@pytest.mark.parametrize("axis, degrees", [("X", 90.0), ("Y", 30.0)])
def test_a_rotated_raster_is_fitted_along_its_own_z(clean_scene, tmp_path, capfd, axis,
                                                    degrees):
    """A raster object turned is fitted along its own z in world space: the surface, in the
    object's frame, ends at the tile's edges; World Z given still wins over it."""
    bpy = clean_scene
    path = write_slope(tmp_path / "slope.asc")
    assert import_points(bpy, path) == {"FINISHED"}
    obj = bpy.context.view_layer.objects.active
    obj.rotation_euler["XYZ".index(axis)] = np.radians(degrees)
    bpy.context.view_layer.update()
    m = np.array(obj.matrix_world, dtype=np.float64)
    capfd.readouterr()
    surface = fit_slope(bpy, obj)
    assert "fitted along its z" in capfd.readouterr().out
    axis_used = spline_of(surface).parameterization.axes[2]
    assert np.linalg.norm(np.cross(axis_used, m[:3, 2])) < 1e-6
    local = (world(surface) - m[:3, 3]) @ np.linalg.inv(m[:3, :3]).T
    assert past_the_tile(local) < 1e-3

    if axis == "Y":  # World Z chosen in Projection is used as given
        surface = fit_slope(bpy, obj, projection="Z")
        assert "fitted along its z" not in capfd.readouterr().out
        assert abs(abs(spline_of(surface).parameterization.axes[2][2]) - 1.0) < 1e-9


def test_rasters_fitted_together_go_along_their_z_only_when_it_is_parallel(clean_scene,
                                                                           tmp_path, capfd):
    """Two raster tiles side by side, selected together: along their common z; one of them
    turned by a degree (z axes not parallel): Projection Auto chooses, and the report says
    why."""
    bpy = clean_scene
    path = write_slope(tmp_path / "slope.asc")
    assert import_points(bpy, path) == {"FINISHED"}
    first = bpy.context.view_layer.objects.active
    assert import_points(bpy, path) == {"FINISHED"}
    second = bpy.context.view_layer.objects.active
    second.location = (SLOPE_COLS * SLOPE_CELL, 0.0, 3.0 * SLOPE_COLS)  # the slope goes on
    bpy.context.view_layer.update()
    capfd.readouterr()
    assert fit(bpy, first, second, max_control_points=150, max_iterations=2) == {"FINISHED"}
    assert "are DEM rasters (Import Points): fitted along their z" in capfd.readouterr().out
    surface = bpy.context.view_layer.objects.active
    assert abs(abs(spline_of(surface).parameterization.axes[2][2]) - 1.0) < 1e-9

    second.rotation_euler[1] = np.radians(1.0)
    bpy.context.view_layer.update()
    assert fit(bpy, first, second, max_control_points=150, max_iterations=2) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "have z axes that are not parallel: Projection Auto chose" in out
    assert "fitted along their z" not in out
    assert not spline_of(bpy.context.view_layer.objects.active).report.get("projection_given")


def test_a_raster_turned_in_its_mesh_or_fitted_with_a_cloud_is_left_to_auto(clean_scene,
                                                                             tmp_path, capfd):
    """The raster mark holds while the object's vertices are on its grid of x and y: turned
    inside the mesh (Apply Rotation) its z crosses the tile, and fitted along it the cloud was
    refused as folded (review); with a cloud that is no raster, Auto chooses too. The reports
    say why."""
    bpy = clean_scene
    assert import_points(bpy, write_slope(tmp_path / "slope.asc")) == {"FINISHED"}
    obj = bpy.context.view_layer.objects.active
    obj.rotation_euler[0] = np.radians(90.0)
    with bpy.context.temp_override(**select(bpy, obj)):
        bpy.ops.object.transform_apply(location=False, rotation=True, scale=False)
    assert obj["tcb_raster"]  # (the mark stays: the user's object is not changed)
    capfd.readouterr()
    surface = fit_slope(bpy, obj)
    out = capfd.readouterr().out
    assert "'slope' was imported as a DEM raster, but its points are no longer on its grid" in out
    assert "fitted along its z" not in out
    assert not spline_of(surface).report.get("projection_given")

    assert import_points(bpy, write_slope(tmp_path / "tile.asc")) == {"FINISHED"}
    tile = bpy.context.view_layer.objects.active
    assert import_points(bpy, write_slope(tmp_path / "cloud.xyz", jitter=True)) == {"FINISHED"}
    cloud = bpy.context.view_layer.objects.active
    cloud.location = (SLOPE_COLS * SLOPE_CELL, 0.0, 3.0 * SLOPE_COLS)
    bpy.context.view_layer.update()
    capfd.readouterr()
    assert fit(bpy, tile, cloud, max_control_points=150, max_iterations=2) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "'cloud' is no DEM raster (Import Points) as 'tile': Projection Auto chose" in out
    assert not spline_of(bpy.context.view_layer.objects.active).report.get("projection_given")


def test_a_spline_among_dropped_files_is_imported_as_import_spline_makes_it(clean_scene,
                                                                            tmp_path, capfd):
    """A .npz dropped (or chosen) with Import Points that is a TCB spline (Export Spline's
    format, the same extension as points and DEMs) is handed to Import Spline: its surface and
    net are made beside the points' objects; a damaged spline is refused with its words."""
    bpy = clean_scene
    surf = core_module().fit_surface(grid(8)[0], tolerance=1e-2, max_control_points=100)
    surf.save(tmp_path / "spline.npz")
    write_xyz(tmp_path / "scan.xyz", 30)
    capfd.readouterr()
    assert import_files(bpy, tmp_path, ["scan.xyz", "spline.npz"], invoke=True) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "imported 'spline.npz' as 'spline TCB Surface'" in out
    assert "Imported 2 files as scan, spline TCB Surface" in out
    surface = bpy.data.objects["spline TCB Surface"]
    assert surface.tcb.role == "SURFACE" and surface.tcb.net is not None
    np.testing.assert_array_equal(spline_of(surface).control_points, surf.control_points)
    assert surface.select_get() and bpy.data.objects["scan"].select_get()
    assert bpy.context.view_layer.objects.active == surface
    # filepath alone (a script) as well; a spline whose knots were cut is refused
    assert import_points(bpy, tmp_path / "spline.npz") == {"FINISHED"}
    with np.load(tmp_path / "spline.npz") as z:
        parts = dict(z)
    parts["knots"] = parts["knots"][:3]
    np.savez(tmp_path / "cut.npz", **parts)
    before = counts(bpy)
    with pytest.raises(RuntimeError, match="cut.npz"):
        import_points(bpy, tmp_path / "cut.npz")
    assert counts(bpy) == before


def view_stand_in(location=(0.0, 0.0, 0.0), distance=15.0, start=0.01, end=1000.0):
    """A SpaceView3D as frame_views reads it: Blender's default clip range and view."""
    from mathutils import Vector

    r3d = SimpleNamespace(view_location=Vector(location), view_distance=distance,
                          view_perspective="PERSP")
    return SimpleNamespace(clip_start=start, clip_end=end, region_3d=r3d)


def view_state(space):
    r3d = space.region_3d
    return (space.clip_start, space.clip_end, tuple(r3d.view_location), r3d.view_distance,
            r3d.view_perspective)


TILE = (UTM, UTM + [10000.0, 8000.0, 300.0])  # a DEM tile 10 km by 8 km at UTM coordinates


def assert_framed_on_tile(space):
    lo, hi = TILE
    diag = np.linalg.norm(hi - lo)
    r3d = space.region_3d
    assert np.allclose(np.array(r3d.view_location), 0.5 * (lo + hi), rtol=0, atol=0.5)
    assert r3d.view_distance == pytest.approx(diag, rel=1e-6)
    # the whole tile within Clip End from the eye, with room to zoom out; the ratio kept
    assert space.clip_end >= 4 * diag > 1.5 * diag
    assert space.clip_end / space.clip_start == pytest.approx(1e5, rel=1e-6)
    assert space.clip_start < 0.5 * diag  # (the nearest point of the tile not clipped)


def test_a_utm_tile_out_of_the_views_reach_is_framed_and_its_clip_range_raised(clean_scene):
    """A tile at its map coordinates is 4e6 from a view at the world origin and wider than its
    Clip End (1000): the view is centred on it at about its diagonal, Clip End raised to 4
    diagonals (rounded up) and Clip Start only as needed to keep the ratio at 1e5 (Blender's
    default range). A view whose Clip End already covers it keeps its clip range (never
    lowered); a small object next to a view is left alone, without a note."""
    bridge = sys.modules[ADDON + ".tcb_addon.bridge"]
    lo, hi = TILE
    view, wide = view_stand_in(), view_stand_in(start=1.0, end=1e6)
    notes = bridge.frame_views([view, wide], lo, hi)
    assert_framed_on_tile(view)
    assert view.clip_end == 52000.0 and view.clip_start == pytest.approx(0.52)  # (4 x 12810)
    assert notes[0] == "Clip End raised to 52000, Clip Start to 0.52"
    assert np.allclose(np.array(wide.region_3d.view_location), 0.5 * (lo + hi))
    assert (wide.clip_start, wide.clip_end) == (1.0, 1e6) and notes[1] == ""
    assert len(notes) == 2

    near = view_stand_in()
    before = view_state(near)
    assert bridge.frame_views([near], [-1.0, -1.0, 0.0], [1.0, 1.0, 0.5]) == []
    assert view_state(near) == before
    # an orthographic view draws half of Clip End each side of the eye: 600 m is out of reach
    ortho, persp = view_stand_in(distance=100.0), view_stand_in(distance=100.0)
    ortho.region_3d.view_perspective = "ORTHO"
    assert bridge.frame_views([persp], [500.0, 0.0, 0.0], [600.0, 0.0, 0.0]) == []
    assert bridge.frame_views([ortho], [500.0, 0.0, 0.0], [600.0, 0.0, 0.0]) == [""]
    assert np.allclose(np.array(ortho.region_3d.view_location), [550.0, 0.0, 0.0])
    assert ortho.clip_end == 1000.0  # (4 x 100 m: its clip range kept)
    # camera view is left for the framed perspective view, as Frame Selected does
    camera = view_stand_in()
    camera.region_3d.view_perspective = "CAMERA"
    bridge.frame_views([camera], lo, hi)
    assert camera.region_3d.view_perspective == "PERSP"


def test_a_real_3d_view_is_framed_on_a_utm_tile_and_left_alone_for_a_small_object(
        clean_scene):
    """The same on a SpaceView3D of the file's screens (background mode has them, without
    windows): its Vector view location and float32 clip range."""
    bpy = clean_scene
    bridge = sys.modules[ADDON + ".tcb_addon.bridge"]
    areas = [a for s in bpy.data.screens for a in s.areas if a.type == "VIEW_3D"]
    assert areas
    space = areas[0].spaces.active
    before = view_state(space)
    try:
        space.clip_start, space.clip_end = 0.01, 1000.0
        space.region_3d.view_location = (0.0, 0.0, 0.0)
        space.region_3d.view_distance = 15.0
        space.region_3d.view_perspective = "PERSP"
        start = view_state(space)
        assert bridge.frame_views([space], [-1.0, -1.0, 0.0], [1.0, 1.0, 0.5]) == []
        assert view_state(space) == start
        notes = bridge.frame_views([space], *TILE)
        assert notes == ["Clip End raised to 52000, Clip Start to 0.52"]
        assert_framed_on_tile(space)
    finally:
        space.clip_start, space.clip_end = before[0], before[1]
        r3d = space.region_3d
        r3d.view_location, r3d.view_distance, r3d.view_perspective = before[2:]


def test_import_frames_the_open_windows_3d_views_in_one_note(clean_scene, tmp_path, capfd):
    """Import Points frames the 3D views of the open windows on what it made (background mode
    has no windows: the operator's step is run on a stand-in window of the real import's
    object) and says so once; with no window nothing is done."""
    bpy = clean_scene
    ops = sys.modules[ADDON + ".tcb_addon.operators"]
    write_asc(tmp_path / "dem.asc", rows=30, cols=40, cell=100.0)  # 4 km by 3 km at UTM
    capfd.readouterr()
    assert import_points(bpy, tmp_path / "dem.asc") == {"FINISHED"}
    assert "Framed" not in capfd.readouterr().out  # (no windows)
    dem = bpy.data.objects["dem"]

    view, reports, redrawn = view_stand_in(), [], []
    area = SimpleNamespace(type="VIEW_3D", spaces=SimpleNamespace(active=view),
                           tag_redraw=lambda: redrawn.append(1))
    window = SimpleNamespace(screen=SimpleNamespace(areas=[area]))
    context = SimpleNamespace(window_manager=SimpleNamespace(windows=[window]))
    me = SimpleNamespace(report=lambda kind, text: reports.append((kind, text)))
    ops.TCB_OT_import_points._frame_views(me, context, [dem])
    assert len(reports) == 1 and reports[0][0] == {"INFO"} and redrawn
    assert reports[0][1].startswith("Framed the 3D view on 'dem', out of its clip range; "
                                    "Clip End raised to ")
    pts = world(dem)
    assert np.allclose(np.array(view.region_3d.view_location),
                       0.5 * (pts.min(axis=0) + pts.max(axis=0)), rtol=0, atol=0.5)
    assert view.clip_end >= 4 * np.linalg.norm(np.ptp(pts, axis=0))


def test_dem_tiles_fitted_one_by_one_join_the_tiles_fitted_before(clean_scene, tmp_path,
                                                                  capfd):
    """Join Neighbours for point clouds: two DEM tiles sharing a column of nodes, imported and
    fitted one after the other (each along its z): the second's surface is joined to the
    first's along that column (core.join.CloudSeam), which is not changed, and the summary
    says so; with Join Neighbours off it is fitted on its own."""
    bpy = clean_scene
    pts, _ = slope_points()
    middle = (SLOPE_COLS // 2 + 0.5) * SLOPE_CELL
    for name, keep in (("west", pts[:, 0] <= middle), ("east", pts[:, 0] >= middle)):
        (tmp_path / f"{name}.xyz").write_text(
            "\n".join(f"{x:.9f} {y:.9f} {h:.9f}" for x, y, h in pts[keep]) + "\n")
        assert import_points(bpy, tmp_path / f"{name}.xyz") == {"FINISHED"}
    west, east = bpy.data.objects["west"], bpy.data.objects["east"]
    assert west["tcb_raster"] and east["tcb_raster"]
    first = fit_slope(bpy, west)
    blob = first["tcb_spline"]
    capfd.readouterr()
    second = fit_slope(bpy, east)
    out = capfd.readouterr().out
    joined = spline_of(second).report["join"]
    assert joined["surfaces"] == 1 and joined["shared_edges"] == 0
    assert abs(joined["shared_length"] - (SLOPE_ROWS - 1) * SLOPE_CELL) < 1e-6
    assert joined["gap_max"] < 0.5 * joined["gap_max_unjoined"], joined
    assert f"joined to '{first.name}' along 290 of shared border" in out, out
    assert first["tcb_spline"] == blob and second.tcb.joined_edges == joined["pins"] > 0
    # the two surfaces' heights along the shared column, between the nodes too
    ys = np.linspace(0.5 * SLOPE_CELL, (SLOPE_ROWS - 0.5) * SLOPE_CELL, 117)
    column = np.c_[np.full_like(ys, middle), ys]
    dz = spline_of(first).heights(column) - spline_of(second).heights(column)
    assert np.isfinite(dz).all() and np.abs(dz).max() <= 1.01 * joined["gap_max"]
    # Refine joins it again, to the first as it is now
    capfd.readouterr()
    with bpy.context.temp_override(**select(bpy, second)):
        assert bpy.ops.tcb.refine() == {"FINISHED"}
    assert f"joined to '{first.name}'" in capfd.readouterr().out
    assert spline_of(second).report["join"]["surfaces"] == 1
    alone = fit_slope(bpy, east, join_neighbours=False)
    assert "join" not in spline_of(alone).report
    # a Shift+D copy of the first tile's surface is no second neighbour (the latest of a
    # tile's results is); a tile whose points were deleted (X) is none (review)
    variant = first.copy()
    bpy.context.collection.objects.link(variant)
    again = fit_slope(bpy, east)
    assert spline_of(again).report["join"]["surfaces"] == 1
    for collection in list(west.users_collection):
        collection.objects.unlink(west)
    assert "join" not in spline_of(fit_slope(bpy, east)).report
