"""Import Spline (.npz): a spline saved by the engine (the command line's --spline,
TCBSurface.save, Export Spline) made into a live TCB result, linked to the selected scan when
that is the data it was fitted to."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scenes import add_mesh, core_module, grid, move_net_vertex, positions, select, spline_of  # noqa: E402

from test_operators import draw_panels, snapshot  # noqa: E402


def saved_fit(tmp_path, verts, faces, name="scan.npz", **kwargs):
    """The engine's fit of ``verts`` / ``faces`` (as the command line makes it), saved."""
    core = core_module()
    kwargs.setdefault("tolerance", 2e-3)
    kwargs.setdefault("max_control_points", 200)
    surf = core.fit_surface(verts, faces, **kwargs)
    path = tmp_path / name
    surf.save(path)
    return surf, path


def import_spline(bpy, path, *selected, **props):
    with bpy.context.temp_override(**select(bpy, *selected)):
        return bpy.ops.tcb.import_spline(filepath=str(path), **props)


def evaluated(bpy, obj) -> np.ndarray:
    return positions(obj.evaluated_get(bpy.context.evaluated_depsgraph_get()))


def test_import_with_its_scan_selected_makes_a_live_result_that_refines(clean_scene, tmp_path,
                                                                        capfd):
    bpy = clean_scene
    verts, faces = grid(20, f=lambda x, y: 0.3 * np.sin(2 * x) * np.cos(y))
    fitted, path = saved_fit(tmp_path, verts, grid(20, triangles=True)[1])
    scan = add_mesh(bpy, "Scan", verts, grid(20, triangles=True)[1])
    before = snapshot(scan)
    capfd.readouterr()
    assert import_spline(bpy, path, scan, resolution=32) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "imported 'scan.npz'" in out and "linked to its source 'Scan'" in out

    surface = bpy.context.view_layer.objects.active
    st = surface.tcb
    assert surface.name == "scan TCB Surface" and st.role == "SURFACE"
    assert [s.object for s in st.sources] == [scan]
    coll = surface.users_collection[0]
    net = st.net
    assert coll.name == "TCB scan" and net.name == "scan TCB Net" and net.name in coll.objects
    assert net.tcb.role == "NET" and net.tcb.surface == surface
    # the net holds the file's control points; the mesh is its tessellation, with a UV map
    assert np.allclose(positions(net), fitted.control_points, atol=1e-6)
    stored = spline_of(surface)
    assert np.array_equal(stored.control_points, fitted.control_points)
    assert st.resolution == 32 and not st.auto_resolution
    v, f = stored.tessellate(32)
    assert len(surface.data.vertices) == len(v) and len(surface.data.polygons) == len(f)
    assert np.allclose(positions(surface), v, atol=1e-6)
    assert "UVMap" in surface.data.uv_layers
    # the fit's figures and settings in the Result panel's properties
    assert st.control_points == len(fitted.control_points)
    assert st.rms == pytest.approx(fitted.report["rms"], rel=1e-6)
    assert st.tolerance == pytest.approx(2e-3) and st.max_control_points == 200
    assert st.degree == "2" and st.mode == "TCB" and st.criterion == "RMS"

    # live: a net drag moves the surface
    shown = evaluated(bpy, surface)
    move_net_vertex(bpy, net, len(fitted.control_points) // 2, (0.0, 0.0, 0.2))
    assert np.abs(evaluated(bpy, surface) - shown).max() > 0.01

    # Refine (which replaces the drag, and says so) and the Deviation Map read the scan
    capfd.readouterr()
    with bpy.context.temp_override(**select(bpy, surface)):
        assert bpy.ops.tcb.refine(tolerance=5e-4, max_control_points=600) == {"FINISHED"}
        assert "1 edited control point was replaced" in capfd.readouterr().out
        assert bpy.ops.tcb.deviation_map() == {"FINISHED"}
    assert surface.tcb.control_points > len(fitted.control_points)
    assert surface.tcb.rms < fitted.report["rms"]
    assert snapshot(scan) == before


def test_export_then_import_gives_the_same_spline_and_mesh(clean_scene, tmp_path):
    bpy = clean_scene
    verts, faces = grid(16, f=lambda x, y: 0.2 * x * y + 0.1 * np.cos(3 * x))
    scan = add_mesh(bpy, "Scan", verts, faces)
    with bpy.context.temp_override(**select(bpy, scan)):
        assert bpy.ops.tcb.fit_surface(tolerance=2e-3, max_control_points=150,
                                       resolution=24) == {"FINISHED"}
    first = bpy.context.view_layer.objects.active
    out = tmp_path / "Patch.npz"
    with bpy.context.temp_override(**select(bpy, first)):
        assert bpy.ops.tcb.export_spline(filepath=str(out)) == {"FINISHED"}
    assert import_spline(bpy, out, scan, resolution=24) == {"FINISHED"}
    second = bpy.context.view_layer.objects.active
    assert second != first and second.name == "Patch TCB Surface"
    a, b = spline_of(first), spline_of(second)
    assert np.array_equal(a.control_points, b.control_points)
    assert np.array_equal(a.knots, b.knots)
    assert np.array_equal(positions(first), positions(second))
    assert np.array_equal(positions(first.tcb.net), positions(second.tcb.net))


def test_import_without_its_scan_warns_and_refine_says_what_it_needs(clean_scene, tmp_path,
                                                                      capfd):
    bpy = clean_scene
    verts, faces = grid(16, triangles=True)
    fitted, path = saved_fit(tmp_path, verts, faces)
    other = add_mesh(bpy, "Other", verts + [0.0, 0.0, 0.05], faces)  # moved: not its data
    capfd.readouterr()
    assert import_spline(bpy, path, other) == {"FINISHED"}
    out = capfd.readouterr().out
    assert "WARNING" in out or "Warning" in out
    assert "'Other' is not the data 'scan.npz' was fitted to (other coordinates" in out
    assert "OBJ" not in out  # (moved, not turned as Blender's OBJ importer turns a file)
    surface = bpy.context.view_layer.objects.active
    assert len(surface.tcb.sources) == 0
    assert surface.tcb.auto_resolution and surface.tcb.resolution in (64, 128, 256)
    assert ("label", "Imported from scan.npz (no source object)") in draw_panels(bpy, [surface])
    # nothing selected: no source, said
    capfd.readouterr()
    assert import_spline(bpy, path) == {"FINISHED"}
    assert "the result has no source object, which Refine and the Deviation Map need" in (
        capfd.readouterr().out)
    for op in ("refine", "deviation_map"):
        with bpy.context.temp_override(**select(bpy, surface)):
            with pytest.raises(RuntimeError, match="was imported without its source object"):
                getattr(bpy.ops.tcb, op)()
    # a point cloud of the mesh's vertices is not the mesh it was fitted to
    cloud = add_mesh(bpy, "Cloud", verts)
    capfd.readouterr()
    assert import_spline(bpy, path, cloud) == {"FINISHED"}
    assert "(a mesh then, a point cloud now)" in capfd.readouterr().out
    assert len(bpy.context.view_layer.objects.active.tcb.sources) == 0


def test_an_imported_edited_spline_keeps_its_edits_and_refine_counts_them(clean_scene, tmp_path,
                                                                          capfd):
    bpy = clean_scene
    verts, faces = grid(16, triangles=True)
    fitted, _ = saved_fit(tmp_path, verts, faces)
    c = fitted.control_points.copy()
    c[[3, 7]] += [0.0, 0.0, 0.1]
    path = tmp_path / "edited.npz"
    fitted.with_control_points(c).save(path)
    scan = add_mesh(bpy, "Scan", verts, faces)
    capfd.readouterr()
    assert import_spline(bpy, path, scan) == {"FINISHED"}
    assert "2 of its control points were edited after the fit" in capfd.readouterr().out
    surface = bpy.context.view_layer.objects.active
    assert np.allclose(positions(surface.tcb.net), c, atol=1e-6)
    with bpy.context.temp_override(**select(bpy, surface)):
        assert bpy.ops.tcb.refine(tolerance=1e-3) == {"FINISHED"}
    assert "2 edited control points were replaced" in capfd.readouterr().out


def test_a_file_that_is_no_spline_is_refused_and_nothing_is_made(clean_scene, tmp_path):
    bpy = clean_scene
    text = tmp_path / "notes.npz"
    text.write_text("not an archive")
    grid_file = tmp_path / "dem.npz"
    np.savez(grid_file, elevation=np.zeros((4, 4)))
    which = "is not a TCB surface file.*: Import Spline reads the .npz files that Export Spline"
    # a spline whose control points are finite but overflow the surface, and one with a
    # report entry of the wrong kind: refused before anything is made (user test: half a
    # result and a traceback)
    verts, faces = grid(10, triangles=True)
    fitted, good = saved_fit(tmp_path, verts, faces, name="good.npz")
    huge = tmp_path / "huge.npz"
    fitted.with_control_points(fitted.control_points * 1e300).save(huge)
    arrays = dict(np.load(good))
    arrays["report"] = np.array(str(arrays["report"]).replace('"rms": ', '"rms": "x", "_": '))
    wrong = tmp_path / "wrong.npz"
    np.savez(wrong, **arrays)
    before = (len(bpy.data.objects), len(bpy.data.collections), len(bpy.data.meshes))
    for path, words in ((text, "notes.npz " + which), (grid_file, "dem.npz is a DEM grid"),
                        (tmp_path / "missing.npz", "no such file"),
                        (tmp_path, "is a folder: give the name of a .npz file"),
                        ("", "No file chosen"),
                        (huge, "huge.npz is damaged: its spline's points are not finite"),
                        (wrong, "wrong.npz is damaged or incomplete \\(its report's 'rms' is "
                                "'x'\\)")):
        with pytest.raises(RuntimeError, match=words):
            import_spline(bpy, path)
        assert (len(bpy.data.objects), len(bpy.data.collections),
                len(bpy.data.meshes)) == before


def test_a_georeferenced_spline_is_imported_near_its_data(clean_scene, tmp_path):
    """A spline of survey data far from the world origin gets an object origin near it, as a
    fit's result does: 32-bit vertex coordinates relative to it keep the engine's precision."""
    bpy = clean_scene
    verts, faces = grid(12, size=50.0, f=lambda x, y: 0.002 * x * y)
    far = verts + [5e5, 4.2e6, 120.0]
    fitted, path = saved_fit(tmp_path, far, grid(12, triangles=True)[1], name="tile.npz")
    assert import_spline(bpy, path, resolution=16) == {"FINISHED"}
    surface = bpy.context.view_layer.objects.active
    origin = np.array(surface.matrix_world.translation)
    assert np.abs(origin).max() > 1e5
    assert np.array_equal(np.array(surface.tcb.net.matrix_world.translation), origin)
    v, _ = spline_of(surface).tessellate(16)
    assert np.abs(positions(surface) + origin - v).max() < 1e-4  # (float32 at 4e6: 0.5)
    assert np.abs(positions(surface.tcb.net) + origin - fitted.control_points).max() < 1e-4


def test_the_command_line_s_spline_of_a_scan_file_links_to_blender_s_import_of_it(
        clean_scene, tmp_path, capfd):
    """The workflow it is for: the command line fits a scan file (on a server, say) and writes
    --spline; Blender imports the same file and the spline, which takes it as its source. PLY
    keeps the file's coordinates; Blender's OBJ importer turns Y-up into Z-up unless told not
    to, which the report names."""
    import importlib

    bpy = clean_scene
    core = core_module()
    meshio = importlib.import_module(core.__name__ + ".meshio")
    cli = importlib.import_module(core.__name__ + ".cli")
    verts, faces = grid(14, f=lambda x, y: 0.25 * np.sin(2 * x + y), triangles=True)
    for ext in ("ply", "obj"):
        meshio.write_mesh(tmp_path / f"scan.{ext}", verts, faces)
    assert cli.main(["fit", str(tmp_path / "scan.ply"), "-o", str(tmp_path / "s.obj"),
                          "--spline", str(tmp_path / "scan.npz"), "--tolerance", "3e-3"]) == 0
    spline = tmp_path / "scan.npz"
    same_axes = dict(forward_axis="Y", up_axis="Z")
    # (the OBJ's text values are rounded to 32-bit floats by Blender: sorted too, they are the
    # same data; user test)
    for ext, axes, linked, shuffle in (("ply", {}, True, False), ("obj", {}, False, False),
                                       ("obj", same_axes, True, False),
                                       ("obj", same_axes, True, True)):
        for o in list(bpy.context.scene.objects):
            bpy.data.objects.remove(o)
        getattr(bpy.ops.wm, f"{ext}_import")(filepath=str(tmp_path / f"scan.{ext}"), **axes)
        scan = bpy.context.selected_objects[0]
        if shuffle:
            with bpy.context.temp_override(**select(bpy, scan)):
                bpy.ops.object.mode_set(mode="EDIT")
                bpy.ops.mesh.select_all(action="SELECT")
                bpy.ops.mesh.sort_elements(type="RANDOMIZE", elements={"VERT", "FACE"})
                bpy.ops.object.mode_set(mode="OBJECT")
            assert not np.array_equal(positions(scan), verts.astype(np.float32))
        capfd.readouterr()
        assert import_spline(bpy, spline, scan) == {"FINISHED"}
        out = capfd.readouterr().out
        surface = bpy.context.view_layer.objects.active
        assert [s.object for s in surface.tcb.sources] == ([scan] if linked else []), (ext, out)
        if not linked:
            assert ("it is the data turned as Blender's OBJ importer turns a file's axes by "
                    "default: clear the scan's rotation, Alt+R, or import it with Forward Y and "
                    "Up Z") in out
            continue
        with bpy.context.temp_override(**select(bpy, surface)):
            assert bpy.ops.tcb.refine(tolerance=1e-3) == {"FINISHED"}


def test_fit_surface_keeps_an_imported_result_and_import_wants_object_mode(clean_scene,
                                                                          tmp_path, capfd):
    """Fit Surface with Replace Previous Result on an imported spline's source makes a new
    result beside it (an import may be a long fit made elsewhere; it had been overwritten, and
    kept the file's names); Import in Edit Mode says to switch (it said "poll() failed")."""
    bpy = clean_scene
    verts, faces = grid(14, triangles=True)
    fitted, path = saved_fit(tmp_path, verts, faces, name="server.npz")
    scan = add_mesh(bpy, "Scan", verts, faces)
    assert import_spline(bpy, path, scan) == {"FINISHED"}
    imported = bpy.context.view_layer.objects.active
    capfd.readouterr()
    with bpy.context.temp_override(**select(bpy, scan)):
        assert bpy.ops.tcb.fit_surface(tolerance=5e-3, resolution=16) == {"FINISHED"}
    assert ("'server TCB Surface' was imported (Import Spline) and was kept: this result is a "
            "new one") in capfd.readouterr().out
    fitted_obj = bpy.context.view_layer.objects.active
    assert fitted_obj != imported and fitted_obj.name == "Scan TCB Surface"
    assert np.array_equal(spline_of(imported).control_points, fitted.control_points)
    # Fit again: the Blender fit is replaced, the import still kept
    with bpy.context.temp_override(**select(bpy, scan)):
        assert bpy.ops.tcb.fit_surface(tolerance=3e-3, resolution=16) == {"FINISHED"}
    assert sorted(o.name for o in bpy.data.objects if o.tcb.role == "SURFACE") == [
        "Scan TCB Surface", "server TCB Surface"]
    with bpy.context.temp_override(**select(bpy, scan)):
        bpy.ops.object.mode_set(mode="EDIT")
        try:
            with pytest.raises(RuntimeError, match=r"Switch to Object Mode \(Tab\) first"):
                bpy.ops.tcb.import_spline(filepath=str(path))
        finally:
            bpy.ops.object.mode_set(mode="OBJECT")
