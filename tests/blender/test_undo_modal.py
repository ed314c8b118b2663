"""Undo/redo of the operators as a user gets them, and the modal (worker-thread) path of Fit,
Refine and Deviation Map driven in the bpy module.

Undo: ``bpy.ops.tcb.x("EXEC_DEFAULT", True, ...)`` (the ``undo`` flag of bpy.ops) pushes an
undo step after the operator, as a click in the UI does; called without it (as the other tests
do) an operator pushes none, and ``ed.undo`` then goes back past it. References to objects do
not survive an undo: they are looked up again by name.

Modal: in the bpy module ``bpy.ops.tcb.x("INVOKE_DEFAULT")`` never reaches a Python ``invoke``
(the window has no event state, so Blender calls ``execute``). :class:`Driver` makes that
``execute`` call the operator's real ``invoke`` with ``bpy.app.background`` seen as False by
the operators module: the job starts on its thread, a real event timer and modal handler are
registered, and the test then plays Blender's event loop, calling ``modal`` with TIMER, ESC and
mouse events. (The reports of an operator driven so are never printed: :class:`OpProxy`
records them.)
"""

from __future__ import annotations

import base64
import hashlib
import inspect
import sys
import time
import types
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scenes import (  # noqa: E402
    ADDON, add_mesh, core_module, failing_fit, fit, grid, move_net_vertex, positions, select,
    spline_of,
)
from test_operators import add_point_cloud, draw_panels, snapshot  # noqa: E402

SURFACE, NET = "Scan TCB Surface", "Scan TCB Net"
WAVE = dict(f=lambda x, y: 0.3 * np.sin(2 * x) * np.cos(2 * y))


def ops_module():
    return sys.modules[ADDON + ".tcb_addon.operators"]


# --- undo helpers -------------------------------------------------------------------------------


def inventory(bpy) -> dict:
    return {kind: sorted(i.name for i in getattr(bpy.data, kind))
            for kind in ("objects", "meshes", "materials", "collections", "node_groups",
                         "pointclouds")}  # fmt: skip


def with_undo(bpy, op, obj, **props):
    """``op`` on ``obj`` with the undo step a click in the UI makes."""
    with bpy.context.temp_override(**select(bpy, obj)):
        return op("EXEC_DEFAULT", True, **props)


def evaluated(bpy, obj) -> np.ndarray:
    return positions(obj.evaluated_get(bpy.context.evaluated_depsgraph_get()))


def state(obj) -> str:
    """A digest of a result object: mesh, custom properties, ``tcb`` settings (pointers by
    name), modifiers, attributes, materials."""
    h = hashlib.sha256(positions(obj).astype(np.float32).tobytes())
    tcb = {}
    for p in obj.tcb.bl_rna.properties:
        if p.identifier in {"rna_type", "sources"}:
            continue
        v = getattr(obj.tcb, p.identifier)
        tcb[p.identifier] = v.name if hasattr(v, "name") else str(v)
    h.update(repr((sorted((k, str(obj[k])) for k in obj.keys()), tcb,
                   [(m.name, m.type) for m in obj.modifiers],
                   sorted(a.name for a in obj.data.attributes),
                   [m.name if m else None for m in obj.data.materials],
                   [s.object.name for s in obj.tcb.sources])).encode())  # fmt: skip
    return h.hexdigest()


def source_with_undo(bpy, kind):
    bpy.ops.ed.undo_push(message="clean scene")
    verts, faces = grid(16, **WAVE)
    if kind == "mesh":
        add_mesh(bpy, "Scan", verts, faces)
    else:
        add_point_cloud(bpy, "Scan", verts)
    bpy.ops.ed.undo_push(message="add the scan")
    return verts


def live_follows_spline(bpy):
    s = bpy.data.objects[SURFACE]
    return np.allclose(evaluated(bpy, s), spline_of(s).tessellate(s.tcb.resolution)[0],
                       atol=1e-5)


# --- undo ---------------------------------------------------------------------------------------


def test_an_operator_called_without_the_undo_flag_pushes_no_undo_step(clean_scene):
    """What a script sees (not a defect of the add-on): only the bpy.ops ``undo`` flag pushes."""
    bpy = clean_scene
    source_with_undo(bpy, "mesh")
    assert fit(bpy, bpy.data.objects["Scan"], tolerance=5e-3, resolution=8) == {"FINISHED"}
    bpy.ops.ed.undo()  # back to the step before "add the scan": the scan goes too
    assert inventory(bpy)["objects"] == []


@pytest.mark.parametrize("kind", ["mesh", "cloud"])
def test_undo_of_fit_leaves_nothing_behind_and_redo_brings_a_working_result(clean_scene, kind):
    bpy = clean_scene
    verts = source_with_undo(bpy, kind)
    before, scan = inventory(bpy), snapshot(bpy.data.objects["Scan"])
    ops_module().clear_cache()
    assert with_undo(bpy, bpy.ops.tcb.fit_surface, bpy.data.objects["Scan"], tolerance=5e-3,
                     max_control_points=200, resolution=16) == {"FINISHED"}
    after, result = inventory(bpy), state(bpy.data.objects[SURFACE])
    text = bpy.data.objects[SURFACE]["tcb_spline"]

    assert bpy.ops.ed.undo() == {"FINISHED"}
    # no surface, net, weights, collection, node group or orphan mesh/material left
    assert inventory(bpy) == before
    assert snapshot(bpy.data.objects["Scan"]) == scan

    assert bpy.ops.ed.redo() == {"FINISHED"}
    assert inventory(bpy) == after
    s, net = bpy.data.objects[SURFACE], bpy.data.objects[NET]
    assert state(s) == result and s["tcb_spline"] == text
    assert s.tcb.net == net and net.tcb.surface == s and s.tcb.sources[0].object.name == "Scan"
    log = draw_panels(bpy, [s])
    assert ("operator", "tcb.refine", True) in log
    # the live net still drives the surface, and undo of a drag puts both back
    j = len(spline_of(s).control_points) // 2
    shown = evaluated(bpy, s)
    move_net_vertex(bpy, net, j, np.array([0.0, 0.0, 0.2]))
    assert np.abs(evaluated(bpy, s) - shown).max() > 1e-2
    bpy.ops.ed.undo_push(message="drag")
    bpy.ops.ed.undo()
    s, net = bpy.data.objects[SURFACE], bpy.data.objects[NET]
    assert np.allclose(positions(net), spline_of(s).control_points, atol=1e-5)
    assert np.allclose(evaluated(bpy, s), shown, atol=1e-6)
    # fitted again after an undo (the fit cache answers): the same result
    bpy.ops.ed.undo()
    assert inventory(bpy) == before
    assert with_undo(bpy, bpy.ops.tcb.fit_surface, bpy.data.objects["Scan"], tolerance=5e-3,
                     max_control_points=200, resolution=16) == {"FINISHED"}
    assert inventory(bpy) == after and bpy.data.objects[SURFACE]["tcb_spline"] == text
    assert live_follows_spline(bpy)
    assert snapshot(bpy.data.objects["Scan"]) == scan
    d = spline_of(bpy.data.objects[SURFACE]).distances(verts)
    assert np.sqrt(np.mean(d**2)) < 5e-3 * np.linalg.norm(np.ptp(verts, axis=0)) * 1.05


def test_each_operator_is_undone_exactly_and_works_again_after_undo(clean_scene):
    bpy = clean_scene
    source_with_undo(bpy, "mesh")
    assert with_undo(bpy, bpy.ops.tcb.fit_surface, bpy.data.objects["Scan"], tolerance=5e-3,
                     max_control_points=200, resolution=16) == {"FINISHED"}
    fitted, objects = state(bpy.data.objects[SURFACE]), inventory(bpy)
    text = bpy.data.objects[SURFACE]["tcb_spline"]
    net0 = positions(bpy.data.objects[NET])

    def undone():
        bpy.ops.ed.undo()
        s = bpy.data.objects[SURFACE]
        assert state(s) == fitted and s["tcb_spline"] == text and inventory(bpy) == objects
        assert np.array_equal(positions(bpy.data.objects[NET]), net0)
        assert live_follows_spline(bpy)
        assert draw_panels(bpy, [s])  # (draws without an error)
        return s

    s = bpy.data.objects[SURFACE]
    assert with_undo(bpy, bpy.ops.tcb.refine, s, tolerance=1e-3,
                     max_control_points=600) == {"FINISHED"}
    refined = bpy.data.objects[SURFACE]["tcb_spline"]
    assert refined != text and live_follows_spline(bpy)
    s = undone()
    assert with_undo(bpy, bpy.ops.tcb.refine, s, tolerance=1e-3,
                     max_control_points=600) == {"FINISHED"}  # again, after the undo
    assert spline_of(bpy.data.objects[SURFACE]).control_points.shape == \
        core_module().TCBSurface.from_bytes(base64.b64decode(refined)).control_points.shape
    s = undone()

    assert with_undo(bpy, bpy.ops.tcb.retessellate, s, resolution=30) == {"FINISHED"}
    assert len(bpy.data.objects[SURFACE].data.vertices) == len(spline_of(s).tessellate(30)[0])
    s = undone()

    assert with_undo(bpy, bpy.ops.tcb.deviation_map, s) == {"FINISHED"}
    s = bpy.data.objects[SURFACE]
    mapped, top = inventory(bpy), s.tcb.deviation_max
    assert s.tcb.has_deviation and s.tcb.deviation_points is not None
    s = undone()  # (no Deviation Points object, material or attribute left)
    assert not s.tcb.has_deviation
    bpy.ops.ed.redo()
    s = bpy.data.objects[SURFACE]
    assert inventory(bpy) == mapped and s.tcb.deviation_max == top
    assert any(e[0] == "label" and e[1].endswith("(max)") for e in draw_panels(bpy, [s]))
    s = undone()
    assert with_undo(bpy, bpy.ops.tcb.deviation_map, s) == {"FINISHED"}
    assert bpy.data.objects[SURFACE].tcb.deviation_max == pytest.approx(top, abs=1e-12)
    s = undone()

    shown = bpy.data.objects[NET].visible_get()
    assert with_undo(bpy, bpy.ops.tcb.toggle_net, s) == {"FINISHED"}
    assert bpy.data.objects[NET].visible_get() != shown
    s = undone()
    assert bpy.data.objects[NET].visible_get() == shown

    assert with_undo(bpy, bpy.ops.tcb.fit_surface, bpy.data.objects["Scan"], tolerance=2e-3,
                     max_control_points=300, resolution=16, replace=True) == {"FINISHED"}
    assert bpy.data.objects[SURFACE]["tcb_spline"] != text
    assert inventory(bpy)["objects"] == objects["objects"]
    assert inventory(bpy)["meshes"] == objects["meshes"]  # (the same names)
    s = undone()
    assert with_undo(bpy, bpy.ops.tcb.fit_surface, bpy.data.objects["Scan"], tolerance=2e-3,
                     max_control_points=300, resolution=16, replace=False) == {"FINISHED"}
    assert len(inventory(bpy)["objects"]) == len(objects["objects"]) + 3
    undone()


def test_refine_retessellate_and_a_replacing_fit_keep_the_mesh_names(clean_scene):
    """Every rewrite had given the surface, net and weights a new mesh named after the old
    one, which still held the name: 'Scan TCB Surface.001', '.002', ... (user test)."""
    bpy = clean_scene
    src = add_mesh(bpy, "Scan", *grid(16))
    assert fit(bpy, src, tolerance=5e-3, resolution=16) == {"FINISHED"}
    s = bpy.data.objects[SURFACE]
    names = (s.data.name, s.tcb.net.data.name, s.tcb.weights.data.name)
    assert names == (SURFACE, NET, SURFACE + " Weights")
    with bpy.context.temp_override(**select(bpy, s)):
        assert bpy.ops.tcb.retessellate(resolution=20) == {"FINISHED"}
        assert bpy.ops.tcb.refine(tolerance=1e-3) == {"FINISHED"}
    assert fit(bpy, src, tolerance=2e-3, resolution=16) == {"FINISHED"}
    assert (s.data.name, s.tcb.net.data.name, s.tcb.weights.data.name) == names
    with bpy.context.temp_override(**select(bpy, s)):
        assert bpy.ops.tcb.deviation_map() == {"FINISHED"}
        assert bpy.ops.tcb.deviation_map() == {"FINISHED"}  # (the points' mesh rewritten)
    assert s.tcb.deviation_points.data.name == SURFACE + " Deviation Points"
    assert not any(m.name.endswith((".001", ".002")) for m in bpy.data.meshes)


def test_undo_of_refine_brings_the_edits_of_the_net_back(clean_scene):
    """Refine says "Ctrl+Z brings the edits back": it does, and the live surface shows them."""
    bpy = clean_scene
    source_with_undo(bpy, "mesh")
    assert with_undo(bpy, bpy.ops.tcb.fit_surface, bpy.data.objects["Scan"], tolerance=5e-3,
                     max_control_points=200, resolution=16) == {"FINISHED"}
    s, net = bpy.data.objects[SURFACE], bpy.data.objects[NET]
    j = len(spline_of(s).control_points) // 2
    edited = move_net_vertex(bpy, net, j, np.array([0.0, 0.0, 0.2]))
    bpy.ops.ed.undo_push(message="drag")
    shown = evaluated(bpy, s)
    assert with_undo(bpy, bpy.ops.tcb.refine, s, tolerance=1e-3,
                     max_control_points=600) == {"FINISHED"}
    bpy.ops.ed.undo()
    assert np.allclose(positions(bpy.data.objects[NET]), edited, atol=1e-6)
    assert np.allclose(evaluated(bpy, bpy.data.objects[SURFACE]), shown, atol=1e-6)


# --- the modal path -----------------------------------------------------------------------------


def EV(kind, value="NOTHING"):
    return SimpleNamespace(type=kind, value=value)


class _App:
    background = False

    def __init__(self, real):
        self._real = real

    def __getattr__(self, key):
        return getattr(self._real, key)


class BpyProxy(types.ModuleType):
    """``bpy`` with ``app.background`` False, for the operators module only."""

    def __init__(self, real):
        super().__init__("bpy")
        self.__dict__.update(_real=real, app=_App(real.app))

    def __getattr__(self, key):
        return getattr(self._real, key)


class OpProxy:
    """The operator, with ``report`` recorded: Python methods run with the proxy as ``self``,
    the rest (RNA properties) goes to the operator. (A bpy_struct finds the RNA ``report``
    before a Python override.)"""

    def __init__(self, op, sink):
        object.__setattr__(self, "_op", op)
        object.__setattr__(self, "_sink", sink)

    def report(self, kind, msg):
        self._sink.append((sorted(kind)[0], msg))

    def __getattr__(self, key):
        try:
            static = inspect.getattr_static(type(self._op), key)
        except AttributeError:
            static = None
        if inspect.isfunction(static):
            return static.__get__(self)
        return getattr(self._op, key)

    def __setattr__(self, key, value):
        setattr(self._op, key, value)


class Driver:
    """Calls ``bpy.ops.tcb.<op>("INVOKE_DEFAULT")`` so that the operator's own ``invoke``
    runs as in the UI, and feeds its ``modal`` the events of Blender's loop."""

    def __init__(self, bpy, monkeypatch):
        self.bpy, self.reports, self.armed = bpy, [], False
        ops = ops_module()
        real_execute = ops._EngineOperator.execute
        driver = self

        def execute(op, context):  # INVOKE_DEFAULT reaches execute in the bpy module
            if not driver.armed or getattr(op, "_driven", False):
                return real_execute(op, context)  # (a plain call, or invoke's fallback)
            op._driven = True
            driver.op = op
            driver.invoked = type(op).invoke(op, context, EV("LEFTMOUSE", "PRESS"))
            return driver.invoked

        monkeypatch.setattr(ops._EngineOperator, "execute", execute)
        monkeypatch.setattr(ops, "bpy", BpyProxy(bpy))

    def invoke(self, op, obj, **props):
        self.op, self.armed = None, True
        try:
            with self.bpy.context.temp_override(**select(self.bpy, obj)):
                return op("INVOKE_DEFAULT", **props)
        finally:
            self.armed = False

    def modal(self, event):
        return ops_module()._EngineOperator.modal(OpProxy(self.op, self.reports),
                                                  self.bpy.context, event)

    def run(self, esc_after=None, timeout=120.0):
        """TIMER events every 20 ms (ESC after ``esc_after`` of them) until the operator ends;
        (its result, the number of TIMER events)."""
        t0, n = time.perf_counter(), 0
        while time.perf_counter() - t0 < timeout:
            if n == esc_after:
                assert self.modal(EV("ESC", "PRESS")) == {"RUNNING_MODAL"}
            result = self.modal(EV("TIMER"))
            n += 1
            if result != {"RUNNING_MODAL"}:
                self.done()
                return result, n
            time.sleep(0.02)
        raise TimeoutError

    def done(self):
        # Blender still holds the handler (it never saw the modal end): at the next file load
        # it calls cancel(), which must then do nothing
        assert self.op._timer is None and self.op._job.done
        self.op._job = None


@pytest.fixture
def driver(installed, monkeypatch):
    return Driver(installed, monkeypatch)


def test_invoke_default_in_the_bpy_module_never_reaches_a_python_invoke(clean_scene, addon,
                                                                        monkeypatch):
    """Why test_background_invoke_runs_synchronously does not test ``invoke``: Blender calls
    ``execute`` directly."""
    bpy = clean_scene
    ops = ops_module()
    calls = []
    monkeypatch.setattr(ops._EngineOperator, "invoke",
                        lambda self, c, e: calls.append(1) or {"CANCELLED"})
    obj = add_mesh(bpy, "Patch", *grid(10))
    with bpy.context.temp_override(**select(bpy, obj)):
        assert bpy.ops.tcb.fit_surface("INVOKE_DEFAULT", tolerance=5e-3, resolution=8) == {
            "FINISHED"}
    assert calls == []


def devs(obj):
    a = obj.data.attributes["tcb_deviation"]
    out = np.empty(len(a.data), np.float32)
    a.data.foreach_get("value", out)
    return out


def test_modal_fit_refine_and_deviation_map_give_the_execute_results(clean_scene, driver,
                                                                     tmp_path):
    bpy = clean_scene
    ops = ops_module()
    verts, faces = grid(20, **WAVE)
    add_mesh(bpy, "Scan", verts, faces)
    path = str(tmp_path / "scan.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    ops.clear_cache()
    props = dict(tolerance=2e-3, max_control_points=300, resolution=16)
    assert fit(bpy, bpy.data.objects["Scan"], **props) == {"FINISHED"}
    s = bpy.data.objects[SURFACE]
    with bpy.context.temp_override(**select(bpy, s)):
        assert bpy.ops.tcb.refine(tolerance=5e-4, max_control_points=900) == {"FINISHED"}
        assert bpy.ops.tcb.deviation_map() == {"FINISHED"}
    s = bpy.data.objects[SURFACE]
    expect = (spline_of(s), len(s.data.vertices), positions(s.tcb.net), devs(s),
              devs(s.tcb.deviation_points))

    bpy.ops.wm.open_mainfile(filepath=path)
    ops.clear_cache()
    before = inventory(bpy)
    assert driver.invoke(bpy.ops.tcb.fit_surface, bpy.data.objects["Scan"], **props) == {
        "RUNNING_MODAL"}
    assert driver.op._timer is not None and inventory(bpy) == before  # nothing made yet
    for event in (EV("MOUSEMOVE"), EV("MIDDLEMOUSE", "PRESS")):  # the view may move
        assert driver.modal(event) == {"PASS_THROUGH"}
    assert driver.modal(EV("A", "PRESS")) == {"RUNNING_MODAL"}  # the rest waits
    assert driver.run()[0] == {"FINISHED"}
    assert [k for k, _ in driver.reports] == ["INFO"]
    assert bpy.context.view_layer.objects.active.name == SURFACE
    # (the cached result: FINISHED straight from invoke, no job)
    assert driver.invoke(bpy.ops.tcb.fit_surface, bpy.data.objects["Scan"], **props) == {
        "FINISHED"}

    statuses = []
    status = ops._EngineOperator._status
    ops._EngineOperator._status = lambda self, c, t: (statuses.append(t), status(self, c, t))
    try:
        assert driver.invoke(bpy.ops.tcb.refine, bpy.data.objects[SURFACE], tolerance=5e-4,
                             max_control_points=900) == {"RUNNING_MODAL"}
        assert driver.run()[0] == {"FINISHED"}
    finally:
        ops._EngineOperator._status = status
    assert any(t and t.startswith("TCB: Refining, iteration") for t in statuses)
    assert statuses[-1] is None  # the status bar is given back

    assert driver.invoke(bpy.ops.tcb.deviation_map, bpy.data.objects[SURFACE]) == {
        "RUNNING_MODAL"}
    assert driver.run()[0] == {"FINISHED"}
    s = bpy.data.objects[SURFACE]
    surf = spline_of(s)
    assert np.array_equal(surf.coefficients, expect[0].coefficients)
    assert np.array_equal(surf.parameterization.uv, expect[0].parameterization.uv)
    assert len(s.data.vertices) == expect[1]
    assert np.array_equal(positions(s.tcb.net), expect[2])
    assert np.array_equal(devs(s), expect[3])
    assert np.array_equal(devs(s.tcb.deviation_points), expect[4])


def test_esc_and_errors_in_the_worker_change_nothing(clean_scene, driver, monkeypatch):
    bpy = clean_scene
    ops, core = ops_module(), core_module()
    verts, faces = grid(16, **WAVE)
    src = add_mesh(bpy, "Scan", verts, faces)
    assert fit(bpy, src, tolerance=5e-3, resolution=16) == {"FINISHED"}
    s = bpy.data.objects[SURFACE]
    before = (inventory(bpy), state(s), positions(s.tcb.net), snapshot(src))

    def unchanged():
        s = bpy.data.objects[SURFACE]
        return ((inventory(bpy), state(s), snapshot(src)) == (before[0], before[1], before[3])
                and np.array_equal(positions(s.tcb.net), before[2]))

    cancelled = [("WARNING", "TCB: cancelled; nothing was changed")]
    monkeypatch.setattr(core.surface, "CLOSEST_CHUNK", 16)  # (the map's Esc is seen)
    for op, obj, props in (
        (bpy.ops.tcb.fit_surface, src, dict(tolerance=1e-6, max_control_points=5000,
                                            resolution=16, replace=False)),
        (bpy.ops.tcb.refine, s, dict(tolerance=1e-6, max_control_points=5000)),
        (bpy.ops.tcb.deviation_map, s, {}),
    ):
        driver.reports.clear()
        assert driver.invoke(op, obj, **props) == {"RUNNING_MODAL"}
        assert driver.run(esc_after=0)[0] == {"CANCELLED"}
        assert driver.reports == cancelled
        assert unchanged()

    def refused(engine, words):
        """Fit through the modal path with ``engine`` as core.fit_surface: the ERROR report
        ``words``, CANCELLED, nothing changed."""
        monkeypatch.setattr(core, "fit_surface", engine)
        driver.reports.clear()
        assert driver.invoke(bpy.ops.tcb.fit_surface, src, tolerance=1e-4,
                             resolution=16) == {"RUNNING_MODAL"}
        assert driver.run()[0] == {"CANCELLED"}
        assert driver.reports == [("ERROR", words)]
        assert unchanged()

    ops.clear_cache()
    refused(failing_fit(core), "injected failure at iteration 2")

    def bad_input(*args, **kwargs):  # found by the engine: named after the object
        raise core.InvalidInputError("the points are all on one line")

    refused(bad_input, "'Scan': the points are all on one line")

    def bug(*args, **kwargs):  # not a user error: raised to Blender, after the clean-up
        raise KeyError("a bug")

    monkeypatch.setattr(core, "fit_surface", bug)
    assert driver.invoke(bpy.ops.tcb.fit_surface, src, tolerance=1e-4,
                         resolution=16) == {"RUNNING_MODAL"}
    with pytest.raises(KeyError, match="a bug"):
        driver.run()
    assert driver.op._timer is None
    driver.op._job = None
    assert unchanged()


def test_loading_a_file_during_the_modal_cancels_the_job(clean_scene, driver, tmp_path,
                                                         monkeypatch):
    """Blender calls ``cancel()`` when a file is loaded while the operator runs."""
    bpy = clean_scene
    ops = ops_module()
    path = str(tmp_path / "other.blend")
    bpy.ops.wm.save_as_mainfile(filepath=path)
    src = add_mesh(bpy, "Scan", *grid(16, **WAVE))
    ops.clear_cache()
    assert driver.invoke(bpy.ops.tcb.fit_surface, src, tolerance=1e-6, max_control_points=5000,
                         resolution=16) == {"RUNNING_MODAL"}
    job = driver.op._job
    calls = []
    real_cancel = ops._EngineOperator.cancel

    def cancel(self, context):
        real_cancel(self, context)
        calls.append((self._job is job, self._timer))

    monkeypatch.setattr(ops._EngineOperator, "cancel", cancel)
    bpy.ops.wm.open_mainfile(filepath=path)
    job.thread.join(60)
    assert [timer for mine, timer in calls if mine] == [None]  # once, its timer removed
    assert job.cancel and not job.thread.is_alive()
    assert "Scan" not in bpy.data.objects


def test_re_tessellate_runs_on_the_job_thread_with_progress_and_esc_keeps_the_old_mesh(
        clean_scene, driver, monkeypatch):
    """Re-tessellate at 2048 took 41 s with no progress and no way out (user test): it runs
    like Fit, on the job's thread, with the share of the vertices done in the status bar and
    Esc to cancel, which leaves the surface, its live net's weights and the file as they were
    (also while the grid is laid out, before the first vertex); run to the end it gives the
    mesh and weights of the synchronous path."""
    bpy = clean_scene
    ops, core = ops_module(), core_module()
    src = add_mesh(bpy, "Scan", *grid(16, **WAVE))
    assert fit(bpy, src, tolerance=5e-3, resolution=16) == {"FINISHED"}
    s = bpy.data.objects[SURFACE]
    assert s.tcb.weights is not None  # (a live net: its weights are remade too)
    before = (inventory(bpy), state(s), state(s.tcb.weights), len(s.data.vertices))
    monkeypatch.setattr(core.surface, "CLOSEST_CHUNK", 64)  # (many chunks: Esc is seen)
    driver.reports.clear()
    assert driver.invoke(bpy.ops.tcb.retessellate, s, resolution=48) == {"RUNNING_MODAL"}
    assert driver.run(esc_after=0)[0] == {"CANCELLED"}
    assert driver.reports == [("WARNING", "TCB: cancelled; nothing was changed")]
    s = bpy.data.objects[SURFACE]
    assert (inventory(bpy), state(s), state(s.tcb.weights), len(s.data.vertices)) == before

    statuses = []
    status = ops._EngineOperator._status
    monkeypatch.setattr(ops._EngineOperator, "_status",
                        lambda self, c, t: (statuses.append(t), status(self, c, t)))
    assert driver.invoke(bpy.ops.tcb.retessellate, s, resolution=48) == {"RUNNING_MODAL"}
    assert driver.run()[0] == {"FINISHED"}
    assert any(t and t.startswith("TCB: Re-tessellating, ") and t.endswith(
        " points (Esc to cancel)") for t in statuses), statuses
    # before the vertices, the grid's steps (6-8 s at 2048, when Esc had not been heard):
    # Esc stops the job at the first (the status shows it; this small grid takes milliseconds,
    # which the modal's timer may not see)
    job = ops._Job(ops._tessellation, dict(surf=spline_of(s), resolution=47, weights=True))
    job.cancel = True
    job.start().thread.join(60)
    assert isinstance(job.error, core.CancelledError) and job.result is None
    steps = core.surface.TESSELLATION_SPLITS + 3
    assert job.progress == {"grid_step": 1, "grid_steps": steps}
    assert ops.progress_text(job.progress, "Re-tessellating") == (
        f"TCB: Re-tessellating, laying out the mesh, step 1 of {steps} (Esc to cancel)")
    assert statuses[-1] is None
    s = bpy.data.objects[SURFACE]
    modal = (positions(s), state(s.tcb.weights), s.tcb.resolution)
    assert s.tcb.resolution == 48 and len(s.data.vertices) > before[3]
    with bpy.context.temp_override(**select(bpy, s)):
        assert bpy.ops.tcb.retessellate(resolution=16) == {"FINISHED"}
        assert bpy.ops.tcb.retessellate(resolution=48) == {"FINISHED"}
    s = bpy.data.objects[SURFACE]
    assert np.allclose(positions(s), modal[0], atol=1e-6) and state(s.tcb.weights) == modal[1]
    # the weights drive the mesh: the net's surface where it is
    uv, _ = spline_of(s).tessellation_uv(48)
    assert np.allclose(evaluated(bpy, s), spline_of(s)(uv), atol=1e-5)
