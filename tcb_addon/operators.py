"""Operators (``bpy.ops.tcb.*``): fit, refine, re-tessellate, deviation map, net, export,
import.

Thin: the fit is ``core.fit_surface`` / ``TCBSurface.refine``; this module reads the selection
(``bridge``), runs the engine and writes the results. Long runs: ``invoke`` starts the engine
in a worker thread and a modal timer polls it (status text, progress cursor, Esc cancels; only
the main thread touches bpy); ``execute`` runs synchronously (background mode, scripts, redo).
Errors become ``self.report({'ERROR'}, message)`` and ``{'CANCELLED'}`` with nothing changed.
"""

from __future__ import annotations

import base64
import hashlib
import os
import threading
import time
import warnings as _warnings
import weakref

import bpy
import numpy as np
from bpy.props import (BoolProperty, CollectionProperty, FloatProperty, IntProperty,
                       StringProperty)
from bpy_extras.io_utils import ExportHelper, ImportHelper

from . import bridge, live
from .properties import (DEFAULT_SMOOTHNESS, FIT_KEYS, MAX_RESOLUTION, MIN_BUDGET, FitSettings,
                         ResultSettings, draw_fit_settings)

# Custom property of the surface object: TCBSurface.to_bytes(compact=True) as base64 text (the
# data's parameters and errors in float32: half the .blend size of float64, and the
# coordinates Blender holds are float32 anyway). (Raw bytes ID properties lose everything
# after the first NUL byte when an existing one is reassigned.)
SPLINE_KEY = "tcb_spline"
# the surface object's world matrix when its mesh was last written from the spline (16 floats)
PLACED_KEY = "tcb_placed_at"
DEVIATION_ATTR = "tcb_deviation"
# the part of its source a surface was fitted to, when a part (faces selected in Edit Mode):
# bridge.part_text; absent for all of it
PART_KEY = "tcb_source_part"
# a surface made by Import Spline: the file's path (Fit Surface with Replace Previous Result
# leaves it and makes a new result: it may be a long fit's, made elsewhere)
IMPORTED_KEY = "tcb_imported_from"
# an object Import Points made of a DEM raster (.asc grid, .npz elevation, x y z text on a grid
# of x and y: core.meshio.is_dem): heights over its x and y, which Fit Surface with Projection Auto fits along the object's z (on
# its tilted best-fit plane a sloping tile's surface reached past its straight edges)
RASTER_KEY = "tcb_raster"


def _core():
    from .. import core  # the extension's own engine (bl_ext.<repo>.tcb_surface.core)

    return core


def _user_errors():
    """Exceptions whose message is shown to the user as is."""
    core = _core()
    return (bridge.SelectionError, core.TCBError, ValueError)


def _refused_file(op, ex: Exception) -> set:
    """An import operator's ERROR report of ``ex`` (a message for the user, or an OSError
    reading ``op.filepath``) and ``{'CANCELLED'}``."""
    op.report({"ERROR"}, _refusal_text(ex, op.filepath))
    return {"CANCELLED"}


def _refusal_text(ex: Exception, filepath: str) -> str:
    """The words of ``ex``: a message for the user, or an OSError reading ``filepath``."""
    if isinstance(ex, _user_errors()):
        return str(ex)
    return f"Could not read {filepath}: {ex.strerror or ex}"


def check_settings(op, automatic: bool = False) -> None:
    """A :class:`bridge.SelectionError` naming each numeric setting of ``op`` (those it has of
    Tolerance, Max Control Points, Max Iterations, Smoothness and Resolution) out of its range;
    with ``automatic`` (Refine) a Tolerance or Max Control Points of 0 means automatic. The
    properties have soft limits only (properties.py: hard ones clamped without a word)."""
    words = []
    tol = getattr(op, "tolerance", None)
    if tol is not None and not (np.isfinite(tol) and 0 <= tol < 1e30):
        zero = "automatic" if automatic else "refine to Max Control Points"
        # (the limit said: "0 or more" had been said of 1e30; user test)
        words.append(f"Tolerance must be at least 0 and less than 1e+30 (0: {zero}), got "
                     f"{tol:g}")
    budget = getattr(op, "max_control_points", None)
    if budget is not None and budget < MIN_BUDGET and not (automatic and budget == 0):
        words.append(f"Max Control Points must be {'0 (automatic) or ' * automatic}at least "
                     f"{MIN_BUDGET}, got {budget}")
    iterations = getattr(op, "max_iterations", None)
    if iterations is not None and iterations < 1:
        words.append(f"Max Iterations must be at least 1, got {iterations}")
    smoothness = getattr(op, "smoothness", None)
    if (smoothness is not None and not getattr(op, "auto_smoothness", False)
            and not (np.isfinite(smoothness) and 0 <= smoothness < 1e30)):
        words.append(f"Smoothness must be at least 0 and less than 1e+30, got {smoothness:g}")
    resolution = getattr(op, "resolution", None)
    if resolution is not None and not 2 <= resolution <= MAX_RESOLUTION:
        words.append(f"Resolution must be between 2 and {MAX_RESOLUTION}, got {resolution}")
    if words:
        raise bridge.SelectionError("; ".join(words))


# --- a small cache so that redo (Adjust Last Operation) does not refit what did not change ---

_FIT_CACHE: dict = {}
_FIT_CACHE_SIZE = 2


def _cache_get(key):
    """(surface, the engine's warnings, the operator's seconds) of a fit, or None."""
    return _FIT_CACHE.get(key)


def _cache_put(key, surf, notes=(), seconds=None):
    _FIT_CACHE.pop(key, None)
    _FIT_CACHE[key] = (surf, list(notes), seconds)
    while len(_FIT_CACHE) > _FIT_CACHE_SIZE:
        _FIT_CACHE.pop(next(iter(_FIT_CACHE)))


def clear_cache():
    _FIT_CACHE.clear()


# --- helpers ----------------------------------------------------------------------------------


def progress_text(report: dict | None, what: str = "Fitting") -> str:
    """The status-bar line of a running job: a fit's iteration report, the closest
    points' ``{"points_done", "points"}``, or a tessellation's ``{"grid_step", "grid_steps"}``."""
    if not report:
        return f"TCB: {what}... (Esc to cancel)"
    if "grid_step" in report:  # (Re-tessellate, before its vertices: seconds at 2048)
        return (f"TCB: {what}, laying out the mesh, step {report['grid_step']} of "
                f"{report['grid_steps']} (Esc to cancel)")
    if "points_done" in report:
        return (f"TCB: {what}, {progress_percent(report)}% of {report['points']:,} points "
                "(Esc to cancel)")
    parts = [f"TCB: {what}", f"iteration {report.get('iteration', '?')}"]
    if "control_points" in report:
        parts.append(f"{report['control_points']} control points")
    if "rms_rel" in report and "max_rel" in report:
        parts.append(f"RMS {report['rms_rel']:.3g}, max {report['max_rel']:.3g} of diagonal")
    return ", ".join(parts) + " (Esc to cancel)"


def progress_percent(report: dict | None, iteration_offset: int = 0,
                     max_iterations: int = 20) -> int:
    """How far a running job is, 0-99 (the progress bar): the share of the points done, or
    this run's iterations of ``max_iterations`` (Refine's reports go on from the fit's
    numbers: ``iteration_offset``)."""
    report = report or {}
    if "points_done" in report:
        return min(99, int(100 * report["points_done"] / max(1, report["points"])))
    it = report.get("iteration", 0) - iteration_offset
    return min(99, max(0, int(100 * it / max(1, max_iterations))))


def result_objects(obj):
    """(surface, net) of a result object (either one may be given), or (None, None)."""
    if obj is None:
        return None, None
    role = obj.tcb.role
    if role == "SURFACE":
        return obj, obj.tcb.net
    surface = obj.tcb.surface
    # a surface deleted from the scene (X) lives on while its net points to it: not a result
    if role in {"NET", "DEVIATION", "WEIGHTS"} and surface is not None and surface.users_scene:
        return surface, surface.tcb.net
    return None, None


def drop_deviation_points(surface_obj) -> bool:
    """Remove the surface's Deviation Points object (the distances of the data to a surface
    that has just been replaced); whether there was one."""
    pts = surface_obj.tcb.deviation_points
    if pts is None:
        return False
    surface_obj.tcb.deviation_points = None
    mesh = pts.data if pts.type == "MESH" else None
    bpy.data.objects.remove(pts)
    if mesh is not None and mesh.users == 0:
        bpy.data.meshes.remove(mesh)
    return True


def active_surface(context):
    return result_objects(getattr(context, "active_object", None))[0]


def linked_problem(*objs) -> str | None:
    """Why a result cannot be rewritten: one of ``objs`` (or its mesh) is linked from another
    .blend file, read-only (Refine, Re-tessellate and Deviation Map had reported success, and
    the work was gone when the file was saved: user test); None when all are local."""
    for ob in objs:
        if ob is None:
            continue
        lib = ob.library or getattr(ob.data, "library", None)
        if lib is not None:
            return (f"'{ob.name}' is linked from {bpy.path.basename(lib.filepath)}, read-only: "
                    "its changes could not be saved; make it local first (Object > Relations "
                    "> Make Local > Selected Objects and Data)")
    return None


def editable_surface(context, what: str = ""):
    """The active TCB surface, local (not linked: :func:`linked_problem`); a
    :class:`bridge.SelectionError` saying what is missing otherwise."""
    surface = active_surface(context)
    if surface is None:
        raise bridge.SelectionError(no_surface_words(context, what))
    problem = linked_problem(surface, surface.tcb.net) or converted_problem(surface)
    if problem:
        raise bridge.SelectionError(problem[0].upper() + problem[1:])
    return surface


def converted_problem(surface_obj) -> str | None:
    """Why the surface cannot be rewritten, or None: it was converted to another type of
    object (Object > Convert), so it has no mesh to write (Refine, Re-tessellate and
    Deviation Map ended in a traceback, Refine after the whole refit: user test)."""
    if surface_obj.type == "MESH":
        return None
    return (f"'{surface_obj.name}' is no longer a mesh (it was converted to "
            f"{surface_obj.type.replace('_', ' ').title()}): Refine, Re-tessellate and Deviation "
            "Map rewrite the surface's mesh; Fit Surface makes a new surface from the source "
            "(Export Spline still saves its spline)")


def _poll_object_mode(op_cls, context, surface: bool = True) -> bool:
    """The operators' poll: Object Mode and (``surface``) an active TCB surface or net, with
    Blender's poll message saying which is missing (F3 search or a script got only "poll()
    failed, context is incorrect" in Edit Mode: user test)."""
    if context.mode != "OBJECT":
        # Tab leaves Edit Mode, but in Sculpt or a paint mode it goes to Edit Mode (user test)
        op_cls.poll_message_set(
            "Switch to Object Mode (Tab) first" if context.mode.startswith("EDIT") else
            "Switch to Object Mode first (the mode menu in the 3D Viewport's header)")
        return False
    if surface and active_surface(context) is None:
        op_cls.poll_message_set(no_surface_words(context))
        return False
    return True


def no_surface_words(context, what: str = "") -> str:
    """What to select when no TCB surface is active (``what``: for what, e.g. " to refine"):
    a net (or another part of a result) whose surface was deleted with X says so (it had said
    "Select a TCB surface (or its control net)" with the net selected: user test)."""
    obj = getattr(context, "active_object", None)
    if obj is not None and obj.tcb.role in {"NET", "DEVIATION", "WEIGHTS"}:
        return (f"The TCB surface of '{obj.name}' was deleted: select the source and use Fit "
                "Surface to make a new one")
    return f"Select a TCB surface (or its control net){what}"


def stored_surface(surface_obj, use_net: bool = True):
    """The spline stored with a result; with ``use_net``, the net's current vertices as controls."""
    core = _core()
    blob = surface_obj.get(SPLINE_KEY)
    if blob is None:
        raise bridge.SelectionError(
            f"'{surface_obj.name}' carries no spline data: fit it again from the source"
        )
    try:
        data = base64.b64decode(blob, validate=True)
    except (TypeError, ValueError):
        raise bridge.SelectionError(
            f"The spline data stored with '{surface_obj.name}' is damaged: fit it again"
        ) from None
    surf = core.TCBSurface.from_bytes(data, what=f"the spline stored with '{surface_obj.name}'")
    return with_net_edits(surface_obj, surf) if use_net else surf


def with_net_edits(surface_obj, surf):
    """``surf`` (the stored spline) with the control points edited on the net."""
    net = surface_obj.tcb.net
    if net is not None and net.type == "MESH":
        if net.mode == "EDIT":  # a drag in Edit Mode is in the edit mesh until it is loaded
            net.update_from_editmode()
        ctrl, rounding = bridge.read_world_positions_and_rounding(net)
        rounding = rounding + float(net.get(NET_ROUNDING_KEY, 0.0))  # (and as written)
        # a net saved before control points left out the border rings' functions has a
        # vertex per basis function: its edits are kept and it is rewritten in today's form
        old_net = len(ctrl) == len(surf.coefficients) != len(surf.control_points)
        ref = surf.coefficients if old_net else surf.control_points
        if len(ctrl) == len(ref):
            # The net holds the control points rounded to 32 bits (at most half a spacing
            # away): a coordinate farther from the stored one than a spacing was edited and
            # takes the net's value; the others keep the stored float64 value.
            edited = np.abs(ctrl - ref) > rounding + 8 * np.spacing(np.abs(ref))
            if edited.any():
                surf = surf.with_control_points(np.where(edited, ctrl, ref))
        if old_net:
            write_net_mesh(net, surf)
    return surf


def is_max(tcb) -> bool:
    """The tolerance of a result bounds the max error (its stored criterion is the settings'
    enum, "MAX"), not the RMS."""
    return str(tcb.criterion).lower() == "max"


def uneven_density(rms: float, rms_area: float) -> bool:
    """A cloud's RMS over its area tells more than its RMS over points (uneven density: the
    fit met the tolerance by both, core.refine.adaptive_fit)."""
    return rms_area > 1.1 * rms


def net_copy_note(obj) -> str | None:
    """For a copy of a control net (Shift+D of the net alone): that its surface follows the
    original, so its edits change nothing (a linked duplicate, Alt+D, shares the net's mesh:
    that its edits move the surface); None for any other object."""
    surface, net = result_objects(obj)
    if surface is None or obj.tcb.role != "NET" or net is None or net == obj:
        return None
    if obj.data is not None and obj.data == net.data:  # Alt+D: the same mesh (user test)
        return (f"'{obj.name}' shares its mesh with the control net '{net.name}' (a linked "
                f"duplicate): its edits move '{surface.name}' too")
    return (f"'{obj.name}' is a copy of the control net: '{surface.name}' follows "
            f"'{net.name}', so edits here change nothing")


def live_link_problem(surface_obj) -> str | None:
    """Why the live net does not drive the surface, or None: its hidden weights object was
    deleted (an outliner clean-up), so drags of the net change nothing until Re-tessellate,
    Refine or Deviation Map rebuilds it (user test: nothing said so)."""
    if surface_obj.modifiers.get(live.MODIFIER_NAME) is None or surface_obj.tcb.weights is not None:
        return None
    return ("the live link is broken (its hidden weights object was deleted): drags of the net "
            "do not move the surface; Re-tessellate restores it")


def _names(mods) -> str:
    return ", ".join(f"'{m.name}'" for m in mods)


def net_modifier_problem(surface_obj) -> str | None:
    """Why the live surface does not show the net's own vertices, or None: modifiers on the
    net change the points the live link reads (a Wireframe or Skin, to see the cage, made the
    surface garbage half a diagonal off; a Smooth moved it 3%; user test), while Refine and
    Export Spline use the net's own vertices. With modifiers that add or remove vertices the
    live surface stays on the stored spline (the node group of :mod:`live`)."""
    net = surface_obj.tcb.net
    if net is None or net.type != "MESH" or surface_obj.modifiers.get(live.MODIFIER_NAME) is None:
        return None
    mods = [m for m in net.modifiers if m.show_viewport or m.show_render]
    if not mods:
        return None
    return (f"modifiers on the control net '{net.name}' ({_names(mods)}) change the points the "
            "live surface follows, while Refine and Export Spline use the net's own vertices: "
            "turn them off or remove them")


def net_shape_keys(net) -> list:
    """The names of the shape keys of the control net ``net`` besides its basis (the reference
    key, the net's own vertices): none for no net."""
    keys = net.data.shape_keys if net is not None and net.type == "MESH" else None
    if keys is None:
        return []
    return [kb.name for kb in keys.key_blocks if kb != keys.reference_key]


def net_shape_key_problem(surface_obj) -> str | None:
    """Why an edit of the control net through shape keys is not in the spline, or None. The
    live surface follows the net as shown, shape keys mixed in, while Export Spline, Refine
    and the Deviation Map read the net's own vertices (its basis), as with modifiers on the
    net (:func:`net_modifier_problem`): an edit made in a shape key was exported and measured
    as if not made, and Refine removed the keys without a word (user test). Not read as
    edits: a mix of keys is animated and a spline is one shape; Apply All (Shape Key Specials)
    makes the mix the net's own vertices."""
    net = surface_obj.tcb.net
    keys = net_shape_keys(net)
    if not keys:
        return None
    many = len(keys) > 1
    live_net = surface_obj.modifiers.get(live.MODIFIER_NAME) is not None
    return (f"the control net '{net.name}' has the shape key{'s' * many} {_quoted(keys)}"
            + (", whose mix the live surface follows, while" if live_net else ":")
            + " Export Spline, Refine and Deviation Map use the net's own vertices (its basis), "
            f"and Refine removes the key{'s' * many}: to keep the shape, apply "
            f"{'them' if many else 'it'} to the net (Object Data > Shape Keys > Shape Key "
            "Specials > Apply All), else delete "
            + ("them" if many else "it"))


def stack_problem(surface_obj) -> str | None:
    """Why the live net may not drive the surface, or None: modifiers above the live-net
    modifier in the surface's stack (one that adds vertices makes the live link pass the mesh
    through; any other is overwritten). Fit, Refine and Re-tessellate put it first."""
    mods = list(surface_obj.modifiers)
    ours = surface_obj.modifiers.get(live.MODIFIER_NAME)
    if ours is None:
        return None
    above = [m for m in mods[: mods.index(ours)] if m.show_viewport or m.show_render]
    if not above:
        return None
    return (f"{_names(above)} above '{live.MODIFIER_NAME}' in the surface's modifier stack: "
            "the net's edits may not show; move it to the top (Re-tessellate does)")


def net_vertex_problem(surface_obj) -> str | None:
    """Why the edits of the surface's control net are ignored, or None: a vertex was added to
    or deleted from the net, so its vertices no longer match the control points one to one
    (:func:`with_net_edits` and the live surface then use the stored spline)."""
    net = surface_obj.tcb.net
    if net is None or net.type != "MESH":
        return None
    n, m = len(net.data.vertices), surface_obj.tcb.control_points
    if m == 0 or n == m:
        return None
    return (f"the control net '{net.name}' has {n} vertices for {m} control points (a vertex "
            "was added or deleted): its edits are ignored; Ctrl+Z restores the net, Refine or "
            "Fit Surface makes a new one")


# the SPLINE_KEY text of surfaces that :func:`_as_stored` made (encoded on the job's thread)
_STORED_TEXT: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _encoded(surf) -> str:
    return base64.b64encode(surf.to_bytes(compact=True)).decode("ascii")


def store_spline(surface_obj, surf) -> None:
    text = _STORED_TEXT.get(surf)
    surface_obj[SPLINE_KEY] = text if text is not None else _encoded(surf)


# the resolution (and its sag, core's TCBSurface.tessellation_sag) that :func:`_as_stored`
# chose for a surface with Auto Resolution
_CHOSEN_RESOLUTION: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _as_stored(fn, resolution: int, auto: bool = False, holes: bool = True):
    """``fn``, returning the spline as :func:`store_spline` keeps it (compact: the data's
    parameters and errors rounded to float32) instead of the engine's, so that the mesh written
    now is the one a later Re-tessellate or Refine makes from the stored spline; its text,
    its tessellation at ``resolution`` and a cloud's gaps (``open_holes``) are made here too,
    on the job's thread (for 1e6 points the archive took 1.2 s of Blender's main thread).
    ``auto``: the resolution is chosen (``TCBSurface.auto_resolution``, 0.1-2 s), see
    :func:`chosen_resolution`; ``holes``: the gaps too (not for Import Spline, which does not
    say them: a 1e6-point cloud's spline took 4.2 s to import with them, 2.3 s without)."""
    def run(**kw):
        result = fn(**kw)
        if (result.report or {}).get("stop_reason") == "cancelled":
            return result  # (Esc: thrown away; the tessellation could take seconds: review)
        data = result.to_bytes(compact=True)
        surf = _core().TCBSurface.from_bytes(data)
        _STORED_TEXT[surf] = base64.b64encode(data).decode("ascii")
        if auto:
            _CHOSEN_RESOLUTION[surf] = surf.auto_resolution()
        surf.tessellation_uv(chosen_resolution(surf, resolution))
        if holes:
            surf.open_holes(chosen_resolution(surf, resolution))  # (kept: the summary's note)
        return surf
    return run


def auto_resolution_of(op) -> bool:
    """Auto Resolution of Fit Surface or Import Spline ``op``, unless a script gave a
    Resolution and not it (the panel gives both)."""
    props = op.properties
    if props.is_property_set("resolution") and not props.is_property_set("auto_resolution"):
        return False
    return bool(op.auto_resolution)


def chosen_resolution(surf, resolution: int) -> int:
    """The resolution :func:`_as_stored` chose for ``surf`` (Auto Resolution), else
    ``resolution``."""
    return _CHOSEN_RESOLUTION.get(surf, (resolution,))[0]


def resolution_note(surf) -> str | None:
    """A warning when Auto Resolution's finest mesh still strays from the spline by more than
    the fit's max error (the mesh is what the user sees and measures), else None."""
    chosen = _CHOSEN_RESOLUTION.get(surf)
    if chosen is None:
        return None
    resolution, sag = chosen
    target = _core().surface.sag_target(surf.report, surf.options)
    if not sag > target:
        return None
    # (the sag at half: kept by Auto Resolution, or measured whole now if it passed over it
    # on a sample)
    finer = _core().surface.finer_resolution(
        resolution, sag, target, surf.tessellation_sag(resolution // 2) if resolution >= 4
        else None)
    return (f"the surface mesh (Resolution {resolution}, the finest Auto Resolution takes) "
            f"strays up to {bridge.length_text(sag)} from the spline, more than "
            f"{_core().surface.sag_target_words(surf.report, surf.options, bridge.length_text)}"
            f": Re-tessellate finer (e.g. {finer}) to see the fit as it is")


def folded_over(tcb) -> bool:
    """Whether the surface folds over its mesh on more than the share the engine warns of
    (the panel then shows the share: the warning is gone once the report is)."""
    return tcb.folded > _core().surface.FOLDED_SHARE


def source_data(context, surface_obj) -> bridge.InputData:
    if not len(surface_obj.tcb.sources):  # (only Import Spline makes a result without one)
        raise bridge.SelectionError(
            f"'{surface_obj.name}' was imported without its source object: refining and the "
            "deviation map need the input data (select the scan it was fitted to, in the "
            "file's coordinates, and import the spline again)")
    sources = [s.object for s in surface_obj.tcb.sources]
    # deleted (X): in no collection, kept alive by the pointer (user test: the deleted scan
    # was measured, and called hidden)
    if not sources or any(s is None for s in sources):
        raise bridge.SelectionError(
            f"The source object of '{surface_obj.name}' was deleted: refining and the deviation "
            "map need the input data"
        )
    gone = [s for s in sources if live.deleted(s)]
    if gone:
        # one in no collection may also come with its result appended from another file
        # (bpy.data.libraries.load of the result's collection; user test: "was deleted"),
        # the same state as one deleted: both are said, and how to link it
        name = gone[0].name
        raise bridge.SelectionError(
            f"The source object of '{surface_obj.name}' was deleted, or '{name}' is in no "
            "collection of this file (appended without one): refining and the deviation map "
            "need the input data; if it was appended, link it to the scene (Python console: "
            f"C.scene.collection.objects.link(D.objects[{name!r}])) or append it with its "
            "collection, and try again"
        )
    part = surface_obj.get(PART_KEY)
    if part and len(sources) == 1 and sources[0].type == "MESH":
        obj = sources[0]
        if obj.mode == "EDIT":
            raise bridge.SelectionError(bridge.in_edit_mode(obj))
        return bridge.read_part(obj, *bridge.part_of_text(str(part)))[0]
    return bridge.read_selection(context, sources)


def source_words(surface_obj) -> str | None:
    """What the Result panel says of a surface's data when it is not simply its source
    objects: the part fitted (faces selected in Edit Mode) or the file imported (a patch's
    result and an import looked like any fit: user test)."""
    part = surface_obj.get(PART_KEY)
    names = [s.object.name for s in surface_obj.tcb.sources if s.object is not None]
    if part and names:
        kind, mask, _ = bridge.part_of_text(str(part))
        what = "faces" if kind == "FACES" else "vertices"
        return f"Fitted to {int(mask.sum())} selected {what} of '{names[0]}'"
    imported = surface_obj.get(IMPORTED_KEY)
    if imported:
        return (f"Imported from {os.path.basename(str(imported))}"
                + ("" if names else " (no source object)"))
    return None


def source_mismatch(surf, data: bridge.InputData):
    """``(faces, what)``: the faces of ``data`` as the fit of ``surf`` read them, and how
    ``data`` differ from the data ``surf`` was fitted to, in words ("12 points then, 10 now",
    "other coordinates: moved, transformed or edited", "other faces"), or None when they are
    the same (rounding, another order of the same points and faces, vertices in no face added
    or deleted, and a mirrored source's turned faces are no change). Refine refuses other
    data; Import Spline links only the same as the source."""
    key = (surf.report or {}).get("faces_digest")  # (a mesh's; None for clouds, older files)
    digest = _core().surface.faces_digest
    faces = data.faces
    if key is not None and faces is not None and digest(faces) != key and (
            digest(faces[:, ::-1]) == key):
        # a mirrored source fitted before its faces were read turned (bridge._world_faces):
        # its faces as they were read then (review: "changed since ... (other faces)")
        faces = np.ascontiguousarray(faces[:, ::-1])
    # the same values in any order (a sort and a digest): the same data stored in another
    # order (Sort Elements: "changed since ... (other faces)" or "(other coordinates ...)",
    # nothing having moved; user test) are the same, with the same faces renumbered; the
    # engine parameterizes them again (TCBSurface.reordered) on the job's thread
    same_set = surf.same_data_set(data.points)
    same_points = same_set or surf.fitted_to(data.points, data.rounding)
    faces_changed = key is not None and (faces is None or not surf.same_faces(
        faces, data.points if same_set else None))
    if same_points and not faces_changed:
        return faces, None
    if faces is not None and surf.same_mesh(data.points, faces):
        # the same faces on the same vertices, other vertices in no face: a stray vertex
        # deleted renumbers the rest (Refine had refused it: user test); the engine
        # parameterizes the mesh again (TCBSurface.reordered)
        return faces, None
    then, now = len(surf.parameterization.uv), len(data.points)
    return faces, (f"{then} points then, {now} now" if then != now
                   else "other coordinates: moved, transformed or edited" if not same_points
                   else "other faces")


def changed_names(surf, data: bridge.InputData) -> str:
    """The sources of ``data`` that changed since ``surf`` was fitted, as "'A', 'B'": of
    several fitted together, those whose points moved (user test: Refine named 'Right' and
    'Left' when only 'Left' was moved); all when that cannot be told (another count)."""
    moved = surf.moved_points(data.points, data.rounding) if len(data.counts) > 1 else None
    names, start = [], 0
    if moved is not None and moved.any():
        for name, n in data.counts.items():
            if moved[start:start + n].any():
                names.append(name)
            start += n
    return ", ".join(repr(n) for n in names or [o.name for o in data.sources])


def _animated(obj) -> bool:
    """Whether ``obj`` or an object it is parented to (or their data, or their shape keys)
    has an action, NLA strips or drivers: its data may be elsewhere at another frame (an
    action pushed down to the NLA, and shape keys, had not counted: review)."""
    while obj is not None:
        keys = getattr(getattr(obj, "data", None), "shape_keys", None)
        for idb in (obj, obj.data, keys):
            ad = getattr(idb, "animation_data", None)
            if ad is not None and (ad.action is not None or len(ad.drivers)
                                   or any(len(t.strips) for t in ad.nla_tracks)):
                return True
        obj = obj.parent
    return False


def animated_problem(context, surface_obj, data: bridge.InputData) -> str | None:
    """Why the sources of ``surface_obj`` read other data than its fit's, when it is the
    frame: an animated source and a frame other than the fit's (user test: Refine at frame
    10 of a fit at frame 1 said "changed ... (other coordinates: moved, ...)"), else None.
    None also for a result that keeps no fit frame (fitted before it was kept)."""
    then = surface_obj.get(FITTED_FRAME_KEY)
    now = context.scene.frame_current
    if then is None or int(then) == now:
        return None
    names = [o.name for o in data.sources if _animated(o)]
    if not names:
        return None
    return (f"{', '.join(repr(n) for n in names)} {'is' if len(names) == 1 else 'are'} "
            f"animated and the frame is now {now}, not {int(then)} as when "
            f"'{surface_obj.name}' was fitted: go back to frame {int(then)}, or select the "
            "source and use Fit Surface to fit it again at this frame")


def store_stats(tcb, surf, settings: dict) -> None:
    rep = dict(getattr(surf, "report", {}) or {})
    tcb.knots = int(rep.get("knots", 0))
    tcb.control_points = int(rep.get("control_points", len(surf.control_points)))
    tcb.iterations = int(rep.get("iterations", 0))
    tcb.holes_filled = int(rep.get("holes_filled", 0))
    tcb.folded = float(rep.get("folded", 0.0))
    joined = rep.get("join") or {}
    # (a cloud's join has no edges: its pins; what the panel's Joined Gap row is shown for)
    tcb.joined_edges = (int(joined.get("shared_edges", 0) or joined.get("pins", 0))
                        if not joined.get("kept_unjoined") else 0)
    tcb.join_gap_rel = float(joined.get("gap_max_rel", 0.0))
    tcb.stop_reason = str(rep.get("stop_reason", ""))
    for key in ("rms", "max", "rms_rel", "max_rel", "rms_area", "noise", "noise_rel", "seconds"):
        setattr(tcb, key, float(rep.get(key, 0.0)))
    for key, value in settings.items():
        if hasattr(tcb, key):
            setattr(tcb, key, str(value) if key in {"degree", "mode", "criterion"} else value)
    if "smoothness" in rep:  # the value used: the chosen one with Auto Smoothness
        tcb.smoothness = float(rep["smoothness"])
    # the default smoothness of a sparse cloud or a stalled run is cross-validated
    tcb.smoothness_cross_validated = "why" in (rep.get("smoothness_selection") or {})
    # the default replaced by a smoother one: with it the surface swung (review: the panel
    # said "Smoothness 1" with no word why)
    tcb.smoothness_smoother = _core().surface.default_swung(rep.get("smoothness_selection"))


def remember_placement(surface_obj) -> None:
    """Store the surface object's world matrix: its mesh was just written from the spline."""
    surface_obj[PLACED_KEY] = [float(x) for row in surface_obj.matrix_world for x in row]


WRITTEN_BACK = "it was written back where the spline is"


def _moved_from_placement(surface_obj) -> bool:
    """The surface object's world matrix differs from the one its mesh was written with."""
    placed = surface_obj.get(PLACED_KEY)
    if placed is None:
        return False
    now = np.array(surface_obj.matrix_world, dtype=np.float64).ravel()
    then = np.asarray(list(placed), dtype=np.float64)
    return then.shape == now.shape and not np.allclose(
        now, then, rtol=1e-9, atol=1e-9 * (1 + np.abs(then).max()))


def live_moved_problem(surface_obj) -> str | None:
    """Why moving a live surface's object shows no change, or None: the surface follows its
    net wherever its object is (Blender user test: moved, rotated or parented, it stayed, and
    nothing said why)."""
    live_net = surface_obj.modifiers.get(live.MODIFIER_NAME) is not None
    if not live_net or not _moved_from_placement(surface_obj):
        return None
    return ("the surface object was moved, but a live surface stays with its control net: "
            "move the net to move the surface")


def moved_note(surface_obj, what: str = WRITTEN_BACK) -> str | None:
    """Why a rewrite of the mesh puts the surface back, or None: without a live net the
    surface object can be moved (G) away from its spline; the spline stays with the data and
    the net, so Re-tessellate and Refine write it where it was (with a live net the surface
    follows the net wherever its object is)."""
    live_net = surface_obj.modifiers.get(live.MODIFIER_NAME) is not None
    if live_net or not _moved_from_placement(surface_obj):
        return None
    how = "move the net, or " if surface_obj.tcb.net is not None else ""
    return (f"'{surface_obj.name}' had been moved as an object, away from its spline: {what} "
            f"(the spline stays with the data and the control net; to move the surface, {how}"
            "apply the move to the source and fit again)")


def write_surface_mesh(surface_obj, surf, resolution: int, name: str | None = None,
                       tessellation=None) -> tuple[str | None, bool]:
    """The surface mesh of ``surf`` at ``resolution`` into ``surface_obj`` (``tessellation``:
    its ``(verts, faces)`` computed already, as Re-tessellate's job does). Returns what the
    report says of the old mesh's shape keys and vertex groups (:func:`rewrite_note`) and
    whether shape keys were dropped (a warning)."""
    verts, faces = tessellation if tessellation is not None else surf.tessellate(resolution)
    local = bridge.to_local(surface_obj, verts)
    name = name or surface_obj.data.name
    mesh = bridge.new_mesh(name, local, faces)
    set_texture(mesh, surf, resolution)
    mesh.shade_smooth()
    weighted = bool(len(surface_obj.vertex_groups)) and bridge.has_vertex_weights(
        surface_obj.data)
    keys = bridge.replace_mesh(surface_obj, mesh, name)
    # the Deviation Map's material shows colours the new mesh does not have (it rendered
    # near-black after Refine, Re-tessellate or Fit again: user test)
    bridge.drop_deviation_material(mesh)
    surface_obj.tcb.has_deviation = False
    remember_placement(surface_obj)
    return rewrite_note(surface_obj, keys, weighted), bool(keys)


def rewrite_note(obj, keys: list, weighted: bool = True) -> str | None:
    """What a new mesh of ``obj`` left of the old one's shape keys (``keys``, their names:
    dropped, as they hold positions of the old vertices) and vertex groups (their names kept,
    so modifiers naming them still find them, with no weights on the new vertices; said when
    the old mesh had weights, ``weighted``); None when it had neither (both had gone without
    a word: user test)."""
    groups = [g.name for g in obj.vertex_groups] if weighted else []
    parts = []
    if keys:
        many = len(keys) > 1
        parts.append(f"its shape key{'s' * many} ({_quoted(keys)}) {'were' if many else 'was'} "
                     f"removed with the old mesh (Ctrl+Z brings {'them' if many else 'it'} back)")
    if groups:
        many = len(groups) > 1
        parts.append(f"its vertex group{'s' * many} ({_quoted(groups)}) "
                     f"{'are' if many else 'is'} kept by name, with no weights on the new "
                     "vertices")
    if not parts:
        return None
    return f"'{obj.name}' has a new mesh of other vertices: {'; '.join(parts)}"


def _quoted(names) -> str:
    return ", ".join(f"'{n}'" for n in names)


def set_texture(mesh, surf, resolution: int) -> None:
    """A UV map on the surface ``mesh`` (the tessellation of ``surf`` at ``resolution``) from
    the spline's parameters (TCBSurface.texture_coordinates): ready for textures. The
    parameters are the tessellation's, cached on ``surf``."""
    bridge.set_uv_map(mesh, surf.texture_coordinates(surf.tessellation_uv(resolution)[0]))


def write_net_mesh(net_obj, surf, name: str | None = None) -> str | None:
    """The control net of ``surf`` into ``net_obj`` (in its own frame); the report's words on
    the old net's shape keys, which go with its mesh (:func:`net_shape_key_problem`), or
    None."""
    pts, faces = surf.control_net()
    name = name or net_obj.data.name
    mesh = bridge.new_mesh(name, bridge.to_local(net_obj, pts), faces)
    keys = bridge.replace_mesh(net_obj, mesh, name)  # (besides the basis, as net_shape_keys)
    _remember_net_rounding(net_obj)
    if not keys:
        return None
    many = len(keys) > 1
    return (f"the shape key{'s' * many} {_quoted(keys)} of the control net '{net_obj.name}' "
            f"{'were' if many else 'was'} removed with its old mesh: the new net is the fit's, "
            f"and {'they were' if many else 'it was'} not part of the spline (Ctrl+Z brings "
            f"{'them' if many else 'it'} back)")


# the largest float32 spacing of a net's coordinates when they were written, in world units: a
# net vertex differs from its control point by at most that plus its spacing now
NET_ROUNDING_KEY = "tcb_net_rounding"


def _remember_net_rounding(net_obj) -> None:
    """Keep the spacing its coordinates were rounded to as written (:data:`NET_ROUNDING_KEY`):
    Set Origin on the net (its frame changed, no vertex moved) re-rounds them to a finer
    spacing, against which the first rounding looked like edits (user test: "41 edited
    control points were replaced" by Refine, for moves of 6e-8); and its world matrix
    (:data:`NET_PLACED_KEY`, :func:`net_moved_note`)."""
    net_obj[NET_ROUNDING_KEY] = float(
        bridge.read_world_positions_and_rounding(net_obj)[1].max(initial=0.0))
    net_obj[NET_PLACED_KEY] = [float(x) for row in net_obj.matrix_world for x in row]


# the control net object's world matrix when its vertices were last written (16 floats)
NET_PLACED_KEY = "tcb_net_placed_at"


def net_moved_note(surface_obj, stored) -> str | None:
    """Words for a control net moved as an object (G on the net, as "move the net to move the
    surface" invites) since its vertices were written from ``stored`` (the stored spline), or
    None: its vertices then all count as edits, and the Deviation Map measured the moved
    surface (RMS 2.9 for a fit of 1e-3) and Refine replaced "41 edited control points"
    without saying why (user test). Moved: its object's matrix changed and most of its
    vertices are off their control points (Set Origin changes the matrix and not where the
    vertices are; a drag in Edit Mode moves some vertices, not the matrix); by how much: the
    median of their offsets."""
    net = surface_obj.tcb.net
    placed = net.get(NET_PLACED_KEY) if net is not None and net.type == "MESH" else None
    if placed is None:
        return None
    now = np.array(net.matrix_world, dtype=np.float64)
    then = np.asarray(list(placed), dtype=np.float64).reshape(4, 4)
    if np.allclose(now, then, rtol=1e-9, atol=1e-9 * (1 + np.abs(then).max())):
        return None
    ctrl, rounding = bridge.read_world_positions_and_rounding(net)
    ref = np.asarray(stored.control_points, dtype=np.float64)
    if len(ctrl) != len(ref) or not len(ref):
        return None
    # (off by more than the rounding: an edit, as with_net_edits counts them)
    rounding = rounding + float(net.get(NET_ROUNDING_KEY, 0.0))
    off = (np.abs(ctrl - ref) > rounding + 8 * np.spacing(np.abs(ref))).any(axis=1)
    if not off.mean() > 0.5:
        return None
    shift = np.median(ctrl - ref, axis=0)
    # (the 32-bit rounding of the vertices had been said as "(1.49e-08, 0, 3)")
    shift = np.where(np.abs(shift) > 1e-6 * np.linalg.norm(shift), shift, 0.0)
    turned = not np.allclose(now[:3, :3], then[:3, :3], rtol=1e-9, atol=1e-9)
    return (f"the control net '{net.name}' was moved as an object since it was written (by "
            f"({', '.join(f'{c:.4g}' for c in shift)}), {np.linalg.norm(shift):.4g} units"
            + (", and turned or scaled" if turned else "") + ")")


def _summary(surf, seconds: float | None = None) -> str:
    """The one-line summary; ``seconds``: the operator's own time (reading the selection,
    the fit, the objects made), else the engine's (user test: a 1e6-vertex mesh took 103 s
    and the summary said 18.66)."""
    rep = dict(getattr(surf, "report", {}) or {})
    n = rep.get("control_points", len(surf.control_points))
    sel = rep.get("smoothness_selection") or {}
    why = _core().refine.replaced_default_reason(sel)
    how = (f" ({why}: cross-validated)" if why
           else f" (with the default {sel['chosen']:.3g} the surface swung away from the data)"
           if _core().surface.default_swung(sel) else " (auto)" if sel else "")
    return (
        f"TCB: {n} control points, RMS {bridge.length_text(rep.get('rms', np.nan))}, "
        f"max {bridge.length_text(rep.get('max', np.nan))} "
        f"({100 * rep.get('max_rel', float('nan')):.3g}% of the diagonal)"
        # a cloud of uneven density: its error over the area, when it tells more than the RMS
        + (f", RMS over area {bridge.length_text(rep['rms_area'])}"
           if uneven_density(rep.get("rms", np.inf), rep.get("rms_area", 0.0)) else "")
        + f", smoothness {rep.get('smoothness', float('nan')):.3g}{how}, "
        f"{rep.get('seconds', 0.0) if seconds is None else seconds:.2f} s"
        + (f", {rep['outliers']} outlier{'s' if rep['outliers'] != 1 else ''} left out"
           if rep.get("outliers") else "")
        + (f", the surface of iteration {rep['returned_iteration']} of {rep['iterations']} "
           f"({_core().refine.returned_why(rep, getattr(surf.options, 'criterion', 'rms'))})"
           if 0 < rep.get("returned_iteration", 0) < rep.get("iterations", 0) else "")
    )


def _scatter(surf) -> str:
    """Words for the data's noise in the report of ``surf`` (core.parameterize.local_noise)."""
    rep = surf.report
    mesh = getattr(surf.parameterization, "faces", None) is not None
    return (f"the {'vertices' if mesh else 'points'} scatter {bridge.length_text(rep['noise'])} "
            f"({100 * rep['noise_rel']:.3g}% of the diagonal) across a smooth surface")


def report_result(op, surf, notes=(), warnings=(), seconds: float | None = None,
                  auto: bool = False) -> None:
    """The summary of a fit or refine: INFO, or WARNING when the tolerance was not reached
    (the budget or the iteration limit stopped the loop first), with what to change, or when
    there are ``warnings``. ``auto``: the mesh's resolution is Auto Resolution's choice
    (said when finer than its first, or warned of when even its finest strays)."""
    rep = dict(getattr(surf, "report", {}) or {})
    reason = str(rep.get("stop_reason", ""))
    if (rep.get("swings") or {}).get("places"):  # core.surface.data_swings
        warnings = list(warnings) + [_core().surface.swing_warning(rep)]
    # a net much larger than its mesh (core.surface.coarse_mesh_warning), in Blender's words
    # (the engine's had said "faces=None": user test)
    large_net = "coarse_mesh_crease" in rep
    if large_net:
        warnings = list(warnings) + [_core().surface.coarse_mesh_warning(
            rep, budget="Max Control Points",
            subdivide="subdivide the mesh first (a Subdivision Surface modifier)",
            cloud="fit its vertices as a point cloud (a copy of the mesh with its faces "
                  "deleted: Delete > Only Faces)")]
    loose = rep.get("loose_vertices", 0)
    if loose and not any("in no face" in str(w) for w in warnings):
        # (the engine's warning says it, with what to do: the summary had said it again, "1
        # loose vertices (in no face) left out"; user test)
        warnings = list(warnings) + [f"{loose} loose vert{'ex' if loose == 1 else 'ices'} (in "
                                     "no face) left out"]
    chosen = _CHOSEN_RESOLUTION.get(surf) if auto else None
    stray = resolution_note(surf) if chosen is not None else None
    if stray:
        warnings = list(warnings) + [stray]
    elif chosen is not None and chosen[0] > _core().surface.AUTO_RESOLUTIONS[0]:
        notes = list(notes) + [f"mesh Resolution {chosen[0]} (Auto Resolution: within the "
                               "fit's max error of the spline)"]
    text = _summary(surf, seconds) + "".join(f"; {n}" for n in list(notes) + list(warnings))
    if reason.startswith("tolerance reached") and "misses" not in reason:
        op.report({"WARNING"} if warnings else {"INFO"}, text)
    elif "misses" in reason:  # sparse data: the smoother cross-validated surface was kept
        op.report({"WARNING"}, f"{text}; few points for the control points: the smoother "
                  "cross-validated surface was kept, which misses the tolerance (a Smoothness "
                  "value set by hand follows the points more closely)")
    elif reason == "cancelled":
        op.report({"WARNING"}, f"{text}; stopped early (cancelled): the best surface so far")
    elif reason == _core().refine.STALLED and _core().surface.far_stall(rep):
        # not noise: the engine's warning (among the notes) says why and what to do
        op.report({"WARNING"}, f"{text}; the tolerance was not reached: {reason} far above "
                  "the data's noise")
    elif reason == _core().refine.STALLED:
        opts = surf.options  # the settings of this fit
        what = "max" if str(opts.criterion).lower() == "max" else "RMS"
        level = (f"{100 * rep.get(what.lower() + '_rel', 0):.3g}% of the diagonal"
                 if opts.relative else bridge.length_text(rep.get(what.lower(), 0)))
        chosen = bool(rep.get("smoothness_selection"))  # by the engine, or Auto Smoothness
        # the data's noise (core.parameterize.local_noise), when the error stopped at it;
        # else the cause is open
        if rep.get("net_capped"):  # (core.refine.NOISY_NET_PER_VERTEX)
            why = (f"when the net reached one control point per vertex of the noisy mesh "
                   f"({rep['net_capped']}): more would fit its noise")
        elif _core().surface.stopped_at_noise(rep):
            why = (f"at the data's noise: {_scatter(surf)}, and more control points would fit "
                   "the noise")
        else:
            why = ("with more control points (noise in the data, or detail the knots cannot "
                   "resolve: more control points would fit the noise)")
        op.report({"WARNING"}, f"{text}; the tolerance was not reached: {reason} {why}: set "
                  f"the tolerance above the {what} reached ({level})"
                  + (" (the smoothness was cross-validated)" if chosen
                     else ", or turn on Auto Smoothness"))
    else:
        # (not with the large net's warning, which says the net is already far too big for
        # the mesh: the two had been given together; user test)
        advice = {"control-point budget reached": "" if large_net else "raise Max Control Points",
                  "iteration limit": "raise Max Iterations",
                  "no triangle has enough data to refine": "add points where the error is "
                  "largest (too few there for more knots)",
                  _core().refine.SWINGS_LEFT: "the rest of the error is where more knots made "
                  "the surface swing between the points (a sharp step?): add points there"
                  }.get(_core().refine.SWINGS_LEFT if _core().refine.mostly_taken_back(rep)
                        else reason, "")
        if advice and rep.get("spikes"):  # (as the command line: user test)
            advice = f"{_core().surface.SPIKES_HELD_OFF}: turn on Drop Outliers"
        opts = surf.options
        if advice and not _core().refine.mostly_taken_back(rep) and (
                _core().surface.noise_near_tolerance(rep, opts.tolerance, opts.relative,
                                                     opts.criterion)):
            # the data's noise (core.parameterize.local_noise) is near the tolerance: more
            # control points would mostly fit it
            what = "max" if str(opts.criterion).lower() == "max" else "RMS"
            level = (f"{100 * rep[what.lower() + '_rel']:.3g}% of the diagonal" if opts.relative
                     else bridge.length_text(rep[what.lower()]))
            rate = _core().surface.fall_rate(rep)
            spiky = advice.startswith(_core().surface.SPIKES_HELD_OFF)  # (its own advice)
            if rate is not None and rate >= _core().surface.STILL_FALLING and not spiky:
                # (the error still falling: the scatter may be detail of the shape; user test)
                advice = (f"{_scatter(surf)}, but the error was still falling (like "
                          f"knots^-{rate:.2f} at the end), so that may be fine detail of the "
                          f"shape: {advice}; if it is noise, more control points would mostly "
                          f"fit it: loosen the tolerance to about the {what} reached ({level})")
            else:
                advice = (f"{_scatter(surf)}, and more control points would mostly fit that "
                          f"noise: loosen the tolerance to about the {what} reached ({level}), "
                          f"or {advice}")
            op.report({"WARNING"}, f"{text}; the tolerance was not reached ({reason}): {advice}")
        else:
            op.report({"WARNING"}, f"{text}; the tolerance was not reached ({reason})"
                      + (f": {advice} or loosen the tolerance" if advice
                         else ": loosen the tolerance, or subdivide the mesh first (see the "
                         "net's size above)"
                         if large_net and reason == "control-point budget reached" else ""))


# --- the worker-thread job and the modal/execute skeleton --------------------------------------


def _recording(fn, sink: list):
    """``fn``, with the engine's RuntimeWarnings appended to ``sink`` for the operator's report
    instead of printed to the console with a file and line (user test); other warnings are
    shown as usual."""
    def run(**kw):
        caught: list = []
        try:
            with _warnings.catch_warnings(record=True) as caught:
                _warnings.simplefilter("always")
                return fn(**kw)
        finally:  # (after the filters are back: the others are shown as they would have been)
            for w in caught:
                if not issubclass(w.category, RuntimeWarning):
                    _warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
                elif str(w.message) not in sink:
                    sink.append(str(w.message))
    return run


def _engine_notes(op) -> list:
    """The engine's warnings recorded for ``op`` (:func:`_recording`), less the swing warning
    and the large net's (report_result words them from the report) and refine()'s word on
    edited control points (Refine says it in Blender's terms); the smoothness advice in
    Blender's terms (it had told a user whose Smoothness was pinned at the default to leave it
    at its default; user test)."""
    advice = _core().surface.SMOOTHNESS_ADVICE
    pinned = (getattr(op, "smoothness_set", False)
              and getattr(op, "smoothness", None) == DEFAULT_SMOOTHNESS)
    words = ("unpin the Smoothness (the pin beside it)" if pinned else
             "set the Smoothness back to 0.0001, not pinned,") + (
        " or turn on Auto Smoothness to have it chosen by cross-validation")
    return [m.replace(advice, words) for m in getattr(op, "_engine", ())
            if not m.startswith("the surface swings away")
            and not m.startswith("the net has ") and "edited control point" not in m]


class _Job:
    """Runs ``fn(**kwargs, callback=...)`` in a thread; the main thread polls it."""

    def __init__(self, fn, kwargs):
        self.fn, self.kwargs = fn, kwargs
        self.progress: dict | None = None
        self.cancel = False
        self.result = None
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="tcb-fit", daemon=True)

    def _callback(self, report):
        self.progress = dict(report)
        return self.cancel

    def _run(self):
        try:
            self.result = self.fn(**self.kwargs, callback=self._callback)
        except BaseException as ex:  # noqa: BLE001 (handed to the main thread)
            self.error = ex

    def start(self):
        self.thread.start()
        return self

    @property
    def done(self):
        return not self.thread.is_alive()


def _print_progress(report, what: str = "Fitting"):
    if "grid_step" in report or ("points_done" in report
                                 and report["points"] <= _core().surface.CLOSEST_CHUNK):
        return  # (one chunk, or a tessellation's grid: nothing to follow)
    print(progress_text(report, what).replace(" (Esc to cancel)", ""), flush=True)


class _EngineOperator:
    """Shared execute/invoke/modal. Subclasses define ``prepare`` and ``finish``.

    ``prepare(context)`` returns ``("done", surface)`` (nothing to compute, e.g. a cache hit) or
    ``("run", fn, kwargs)``; ``finish(context, surface)`` writes the result and returns the
    operator's return set. Both may raise the user errors of :func:`_user_errors`.
    """

    _what = "Fitting"

    def execute(self, context):
        errors = _user_errors()
        try:
            task = self.prepare(context)
            if task[0] == "done":
                surf = task[1]
            else:
                _, fn, kwargs = task
                cb = (lambda r: _print_progress(r, self._what)) if bpy.app.background else None
                surf = fn(**kwargs, callback=cb)
            return self.finish(context, surf)
        except errors as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}

    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            task = self.prepare(context)
        except _user_errors() as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        if task[0] == "done":
            return self._finish_safely(context, task[1])
        self._job = _Job(task[1], task[2]).start()
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.progress_begin(0, 100)
        self._t0 = time.perf_counter()
        self._status(context, progress_text(None, self._what))
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        job = self._job
        if event.type == "ESC" and event.value == "PRESS" and not job.cancel:
            job.cancel = True
            self._status(context, "TCB: cancelling...")
            return {"RUNNING_MODAL"}
        if event.type != "TIMER":
            # let the user look around while the engine works; everything else waits
            if event.type in {"MIDDLEMOUSE", "WHEELUPMOUSE", "WHEELDOWNMOUSE", "TRACKPADPAN",
                              "TRACKPADZOOM", "MOUSEMOVE", "INBETWEEN_MOUSEMOVE"}:  # fmt: skip
                return {"PASS_THROUGH"}
            return {"RUNNING_MODAL"}
        if not job.done:
            if not job.cancel:
                self._status(context, progress_text(job.progress, self._what))
            context.window_manager.progress_update(progress_percent(
                job.progress, getattr(self, "_iteration_offset", 0),
                getattr(self, "max_iterations", 20)))
            return {"RUNNING_MODAL"}
        self._cleanup(context)
        if job.cancel:
            self.report({"WARNING"}, "TCB: cancelled; nothing was changed")
            return {"CANCELLED"}
        if job.error is not None:
            if isinstance(job.error, _user_errors()):
                self.report({"ERROR"}, str(job.error))
                return {"CANCELLED"}
            raise job.error
        return self._finish_safely(context, job.result)

    def _finish_safely(self, context, surf):
        try:
            return self.finish(context, surf)
        except _user_errors() as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}

    def cancel(self, context):  # Blender calls this when the modal is aborted (e.g. file load)
        if getattr(self, "_job", None) is not None:
            self._job.cancel = True
            self._cleanup(context)

    def _status(self, context, text):
        if context.workspace is not None:
            context.workspace.status_text_set(text)

    def _cleanup(self, context):
        wm = context.window_manager
        if getattr(self, "_timer", None) is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        self._status(context, None)


# --- Fit ----------------------------------------------------------------------------------------

# Custom property of a surface object: when it was fitted (time.time()), so that Fit with
# Replace Previous Result replaces the latest of several results of the same source
FITTED_KEY = "tcb_fitted_at"
# ... and the name the fit gave it: a Shift+D copy carries both properties, not the name
FITTED_NAME_KEY = "tcb_fitted_name"
# ... and the scene frame it was fitted at: an animated source is elsewhere at other frames
# (user test: Refine at another frame said "changed ... (other coordinates: moved, ...)")
FITTED_FRAME_KEY = "tcb_fitted_frame"


def _fit_order(ob) -> tuple:
    """The order in which :func:`previous_result` prefers results: the latest fitted; of a
    result and its Shift+D copies (the same fit time), the one still named as the fit named
    it, then the one its net belongs to (a surface copied alone shares the original's net,
    whose surface is the original), then the first made in this session
    (``ID.session_uid``; after a reload, the first by name): the copy the user kept as a
    variant had been rewritten, as the later name (user test)."""
    net = ob.tcb.net
    return (float(ob.get(FITTED_KEY, 0.0)), ob.name == ob.get(FITTED_NAME_KEY),
            net is not None and net.tcb.surface == ob, -ob.session_uid)


def previous_result(context, sources, kept: list | None = None, part: str = ""):
    """The surface object of the view layer fitted to exactly the objects ``sources`` (the
    latest fitted when there are several), or None; and to the same ``part`` of them (faces
    selected in Edit Mode, ``bridge.part_text``: the same faces, ``bridge.part_identity``,
    whatever their numbers; "" for all: a patch's result and the whole mesh's are two). (One in an excluded collection stays as it is: it cannot be made active;
    so does one linked from another file, and one made by Import Spline: ``kept`` gets a
    sentence for each.)"""
    want = sorted(o.as_pointer() for o in sources)
    found = [ob for ob in context.view_layer.objects
             if ob.tcb.role == "SURFACE" and ob.type == "MESH"
             and sorted(s.object.as_pointer() for s in ob.tcb.sources if s.object is not None)
             == want and len(ob.tcb.sources) == len(want)
             and bridge.part_identity(ob.get(PART_KEY, "")) == bridge.part_identity(part)]
    if kept is not None:
        kept += [f"'{ob.name}' is linked from another file and was kept: this result is a "
                 "new one" for ob in found if linked_problem(ob, ob.tcb.net)]
        kept += [f"'{ob.name}' was imported (Import Spline) and was kept: this result is a "
                 "new one" for ob in found if ob.get(IMPORTED_KEY)
                 and not linked_problem(ob, ob.tcb.net)]
    found = [ob for ob in found if not linked_problem(ob, ob.tcb.net)
             and not ob.get(IMPORTED_KEY)]
    if not found:
        return None
    return max(found, key=_fit_order)


def neighbour_joins(context, obj, part: str, data) -> tuple[list, list, list]:
    """The neighbours to join a fit of faces ``part`` (``bridge.part_text``) of mesh ``obj``,
    read as ``data``, to (Join Neighbours; ``core.join``): ``(join, names, notes)``, ``join``
    as ``fit_surface`` takes it (each neighbouring result's spline, with its net's edits, and
    the vertex pairs the two parts share: identical world coordinates), the neighbours'
    names, and a sentence for each result of another part of ``obj`` sharing a border with
    this one that is not joined (the selections share faces, or the mesh moved or was edited
    since its fit). Neighbours: the other results of faces of ``obj`` in the view layer with a
    border edge in common with these (and no face: a selection made in vertex select mode
    takes the faces whose vertices are all selected, a neighbour's too: user test)."""
    core = _core()
    kind, mask, _ = bridge.part_of_text(part)
    if kind != "FACES" or data.faces is None:
        return [], [], []
    join, names, notes = [], [], []
    mine = bridge.part_identity(part)
    for ob in context.view_layer.objects:
        text = str(ob.get(PART_KEY, "")) if ob.type == "MESH" else ""
        if (ob.tcb.role != "SURFACE" or not text or bridge.part_identity(text) == mine
                or [s.object for s in ob.tcb.sources] != [obj] or live.deleted(ob)):
            continue
        other_kind, other_mask, digest = bridge.part_of_text(text)
        if other_kind != "FACES" or len(other_mask) != len(mask):
            continue  # (vertices, or another mesh's numbers)
        common = int((other_mask & mask).sum())
        if common == int(mask.sum()) or common == int(other_mask.sum()):
            continue  # (a part within the other: not a neighbour)
        try:
            other = bridge.read_part(obj, other_kind, other_mask, digest)[0]
        except bridge.SelectionError:
            continue  # (its faces renumbered or edited: not a patch of this mesh any more)
        pairs = core.join.shared_vertices(data.points, other.points)
        if not len(core.join.shared_border_edges(data.faces, other.faces, pairs)[0]):
            continue  # (no border in common: apart, or touching at a corner)
        if common:
            notes.append(
                f"not joined to '{ob.name}': the two selections share {common} face"
                f"{'s' if common > 1 else ''} (in vertex select mode a face whose vertices are "
                "all selected is selected too: deselect those, or select in face select mode, "
                "and fit again)")
            continue
        try:
            surf = stored_surface(ob, use_net=True)
        except bridge.SelectionError:
            surf = None
        if surf is None or surf.parameterization.faces is None or not surf.fitted_to(
                other.points, other.rounding):
            # (its faces are as they were, read_part says: the object was moved; user test)
            notes.append(f"not joined to '{ob.name}': '{obj.name}' was moved or transformed "
                         "since that part was fitted (fit it again, then these faces)")
            continue
        join.append((surf, pairs))
        names.append(ob.name)
    return join, names, notes


def _world_box(ob) -> np.ndarray:
    """The world bounding box ``(2, 3)`` of an object's geometry (its ``bound_box`` corners
    through ``matrix_world``)."""
    m = np.array(ob.matrix_world)
    corners = np.array([list(c) for c in ob.bound_box], dtype=np.float64)
    world = corners @ m[:3, :3].T + m[:3, 3]
    return np.array([world.min(axis=0), world.max(axis=0)])


def cloud_neighbours(context, data, kwargs: dict, param=None) -> tuple[list, list, list]:
    """The neighbours to join a point cloud's fit ``data`` to (Join Neighbours; in Object Mode,
    ``core.join.cloud_seam``), as :func:`neighbour_joins` gives a part's: ``(join, names,
    notes)``. Height fields only: a cloud fitted along a given direction (a DEM raster along
    its z, or a world axis chosen in Projection), and the surfaces in the view layer fitted so
    to other objects' clouds (DEM tiles imported one by one and fitted in turn) whose fitted
    part reaches this cloud's border, parameterized as the fit will be (``param``, Refine:
    the stored one); a surface reaching it that cannot be joined (fitted along another
    direction, or reaching all of the border) is named in a note. Of a tile's results (Shift+D
    copies, a variant kept) the one Replace Previous Result would replace (:func:`_fit_order`);
    none of a tile deleted, and none whose mesh's box is apart from this cloud's (read before
    its spline: 20 tiles in a scene). Scans on their best-fit planes are not joined (two
    overlapping scans of a part fitted one by one are not tiles)."""
    core = _core()
    if kwargs.get("projection") is None or not len(data.points):
        return [], [], []
    mine = {o.as_pointer() for o in data.sources}
    lo, hi = data.points.min(axis=0), data.points.max(axis=0)
    pad = 1e-3 * float(np.linalg.norm(hi - lo)) + 1e-9
    latest = {}
    for ob in context.view_layer.objects:
        if (ob.tcb.role != "SURFACE" or ob.get(PART_KEY) or live.deleted(ob)
                or not ob.tcb.sources
                or any(s.object is None or live.deleted(s.object)
                       or s.object.as_pointer() in mine for s in ob.tcb.sources)):
            continue
        box = _world_box(ob)
        if (box[0] > hi + pad).any() or (box[1] < lo - pad).any():
            continue  # (apart)
        key = tuple(sorted(s.object.as_pointer() for s in ob.tcb.sources))
        if key not in latest or _fit_order(ob) > _fit_order(latest[key]):
            latest[key] = ob
    found = []
    for ob in latest.values():
        try:
            surf = stored_surface(ob, use_net=True)
        except (bridge.SelectionError, core.TCBError):
            continue  # (a damaged spline: that result's own operators say so)
        if (surf is not None and surf.parameterization.kind == "plane"
                and (surf.report or {}).get("projection_given")):
            found.append((ob, surf))
    if not found:
        return [], [], []
    if param is None:
        try:  # (this cloud's parameters, as the fit makes them: where its border is)
            with _warnings.catch_warnings():
                _warnings.simplefilter("ignore")  # (the fit says them)
                param = core.parameterize.parameterize(
                    data.points, projection=kwargs.get("projection"),
                    drop_outliers=bool(kwargs.get("drop_outliers")),
                    fill_holes=bool(kwargs.get("fill_holes")))
        except core.TCBError:
            return [], [], []  # (the fit says why)
    join, names, notes = [], [], []
    for ob, surf in found:
        try:
            core.join.cloud_seam(param, surf, points=data.points)
        except core.InvalidInputError as exc:
            if "reaches no part" not in str(exc):  # (apart: not a neighbour, said nothing)
                notes.append(f"not joined to '{ob.name}': "
                             + str(exc).split(": ", 1)[-1].split(";")[0])
            continue
        join.append((surf, None))
        names.append(ob.name)
    return join, names, notes


def join_words(surf, names: list) -> list:
    """The summary's sentence on a joined fit (``report["join"]``), or none."""
    j = (surf.report or {}).get("join")
    if not j or not names:
        return []
    who = ", ".join(f"'{n}'" for n in names)
    if j.get("kept_unjoined"):  # (the warning says why; it had said "joined": user test)
        return [f"not joined to {who}: fitted on its own, the borders "
                f"{bridge.length_text(j['gap_max'])} apart "
                f"at most ({j['gap_max_rel']:.2g} of the diagonal)"]
    # (the joined net's size, against the patch's own: up to 4x on a coarse one; user test)
    added = (f"; {j['knots_added']} knots added along it: {j['control_points']} control "
             f"points, {j['control_points_unjoined']} fitted alone" if j.get("knots_added")
             else "")
    along = (f"{j['shared_edges']} shared border edges" if j.get("shared_edges")
             else f"{bridge.length_text(j.get('shared_length', 0.0))} of shared border")
    return [f"joined to {who} along {along}: the borders "
            f"{bridge.length_text(j['gap_max'])} apart at most ({j['gap_max_rel']:.2g} of the "
            "diagonal; "
            f"{j['gap_max_unjoined_rel']:.2g} unjoined{added})"]


def stale_nets(context, sources, part: str = "") -> list:
    """The control nets in the view layer whose surface was deleted (X: the net's pointer
    keeps it in the file, in no collection) and was fitted to exactly the objects
    ``sources``: what Replace Previous Result replaces when there is no surface to replace
    (the old net had stayed beside the new result, which went to a second collection: user
    test); of the same ``part`` (:func:`previous_result`). Nets linked from another file are
    left alone."""
    want = sorted(o.as_pointer() for o in sources)
    return [ob for ob in context.view_layer.objects
            if ob.tcb.role == "NET" and ob.library is None and ob.tcb.surface is not None
            and live.deleted(ob.tcb.surface)
            and sorted(s.object.as_pointer() for s in ob.tcb.surface.tcb.sources
                       if s.object is not None) == want
            and len(ob.tcb.surface.tcb.sources) == len(want)
            and bridge.part_identity(ob.tcb.surface.get(PART_KEY, ""))
            == bridge.part_identity(part)]


def _new_net(coll, name: str, surf, origin):
    """A new control-net object of ``surf`` in ``coll``, placed at ``origin`` (the surface's:
    the live net needs no transform)."""
    pts, nfaces = surf.control_net()
    net = bridge.link_new_object(coll, name, bridge.new_mesh(name, pts - origin, nfaces), origin)
    net.display_type = "WIRE"
    net.show_in_front = True
    net.hide_render = True  # a viewport handle: its faces would hide the surface in renders
    _remember_net_rounding(net)
    return net


def _new_result(coll, name: str, surf, resolution: int, tessellation=None):
    """A new surface object (``surf`` tessellated at ``resolution``, with its UV map;
    ``tessellation``: its ``(verts, faces)`` made already) and control net, named after
    ``name``, in ``coll``; both at an origin near the data when it is far from the world origin
    (``bridge.local_origin``)."""
    verts, faces = tessellation if tessellation is not None else surf.tessellate(resolution)
    origin = bridge.local_origin(verts)  # (0, 0, 0) unless far from the world origin
    smesh = bridge.new_mesh(f"{name} TCB Surface", verts - origin, faces)
    set_texture(smesh, surf, resolution)
    smesh.shade_smooth()
    surface = bridge.link_new_object(coll, f"{name} TCB Surface", smesh, origin)
    remember_placement(surface)
    return surface, _new_net(coll, f"{name} TCB Net", surf, origin)


def set_up_result(context, surface, net, surf, sources, settings: dict, live_net: bool,
                  show_net: bool, part: str = "") -> list:
    """Make ``surface`` and ``net`` (written from ``surf``) a TCB result: its spline stored,
    roles, ``sources`` (and ``part``, the faces of the source fitted: ``bridge.part_text``,
    "" for all of it), links, statistics and ``settings`` (:func:`store_stats`), the live net
    attached (or a replaced result's detached), the net shown or hidden and the surface shown,
    selected and active (Fit Surface, Import Spline). Returns a warning for a replaced result
    that stays hidden because its collection is (the user's collection is left as it is)."""
    # a replaced surface hidden by the user is shown, as a new one is (it had stayed
    # hidden, and only its net came back: user test), also one disabled in viewports (the
    # outliner's monitor icon: the report said it was replaced, and nothing showed)
    for obj, hide in ((net, not show_net), (surface, False)):
        try:
            obj.hide_set(hide)
        except RuntimeError:  # a replaced result's object outside the current view layer
            pass
        if not hide:
            obj.hide_viewport = False
    hidden = [(obj, bridge.hiding_collections(context.view_layer, obj))
              for obj in ((surface, net) if show_net else (surface,))]
    warnings = [f"'{obj.name}' stays hidden: its collection{'s' * (len(names) > 1)} "
                f"{', '.join(repr(n) for n in names)} {'are' if len(names) > 1 else 'is'} "
                "hidden or excluded in the outliner (show or include it to see the result)"
                for obj, names in hidden if names]
    store_spline(surface, surf)
    st = surface.tcb
    st.role = "SURFACE"
    st.sources.clear()
    for src in sources:
        st.sources.add().object = src
    if part:
        surface[PART_KEY] = part
    elif PART_KEY in surface:
        del surface[PART_KEY]
    st.net = net
    net.tcb.role = "NET"
    net.tcb.surface = surface
    store_stats(st, surf, settings)
    if live_net:
        live.attach(surface, net, surf, settings["resolution"])
    else:
        live.detach(surface)  # (a replaced result's live link)
    for obj in context.selected_objects:
        obj.select_set(False)
    surface.select_set(True)
    context.view_layer.objects.active = surface
    return warnings


def _on_its_grid(obj) -> bool:
    """Whether a raster object's vertices are still heights over a grid of its x and y
    (``core.parameterize.on_xy_grid``), as Import Points made them. Turned inside the mesh
    (Apply Rotation, a rotation in Edit Mode) or joined with another cloud, they are not, and
    its z may cross the points' surface (fitted along it, a tile turned 90 degrees and applied
    was refused as folded: review)."""
    n = len(obj.data.vertices)
    co = np.empty(3 * n, dtype=np.float32)
    obj.data.vertices.foreach_get("co", co)
    return _core().parameterize.on_xy_grid(co.reshape(-1, 3))


def raster_projection(sources) -> tuple[tuple | None, str | None]:
    """The direction Projection Auto fits a point cloud along when all its ``sources`` are DEM
    rasters Import Points made (:data:`RASTER_KEY`) whose vertices are still on their grid
    (:func:`_on_its_grid`): their z axis in world space (the object's 3x3 matrix applied to
    (0, 0, 1), as bridge.read_selection maps the points: a height field over the object's x
    and y projects along it onto a parallelogram, so a tile keeps its straight edges), with a
    note; (None, None) when none is a raster, and (None, a note) when only some are, when one
    is off its grid, or when their z axes are not parallel (Auto chooses then)."""
    rasters = [o for o in sources or () if bool(o.get(RASTER_KEY, False))]
    if not rasters:
        return None, None
    auto = "Projection Auto chose the direction from the data"
    others = [o for o in sources if o not in rasters]
    if others:
        return None, (f"{', '.join(repr(o.name) for o in others)} "
                      f"{'is no DEM raster' if len(others) == 1 else 'are no DEM rasters'} "
                      f"(Import Points) as {', '.join(repr(o.name) for o in rasters)}: {auto}")
    moved = [o for o in rasters if not _on_its_grid(o)]
    if moved:
        return None, (f"{', '.join(repr(o.name) for o in moved)} "
                      f"{'was' if len(moved) == 1 else 'were'} imported as a DEM raster, but "
                      "its points are no longer on its grid of x and y (rotated in the mesh, "
                      f"joined or edited): {auto}")
    axes = []
    for obj in rasters:
        d = np.array(obj.matrix_world, dtype=np.float64)[:3, 2]
        size = float(np.linalg.norm(d))
        if not np.isfinite(size) or size == 0.0:  # (a Scale of 0 in z: no direction)
            return None, None
        axes.append(d / size)
    names = ", ".join(f"'{o.name}'" for o in rasters)
    if any(np.linalg.norm(np.cross(axes[0], d)) > 1e-6 for d in axes[1:]):
        return None, (f"the DEM rasters {names} have z axes that are not parallel: {auto}")
    what = (f"'{rasters[0].name}' is a DEM raster (Import Points)" if len(rasters) == 1
            else f"{names} are DEM rasters (Import Points)")
    return tuple(float(x) for x in axes[0]), (
        f"{what}: fitted along {'its' if len(rasters) == 1 else 'their'} z, as heights over x "
        "and y (the Projection setting chooses another)")


# the engine's words for a mesh that is no disk as a whole, where a patch of it may be one (Fit
# Surface then says how to fit one: Edit Mode's selected faces)
_NO_DISK = ("the mesh is closed", "separate pieces (connected components)",
            "the mesh is not a disk", "patch with exactly one border is needed, and")


class TCB_OT_fit_surface(_EngineOperator, FitSettings, ResultSettings, bpy.types.Operator):
    """Fit a smooth TCB-spline surface and its control net to the selected meshes / point clouds"""

    bl_idname = "tcb.fit_surface"
    bl_label = "Fit Surface"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        # Permissive on purpose: a wrong selection gets a specific error message (the panel
        # disables the button and shows the reason). In a mesh's Edit Mode: its selected faces
        if context.mode == "EDIT_MESH":
            return True
        return _poll_object_mode(cls, context, surface=False)

    def _fit_kwargs(self):
        smoothness = "auto" if self.auto_smoothness else self.smoothness
        if smoothness == DEFAULT_SMOOTHNESS and not self.smoothness_set:
            # left at the default (float32 of 1e-4, never set): the core cross-validates it on
            # sparse clouds
            smoothness = _core().fit.DEFAULT_SMOOTHNESS
        return dict(
            # (0, as the property's old hard limit made it: a tolerance too small to reach)
            degree=int(self.degree), mode=self.mode.lower(), tolerance=max(self.tolerance, 1e-9),
            relative=self.relative, max_control_points=self.max_control_points,
            max_iterations=self.max_iterations, smoothness=smoothness,
            criterion=self.criterion.lower(), drop_outliers=self.drop_outliers,
            fill_holes=self.fill_holes,
            projection=None if self.projection == "AUTO" else self.projection.lower(),
        )  # fmt: skip

    def prepare(self, context):
        self._started = time.perf_counter()
        check_settings(self)
        self._part = ""
        edit = context.mode == "EDIT_MESH"
        if edit:  # the selected faces (or vertices) of the mesh in Edit Mode
            problem = bridge.edit_problem(context)
            if problem:
                raise bridge.SelectionError(problem)
            obj = context.edit_object
            kind, mask = bridge.edit_selection(obj)
            # all of a mesh that no modifier or shape key makes another shape: the whole
            # object, read as Object Mode reads it (its loose vertices too, which the engine
            # leaves out and counts), and its result replaced (it had been a second one, also
            # with a loose vertex; review)
            whole = (mask.all() and (kind == "FACES") == bool(len(obj.data.polygons))
                     and not any(bridge.reshaped(obj)))
            data, digest = bridge.read_part(obj, kind, mask, whole=whole)
            self._part = "" if whole else bridge.part_text(kind, mask, digest)
        else:
            data = bridge.read_selection(context)
        self._data = data
        kwargs = self._fit_kwargs()
        self._ignored = []
        # (Drop Outliers applies to meshes too: it dissolves their spike vertices)
        if data.faces is not None and kwargs.get("projection") is not None:
            # (World Z left on from a terrain's fit refused the next mesh: user test)
            kwargs["projection"] = None
            self._ignored.append(f"Projection applies to point clouds: '{data.name}' is a "
                                 "mesh, mapped through its faces")
        if data.faces is None and self.projection == "AUTO":
            # a DEM raster: along its z (its tile's straight edges kept), as the command line
            direction, note = raster_projection(data.sources)
            if direction is not None:
                kwargs["projection"] = direction
            if note:
                self._ignored.append(note)
        # a raster's no-data fill value, in Blender's words (the engine's are Python: review)
        held = data.points if data.faces is None else data.points[np.unique(data.faces)]
        fill = _core().parameterize.fill_value_rows(held)
        if fill is not None:
            words = _core().parameterize.fill_value_words(
                fill, len(held), "points" if data.faces is None else "vertices in faces")
            raise bridge.SelectionError(
                f"'{data.name}': {words}; delete those vertices (in Edit Mode, e.g. box-select "
                "them in a side view) and fit again")
        huge = _core().parameterize.huge_rows(held)
        if huge.any():  # (it had failed as "triangles came out flipped": user test)
            words = _core().parameterize.huge_words(
                huge, held, "points" if data.faces is None else "vertices in faces")
            raise bridge.SelectionError(f"'{data.name}': {words}; delete or fix them (in Edit "
                                        "Mode) and fit again")
        self._joined, joined_notes = [], []
        if self._part and self.join_neighbours:
            join, self._joined, joined_notes = neighbour_joins(context, obj, self._part, data)
            if join:
                kwargs["join"] = join
        elif self.join_neighbours and data.faces is None and not edit:
            # point clouds fitted one by one (DEM tiles): to the surfaces of those they touch
            join, self._joined, joined_notes = cloud_neighbours(context, data, kwargs)
            if join:
                kwargs["join"] = join
        self._ignored += joined_notes
        # (a joined fit is of its neighbours' splines too)
        self._key = (data.digest(), tuple(sorted((k, v) for k, v in kwargs.items()
                                                 if k != "join")),
                     tuple((n, hashlib.sha256(s.control_points.tobytes()).hexdigest())
                           for n, (s, _) in zip(self._joined, kwargs.get("join", ()))))
        cached = _cache_get(self._key)
        self._reused = cached is not None
        if cached is not None:
            # with that fit's warnings and seconds (they had been dropped: user test); the
            # entry becomes the newest (least recently used first out; review)
            _FIT_CACHE[self._key] = _FIT_CACHE.pop(self._key)
            self._engine, self._reused_seconds = list(cached[1]), cached[2]
            return ("done", cached[0])
        core = _core()

        def fit(**kw):  # outliers are named by object and index, not by row of the merged input
            try:
                return core.fit_surface(**kw)
            except core.OutlierError as ex:
                if data.faces is not None:  # a mesh's spike vertices
                    raise core.parameterize.spike_error(
                        data.points, ex.indices, ex.heights, data.label,
                        advice="turn on Drop Outliers in the fit settings, which "
                        + core.parameterize.SPIKES_DISSOLVED) from None
                raise core.parameterize.outlier_error(
                    data.points, ex.indices, data.label,
                    advice="turn on Drop Outliers in the fit settings") from None
            except core.InvalidInputError as ex:  # the shape may be the modifiers' doing
                # a closed scan, a tube, pieces: a patch of it can be fitted as it is (holes:
                # Fill Holes, which the engine's words name)
                no_disk = (isinstance(ex, core.TopologyError)
                           and not isinstance(ex, core.HolesError)
                           and any(w in str(ex) for w in _NO_DISK)
                           # (a mesh's own faces: not a metaball's, nor a shape its modifiers
                           # make, which a part, read without them, would not be; review)
                           and len(data.sources) == 1 and data.sources[0].type == "MESH"
                           and data.modifier_note() is None)
                if isinstance(ex, core.HolesError):  # (in Blender's words)
                    ex = core.parameterize.holes_error(
                        ex.loops, advice="turn on Fill Holes in the fit settings")
                mods = data.modifier_note()
                extra = ([f"the input is read after its modifiers: {mods}; turn them off in "
                          "the viewport to fit the mesh without them"] if mods else [])
                # and how the selection was read (a mesh with loose vertices fitted as a point
                # cloud, objects merged: user test, the error spoke of a cloud only)
                extra += list(data.notes)
                if no_disk:
                    extra.append(
                        "to fit a patch of it, select a disk-like part's faces (one border, "
                        "no handles) in Edit Mode and press Fit Surface" if self._part else
                        "to fit a patch of it, select only a disk-like part of its faces (one "
                        "border, no handles) and press Fit Surface again" if edit else
                        "or fit a patch of it as it is, the mesh unchanged: select the "
                        "patch's faces in Edit Mode and press Fit Surface")
                if str(ex).startswith("at least 10 points are needed") and data.faces is not None:
                    # (the default Plane, 4 vertices: the bare count; user test)
                    extra.append("a mesh of so few vertices can be subdivided first (Edit Mode "
                                 "> Edge > Subdivide)")
                text = str(ex)
                if len(data.sources) == 1 and f"'{data.name}'" not in text:
                    # which object (a metaball's "the mesh is closed" named none: user test)
                    src = data.sources[0]
                    kind = {"MESH": "", "META": " (a metaball)", "FONT": " (a text)",
                            "CURVES": " (hair curves)", "POINTCLOUD": ""}.get(
                        src.type, f" (a {src.type.lower()})")
                    text = f"'{data.name}'{kind}: {text}"
                ex.args = (f"{text} ({'; '.join(extra)})" if extra else text,)
                raise ex from None

        self._engine = []
        return ("run", _as_stored(_recording(fit, self._engine), self.resolution,
                                  self._auto_resolution()),
                dict(points=data.points, faces=data.faces, **kwargs))

    def _auto_resolution(self) -> bool:
        return auto_resolution_of(self)

    def finish(self, context, surf):
        if context.mode == "EDIT_MESH":
            # the result is made in Object Mode, and its undo step (an error or Esc leaves the
            # selection as it was, in Edit Mode): Tab, select other faces and Fit again for
            # another patch
            bpy.ops.object.mode_set(mode="OBJECT")
        data = self._data
        name = data.name
        auto = self._auto_resolution()
        if auto and surf not in _CHOSEN_RESOLUTION:  # (a fit reused from the cache)
            _CHOSEN_RESOLUTION[surf] = surf.auto_resolution()
        resolution = chosen_resolution(surf, self.resolution) if auto else self.resolution
        kept = []
        self._rewrite_warnings = []  # (shape keys of a replaced surface and of its net)
        part = getattr(self, "_part", "")
        previous = previous_result(context, data.sources, kept, part) if self.replace else None
        replaced = kept[:1] if previous is None else []
        stale = (stale_nets(context, data.sources, part) if self.replace and previous is None
                 else [])
        coll = next((c for n in stale for c in n.users_collection), None)
        if previous is None:
            if not stale:
                # a result deleted with its net (X) holds its names until the file is saved:
                # the new one had been "Scan TCB Surface.001", for good (user test)
                early = live.drop_orphaned_weights() + live.drop_deleted_results()
                if early:  # (the view layer lists a removed object as None until updated)
                    context.view_layer.update()
            if coll is None:
                coll = bridge.result_collection(context, f"TCB {name}")
            surface, net = _new_result(coll, name, surf, resolution)
        else:  # the same objects, rewritten (as Refine does), at the data
            surface = previous
            rewrite, dropped = write_surface_mesh(surface, surf, resolution)
            net = live.own_net(surface)
            if net is None or net.type != "MESH" or not net.users_collection:  # deleted
                live.relink(surface, surf, resolution)  # (drops a deleted net's link)
                coll = (surface.users_collection[0] if surface.users_collection
                        else context.scene.collection)
                net = _new_net(coll, f"{name} TCB Net", surf, np.zeros(3))
                net.matrix_world = surface.matrix_world.copy()  # the surface's frame
            keys = write_net_mesh(net, surf)  # (in its own frame)
            replaced.append(f"replaced the previous result '{surface.name}' (Ctrl+Z brings "
                            "it back; turn off Replace Previous Result to keep both)")
            if rewrite:
                (self._rewrite_warnings if dropped else replaced).append(rewrite)
            if keys:
                self._rewrite_warnings.append(keys)
            if drop_deviation_points(surface):
                replaced.append("its Deviation Points were removed (run Deviation Map again)")
        surface[FITTED_KEY] = time.time()  # (the latest of several results is replaced)
        surface[FITTED_FRAME_KEY] = context.scene.frame_current
        # the stale nets go once the new result exists (an error before would have left
        # neither: review); their deleted surfaces, used by nothing then, go with them, and
        # the new objects take the names
        for old in stale:
            replaced.append(f"replaced the control net '{old.name}' of the previous result, "
                            "whose surface was deleted (Ctrl+Z brings it back)")
            live._remove(old)
        if stale:
            live.drop_orphaned_weights()
            live.drop_deleted_results()
            surface.name, net.name = f"{name} TCB Surface", f"{name} TCB Net"
        surface[FITTED_NAME_KEY] = surface.name
        self._rewrite_warnings += set_up_result(context, surface, net, surf, data.sources,
                      {k: getattr(self, k) for k in FIT_KEYS}
                      | {"resolution": resolution, "auto_resolution": auto},
                      live_net=self.live_net, show_net=self.show_net, part=part)
        if live.drop_orphaned_weights() or stale:  # (of surfaces deleted with X; the view
            context.view_layer.update()  # layer lists a removed object as None until updated)
        reused = ["the same input and settings as the last fit: its result was reused (the "
                  "seconds are that fit's)"] if getattr(self, "_reused", False) else []
        holes = int((surf.report or {}).get("holes_filled", 0))
        kind = "mesh" if surf.parameterization.faces is not None else "cloud"
        spanned = [f"the surface spans the {kind}'s {holes} hole{'s' if holes > 1 else ''} "
                   "(Fill Holes)"] if holes else []
        gaps = surf.open_holes(surface.tcb.resolution)
        if gaps:  # (a scan's occlusions came out as holes, the option unknown: user test)
            spanned.append(f"{gaps} gap{'s' if gaps > 1 else ''} inside the point cloud "
                           f"{'are' if gaps > 1 else 'is'} left open (no points there): turn "
                           f"on Fill Holes to cover {'them' if gaps > 1 else 'it'}")
        flat = (_core().surface.flat_height_field(surf, data.points)
                if data.faces is None and self.relative and self.tolerance > 0 else None)
        if flat is not None:  # (terrain: the command line said it, Blender not; user test)
            across, height = flat
            tol = self.tolerance * across
            spanned.append(
                f"the input is a height field {bridge.length_text(across)} across and "
                f"{bridge.length_text(height)} high, and the Tolerance is relative to the "
                f"bounding-box diagonal: {self.tolerance:g} of it is {bridge.length_text(tol)} "
                f"({tol / height:.2g} of the height range); turn off Relative for a Tolerance "
                "in Blender units (the Fit panel says what it is in the scene's units)")
        if reused:
            seconds = getattr(self, "_reused_seconds", None)
        else:
            seconds = time.perf_counter() - getattr(self, "_started", time.perf_counter())
            _cache_put(self._key, surf, self._engine, seconds)
        # which shape was fitted: the one the modifiers make (the report had not said so,
        # nor how many points that is: user test)
        mods = data.modifier_note()
        read = [f"fitted after the modifiers ({mods}): {len(data.points)} "
                f"{'vertices' if data.faces is not None else 'points'}"] if mods else []
        report_result(self, surf,
                      read + list(data.notes) + self._ignored + reused + replaced + spanned
                      + join_words(surf, getattr(self, "_joined", [])),
                      self._rewrite_warnings + _engine_notes(self), seconds=seconds, auto=auto)
        return {"FINISHED"}

    def draw(self, context):
        draw_fit_settings(self.layout, self)


# --- Refine -------------------------------------------------------------------------------------


# Refine's automatic tolerance (half the current error) is at least this share of the
# diagonal: below it a fit's error is rounding (the stored spline keeps its parameters in
# float32: a flat grid fitted to 9e-17 is refitted at the same knots to 5.3e-9)
REFINE_ROUNDING = 1e-7


class TCB_OT_refine(_EngineOperator, bpy.types.Operator):
    """Continue the adaptive fit of the active TCB surface with a tighter tolerance or budget"""

    bl_idname = "tcb.refine"
    bl_label = "Refine Surface"
    bl_options = {"REGISTER", "UNDO"}
    _what = "Refining"

    tolerance: FloatProperty(
        name="Tolerance",
        description="New tolerance (0: half of the current error, or of the previous tolerance "
        "if that is smaller)",
        default=0.0, soft_min=0.0, precision=6, step=0.01,
    )  # fmt: skip
    relative: BoolProperty(name="Relative", default=True,
                           description="Tolerance is a fraction of the bounding-box diagonal")  # fmt: skip
    max_control_points: IntProperty(
        name="Max Control Points", default=0, soft_min=0,
        description="New budget (0: the fit's budget, or twice the current number of control "
        "points if that is more)",
    )  # fmt: skip
    max_iterations: IntProperty(
        name="Max Iterations", default=20, soft_min=1,
        description="Largest number of fits (the first one refits the current control net)",
    )  # fmt: skip

    @classmethod
    def poll(cls, context):
        return _poll_object_mode(cls, context)

    def invoke(self, context, event):
        surface = active_surface(context)
        if surface is not None and not self.properties.is_property_set("relative"):
            self.relative = surface.tcb.relative  # the box shows what an untouched one means
        return super().invoke(context, event)

    def prepare(self, context):
        # (the summary's seconds: the engine's alone had said 0.88 s for 3.4 s, without the
        # reading and Auto Resolution's pass; user test)
        self._started = time.perf_counter()
        check_settings(self, automatic=True)  # (the engine's words had been shown)
        surface = editable_surface(context, " to refine")
        st = surface.tcb
        self._surface = surface
        stored = stored_surface(surface, use_net=False)
        rel = self.relative if self.properties.is_property_set("relative") else st.relative
        rep = dict(stored.report or {})
        self._iteration_offset = len(rep.get("history", ()))  # the engine numbers on from it
        # the default: half of the current error (a fit often beats a loose tolerance by far:
        # half the tolerance would then change nothing), or of the tolerance if smaller (only
        # when it is in the same units)
        key = ("max" if is_max(st) else "rms") + ("_rel" if rel else "")
        current = float(rep.get(key, 0.0))
        if key.startswith("rms") and "rms_area" in rep:  # uneven clouds meet both (fit_surface)
            current = max(current, float(rep[key.replace("rms", "rms_area")]))
        previous = st.tolerance if rel == st.relative else np.inf
        tol = self.tolerance or 0.5 * (min(previous, current) if current > 0 else st.tolerance)
        # a fit at rounding level (a flat mesh: RMS 9e-17 of the diagonal) has nothing to
        # refine: half its error had sent Refine to the budget chasing rounding (1627 control
        # points, RMS 5.8e-10: user test); the default stops at REFINE_ROUNDING
        floor = REFINE_ROUNDING * (1.0 if rel else float(rep.get("diagonal", 0.0)))
        self._at_rounding = not self.tolerance and key in rep and current <= floor
        if not self.tolerance:
            tol = max(tol, floor)
        budget = self.max_control_points or max(st.max_control_points, 2 * st.control_points)
        self._settings = dict(tolerance=tol, relative=rel, max_control_points=budget,
                              max_iterations=self.max_iterations)  # fmt: skip
        self._before = (current, int(len(stored.control_points)))
        data = source_data(context, surface)
        self._notes = data.notes
        surf = with_net_edits(surface, stored)
        faces, what = source_mismatch(surf, data)
        if what is not None and data.unmodified:
            # (nothing was moved: "changed since ... (other coordinates: moved, ...)" had led;
            # user test)
            raise bridge.SelectionError(
                f"{'; '.join(data.unmodified)}: Refine needs the shape '{surface.name}' was "
                "fitted to")
        animated = animated_problem(context, surface, data) if what is not None else None
        if animated:  # (the frame, not an edit: user test)
            raise bridge.SelectionError(animated)
        if what is not None:
            names = changed_names(surf, data)  # (only those that changed: user test)
            hidden = "".join(f"; {n}" for n in data.notes)
            # (one turned off since the fit: user test)
            mods = data.modifier_note(applied_only=False)
            hidden += f"; {mods}" if mods else ""
            raise bridge.SelectionError(
                f"{names} changed since '{surface.name}' was fitted ({what}{hidden}): Refine "
                "continues the fit of the same data; select the source and use Fit Surface to "
                "fit it as it is now"
            )
        # Refine fits the data again: edits of the net are not kept, and the user is told (also
        # those kept in the stored spline: an imported edited one, a net dropped by
        # Re-tessellate)
        edited = int(surf.report.get("edited", 0))
        self._warnings = [f"{edited} edited control point{' was' if edited == 1 else 's were'} "
                          "replaced (Refine fits the data again; Ctrl+Z brings the edits back)"
                          ] if edited else []
        moved = net_moved_note(surface, stored)
        if moved:
            self._warnings.append(
                f"{moved}: its vertices counted as edits, and the refined surface is at the data "
                "again, while the net object stays where it was moved (to fit the data "
                "elsewhere, move the source and use Fit Surface)")
        # a joined patch is joined again, to its neighbours as they are now (refined on its
        # own, its border would part from theirs again)
        join, self._joined = None, []
        part = str(surface.get(PART_KEY, ""))
        if part and (stored.report or {}).get("join"):
            found, self._joined, notes = neighbour_joins(context, data.sources[0], part, data)
            self._notes = list(self._notes) + notes + (
                [] if found else ["no longer joined: no neighbouring patch's surface shares "
                                  "its border now"])
            join = found or None
        elif not part and data.faces is None and (stored.report or {}).get("join"):
            # a DEM tile joined to the tiles fitted before: to them as they are now, along the
            # direction it was fitted
            found, self._joined, notes = cloud_neighbours(
                context, data, {"projection": tuple(stored.parameterization.axes[2])},
                param=stored.parameterization)
            self._notes = list(self._notes) + notes + (
                [] if found else ["no longer joined: no other tile's surface reaches its "
                                  "border now"])
            join = found or None
        self._engine = []
        return ("run", _as_stored(_recording(surf.refine, self._engine), st.resolution,
                                  st.auto_resolution),
                dict(points=data.points, faces=faces, rounding=data.rounding, join=join,
                     **self._settings))

    def finish(self, context, surf):
        surface = self._surface
        st = surface.tcb
        moved = moved_note(surface)
        if st.auto_resolution:  # (chosen again: a refined fit's mesh needs a finer one)
            st.resolution = chosen_resolution(surf, st.resolution)
        rewrite, dropped = write_surface_mesh(surface, surf, st.resolution)
        keys = write_net_mesh(live.own_net(surface), surf) if st.net is not None else None
        live.relink(surface, surf, st.resolution, self.report)
        store_spline(surface, surf)
        store_stats(st, surf, self._settings)
        mods = net_modifier_problem(surface)
        warnings = (list(getattr(self, "_warnings", ())) + ([moved] if moved else [])
                    + ([mods] if mods else []) + ([rewrite] if dropped else [])
                    + ([keys] if keys else [])
                    + _engine_notes(self))
        notes = list(getattr(self, "_notes", ())) + ([rewrite] if rewrite and not dropped
                                                      else [])
        if drop_deviation_points(surface):
            notes.append("the Deviation Points of the previous surface were removed (run "
                         "Deviation Map again)")
        rep = dict(surf.report or {})
        kept = rep.get("kept_start")
        if kept:  # (core: refine() returns the surface it started from when it got worse)
            d = float(rep.get("diagonal", 1.0)) or 1.0
            if kept["refined_control_points"] == self._before[1]:
                # the run's best was the same net refitted: the error stopped falling at once
                # ("the refined surface (iteration 2, 105 control points)" had read as a new
                # net of the same size; user test)
                what = "max error" if kept.get("criterion") == "max" else "RMS"
                again, start = (f"{kept[k] / d:.4g}" for k in ("refined", "start"))
                than = (f"the same {what}, {start}" if again == start
                        else f"{what} {again} against {start}")
                warnings.append(
                    "nothing was refined: no larger net lowered the error, and the same "
                    f"{kept['refined_control_points']} control points fitted again (iteration "
                    f"{kept['refined_iteration']}) have {than} of the diagonal; the surface is "
                    "kept as it was")
            else:
                words = _core().refine.kept_words(kept, d, " of the diagonal")
                warnings.append(
                    f"nothing was refined: the refined surface (iteration "
                    f"{kept['refined_iteration']}, {kept['refined_control_points']} control "
                    f"points), at the data, {words}; the surface is kept as it was")
        elif (len(surf.control_points) == self._before[1]
                and str(rep.get("stop_reason", "")).startswith("tolerance reached")):
            what = "max" if is_max(st) else "RMS"
            relative = self._settings["relative"]

            def size(x):  # (an absolute one in the scene's length unit)
                return f"{x:.4g} of the diagonal" if relative else bridge.length_text(x)
            if self._at_rounding:
                warnings.append(f"nothing was refined: the surface already fits its data to "
                                f"rounding ({what} {size(self._before[0])})")
            else:
                warnings.append(f"nothing was refined: the surface already meets the "
                                f"tolerance {size(self._settings['tolerance'])} ({what} "
                                f"{size(self._before[0])}); set a smaller Tolerance")
        report_result(self, surf, notes + join_words(surf, getattr(self, "_joined", [])),
                      warnings, auto=st.auto_resolution,
                      seconds=time.perf_counter() - self._started)
        return {"FINISHED"}


# --- Re-tessellate, deviation map, net visibility, export ---------------------------------------


def _tessellation(surf, resolution: int, weights: bool, callback=None):
    """Re-tessellate's engine part (on the job's thread): the surface mesh ``(verts, faces)``
    at ``resolution`` and, with ``weights``, the live net's padded weights of its vertices
    (:func:`live.padded_weights`), from one evaluation of the basis
    (``TCBSurface.tessellate_with_matrix``; they had been evaluated twice). ``callback``
    hears the grid's steps, then ``{"points_done", "points"}`` after each chunk of vertices,
    and may return True to stop (CancelledError): resolution 2048 is 3 million vertices,
    20-40 s."""
    if not weights:
        return (*surf.tessellate(resolution, callback=callback), None)
    verts, faces, matrix = surf.tessellate_with_matrix(resolution, callback=callback)
    return verts, faces, live.padded_weights(matrix)


class TCB_OT_retessellate(_EngineOperator, bpy.types.Operator):
    """Rebuild the surface mesh of the active TCB surface from its stored spline"""

    bl_idname = "tcb.retessellate"
    bl_label = "Re-tessellate"
    bl_options = {"REGISTER", "UNDO"}
    # the mesh is evaluated on a thread, with the share of the vertices done in the status bar
    # and Esc to cancel (resolution 2048 had blocked Blender for 41 s: user test)
    _what = "Re-tessellating"

    resolution: IntProperty(name="Resolution", default=64, soft_min=2, soft_max=512)

    @classmethod
    def poll(cls, context):
        return _poll_object_mode(cls, context)

    def invoke(self, context, event):
        surface = active_surface(context)
        if surface is not None and not self.properties.is_property_set("resolution"):
            self.resolution = surface.tcb.resolution or self.resolution
        return _EngineOperator.invoke(self, context, event)

    def prepare(self, context):
        check_settings(self)
        surface = editable_surface(context)
        surf = stored_surface(surface)
        self._surface, self._surf = surface, surf
        # the live net's weights are made on the job's thread too, when relink will want them
        # (a net in the scene and a live link; otherwise relink drops or keeps none)
        st, net = surface.tcb, surface.tcb.net
        weights = (net is not None and net.type == "MESH" and bool(net.users_collection)
                   and (surface.modifiers.get(live.MODIFIER_NAME) is not None
                        or st.weights is not None))
        return ("run", _tessellation, dict(surf=surf, resolution=self.resolution,
                                           weights=weights))

    def finish(self, context, result):
        surface, surf = self._surface, self._surf
        verts, faces, weights = result
        moved = moved_note(surface)
        rewrite, dropped = write_surface_mesh(surface, surf, self.resolution,
                                              tessellation=(verts, faces))
        if live.relink(surface, surf, self.resolution, self.report, weights=weights):
            store_spline(surface, surf)  # the net was dropped: its edits are kept
        surface.tcb.resolution = self.resolution
        surface.tcb.auto_resolution = False  # (the user's choice: Refine keeps it; review)
        for problem in (moved, net_vertex_problem(surface), net_modifier_problem(surface),
                        net_shape_key_problem(surface), rewrite if dropped else None):
            if problem:
                self.report({"WARNING"}, f"TCB: {problem}")
        if rewrite and not dropped:
            self.report({"INFO"}, f"TCB: {rewrite}")
        return {"FINISHED"}


# Deviation map of a cloud: surface vertices with no data near them (color; count on the object)
NO_DATA_COLOR = (0.5, 0.5, 0.5)
NO_DATA_KEY = "tcb_deviation_no_data"


class TCB_OT_deviation_map(_EngineOperator, bpy.types.Operator):
    """Color the active TCB surface by how far the input data is from it, and store the distance
    of every input point to the surface on a copy of the input points"""

    # What the surface vertices show: for a mesh, their distance to the mesh's triangles (a
    # continuous surface: the distance between the two surfaces). For a point cloud, the
    # distance to the nearest data point would measure the gaps between the samples, so each
    # vertex takes the data-to-surface distance of the data near it
    # (core.geometry.distances_at_vertices); vertices with no data near them are grey, value 0.
    # The color range is that of the data-to-surface distances of the fitted points, shared by
    # the surface and the point copy.

    bl_idname = "tcb.deviation_map"
    bl_label = "Deviation Map"
    bl_options = {"REGISTER", "UNDO"}
    # the distances are computed on a thread, with the progress in the status bar and Esc to
    # cancel (1e6 points of a cloud take about 13 s: it had blocked Blender with no progress)
    _what = "Deviation Map"

    points_copy: BoolProperty(
        name="Copy of Input Points", default=True,
        description="Also create a point object with the distance of each input point to the surface",
    )  # fmt: skip

    @classmethod
    def poll(cls, context):
        return _poll_object_mode(cls, context)

    def prepare(self, context):
        surface = editable_surface(context)
        data = source_data(context, surface)
        surf = stored_surface(surface)
        # the same data in another order, as Sort Elements leaves them, are no change: the
        # points the fit left out are found in their new order on the job's thread
        same_set = surf.same_data_set(data.points)
        self._reordered = same_set and _core().surface.data_digest(data.points) != (
            (surf.report or {}).get("data_digest"))
        self._same = (same_set and not self._reordered) or (
            not same_set and surf.fitted_to(data.points, data.rounding))
        # ... and so is the mesh with vertices in no face added or deleted (renumbered)
        self._reordered = self._reordered or not self._same and surf.same_mesh(
            data.points, data.faces)
        if data.unmodified and not (self._same or self._reordered):
            # (its map had measured the other shape, 10x off, with a warning: user test)
            raise bridge.SelectionError(
                f"{'; '.join(data.unmodified)}: the map measures the shape '{surface.name}' "
                "was fitted to")
        self._surface, self._data, self._surf = surface, data, surf
        self._net_moved = net_moved_note(surface, stored_surface(surface, use_net=False))
        cloud = data.faces is None
        # a cloud's surface colours are computed on the job's thread too, at the surface's
        # vertices as they are now (finish checks that they did not change meanwhile)
        verts = _painted_vertices(context, surface, surf) if cloud else None
        if self._reordered:
            return ("run", _reordered_distances, dict(surf=surf, points=data.points,
                                                      faces=data.faces, vertices=verts))
        return ("run", _data_distances, dict(surf=surf, points=data.points, cloud=cloud,
                                             vertices=verts))

    def finish(self, context, result):
        surface, data, surf = self._surface, self._data, self._surf
        feet, data_dist, shading, *used = result
        # (reordered: the mask of the points the fit used in their order now; None: they map
        # to other parameters, so the data are not the same after all)
        used = used[0] if used else surf.parameterization.used
        moved = moved_note(surface, "the colors are painted on it where it is now, the "
                                    "distances are those to the spline (Re-tessellate puts it back)")
        # the source moved or edited since the fit: the distances measure that, not the fit
        # (user test: RMS 0.2 for a fit of 1.4e-4, and nothing said why; Refine refuses)
        changed = None
        if not (self._same or self._reordered and used is not None):
            # (a source hidden since the fit, read without its modifiers, is refused in
            # prepare: nothing was edited, and fitting it again would fit the other shape)
            changed = (
                f"{changed_names(surf, data)} changed since "  # (those that did: user test)
                f"'{surface.name}' was fitted (moved, transformed or edited): the distances "
                "are those of the data as it is now; select the source and use Fit Surface to "
                "fit it again")
            animated = animated_problem(context, surface, data)  # (the frame: user test)
            if animated:
                changed = f"{animated} (the distances are those of the data at this frame)"
        # a live net whose weights were deleted is linked again, so the colors show the net
        live.relink(surface, surf, surface.tcb.resolution, rewrite=False)

        # points the fit left out (Drop Outliers) keep their distance on the point copy but
        # do not set the statistics, the colour range or (clouds) the surface's colours
        counted = _counted(len(data_dist), used)
        left_out = int(len(data_dist) - counted.sum())
        fitted_dist = data_dist[counted]
        verts = _painted_vertices(context, surface, surf)
        if data.faces is None:
            if shading is not None and np.array_equal(shading[0], verts):
                surf_dist, has_data = shading[1], shading[2]
            else:  # the surface changed while the job ran (or a live link was just repaired)
                from ..core.geometry import distances_at_vertices

                surf_dist, has_data = distances_at_vertices(verts, feet[counted], fitted_dist)
        else:
            surf_dist = bridge.nearest_distances(verts, data.points, data.faces)
            has_data = ~_over_holes(surface, surf, len(verts))
            # (over a filled hole the distance to the mesh's faces is the hole's size: it had
            # set the colour range, 0.149 against the data's 0.0114; user test)
            surf_dist = np.where(has_data, surf_dist, 0.0)
        vmax = float(max(surf_dist.max(initial=0.0), fitted_dist.max(initial=0.0)))
        colors = bridge.ramp_colors(surf_dist, vmax)
        colors[~has_data, :3] = NO_DATA_COLOR
        bridge.set_float_attribute(surface.data, DEVIATION_ATTR, surf_dist)
        bridge.set_color_attribute(surface.data, DEVIATION_ATTR + "_color", colors)
        mat = bridge.deviation_material(attribute=DEVIATION_ATTR + "_color")
        if mat.name not in surface.data.materials:
            surface.data.materials.append(mat)
        # every face in the map's slot: with a material of the user's first, the map's
        # colours never showed in Material Preview or renders (user test). A rewrite of the
        # mesh (Refine, Re-tessellate) drops the map and gives the faces the first slot again
        slot = surface.data.materials.find(mat.name)
        surface.data.polygons.foreach_set(
            "material_index", np.full(len(surface.data.polygons), slot, np.int32))

        st = surface.tcb
        if self.points_copy:
            pts_obj = st.deviation_points
            if pts_obj is not None and not pts_obj.users_scene:
                # deleted by the user (X), kept alive by the pointer: a new copy is made
                # (user test: the next copy went into the deleted one, in no scene)
                drop_deviation_points(surface)
                pts_obj = None
            if pts_obj is None:
                origin = bridge.local_origin(data.points)
                local = data.points - origin
            else:
                local = bridge.to_local(pts_obj, data.points)
            mesh = bridge.new_mesh(f"{surface.name} Deviation Points", local)
            bridge.set_float_attribute(mesh, DEVIATION_ATTR, data_dist)
            bridge.set_color_attribute(
                mesh, DEVIATION_ATTR + "_color", bridge.ramp_colors(data_dist, vmax)
            )
            if pts_obj is None:
                coll = (
                    surface.users_collection[0]
                    if surface.users_collection
                    else context.scene.collection
                )
                pts_obj = bridge.link_new_object(
                    coll, f"{surface.name} Deviation Points", mesh, origin
                )
                pts_obj.tcb.role = "DEVIATION"
                pts_obj.tcb.surface = surface
                st.deviation_points = pts_obj
            else:
                bridge.replace_mesh(pts_obj, mesh, f"{surface.name} Deviation Points")
        elif drop_deviation_points(surface):
            # without a new copy the old one would show the distances to the surface as it
            # was (user test: its max 0.0033 beside the map's 0.094 after a net edit)
            data.notes.append("the Deviation Points of the last map were removed (Copy of "
                              "Input Points is off)")

        # the deviation's own statistics (the fit's stay: they are what the fit reached, and a
        # closest-point distance is another measure than the fit's error at the data's own
        # parameters; the panel showed these under the fit's "RMS" beside its tolerance)
        st.has_deviation = True
        st.deviation_max = vmax
        st.deviation_rms = float(np.sqrt(np.mean(fitted_dist**2))) if len(fitted_dist) else 0.0
        st.deviation_data_max = float(fitted_dist.max(initial=0.0))
        st.deviation_surface_max = (0.0 if data.faces is None
                                    else float(surf_dist.max(initial=0.0)))
        # relative to the data's bounding-box diagonal, as the fit's numbers are
        fitted_points = data.points[counted]
        diagonal = float(np.linalg.norm(np.ptp(fitted_points, axis=0))) if len(fitted_points) else 0.0
        scale = 1.0 / diagonal if diagonal > 0 else 0.0
        st.deviation_rms_rel = st.deviation_rms * scale
        st.deviation_data_max_rel = st.deviation_data_max * scale
        no_data = int(len(has_data) - has_data.sum())
        surface[NO_DATA_KEY] = no_data  # the panel's legend shows grey when there are any
        _show_attribute_colors(context)
        # a mesh's left out: its spike vertices dissolved by Drop Outliers, the others loose
        spikes = min(left_out, int((surf.report or {}).get("outliers", 0))) if (
            data.faces is not None) else 0
        loose = left_out - spikes
        what = ", ".join(
            ([f"{loose} loose vert{'ex' if loose == 1 else 'ices'} (in no face)"] if loose else [])
            + ([f"{spikes} spike vert{'ex' if spikes == 1 else 'ices'} (Drop Outliers)"]
               if spikes else [])) if data.faces is not None else (
            f"{left_out} outlier{'' if left_out == 1 else 's'}")
        note = f" ({what} left out of the fit not counted)" if left_out else ""
        if no_data:
            where = ("over the mesh's filled holes (no data there)" if data.faces is not None
                     else "with no data near them")
            note += f"; {no_data} surface vertices {where} are grey"
        note += "".join(f"; {n}" for n in data.notes)  # e.g. a hidden source read without modifiers
        rep = surf.report or {}
        if "rms" in rep and not (changed or rep.get("edited")):
            # (two RMS of one surface and its data, 2x apart, and nothing said why: user test)
            note += (f"; these are distances to the closest surface points, the fit's RMS "
                     f"{bridge.length_text(rep['rms'])} and max "
                     f"{bridge.length_text(rep.get('max', np.nan))} errors at "
                     "each point's own parameters (never smaller)")
        back = (f"; surface to mesh max {bridge.length_text(st.deviation_surface_max)}"
                if data.faces is not None else "")
        self.report({"INFO"}, f"TCB deviation: data to surface RMS "
                              f"{bridge.length_text(st.deviation_rms)}, max "
                              f"{bridge.length_text(st.deviation_data_max)}{back}; color range "
                              f"0 - {bridge.length_text(vmax)}"
                              f"{note}")  # fmt: skip
        net_moved = self._net_moved and (
            f"{self._net_moved}: the distances are to the surface where the moved net puts it, "
            "not where it was fitted (move the net back to measure the fit)")
        for problem in (moved, changed, net_moved, net_modifier_problem(surface),
                        net_shape_key_problem(surface)):
            if problem:
                self.report({"WARNING"}, f"TCB: {problem}")
        return {"FINISHED"}


def _painted_vertices(context, surface, surf) -> np.ndarray:
    """World positions of the vertices of the surface's own mesh, where they are shown: the
    Deviation Map's colours are written on them (the modifiers carry them on). Evaluated,
    so with a live net's edits; but a modifier of the user's that changes the vertex count
    (Subdivision, Solidify, Mirror, Decimate) puts other vertices there (user test: a
    traceback, 466 values for 2579 vertices): then the spline ``surf`` (with the net's edits)
    at the tessellation's parameters when the live net drives the mesh, else the mesh's own
    vertices."""
    verts = bridge.read_world_positions(surface, context.evaluated_depsgraph_get())
    n = len(surface.data.vertices)
    if len(verts) == n:
        return verts
    if surface.modifiers.get(live.MODIFIER_NAME) is not None:
        uv, _ = surf.tessellation_uv(surface.tcb.resolution)
        if len(uv) == n:
            return np.asarray(surf(uv), dtype=np.float64)
    return bridge.read_world_positions(surface)


def _over_holes(surface, surf, n: int) -> np.ndarray:
    """Mask of the ``n`` vertices of the surface's mesh that lie over a hole the fit spanned
    (Fill Holes: ``core.parameterize.Parameterization.in_holes`` at the tessellation's
    parameters); none when no hole was filled or when the mesh's vertices are not the
    tessellation's (a modifier of the user's changed their count)."""
    if not (surf.report or {}).get("holes_filled"):
        return np.zeros(n, dtype=bool)
    uv, _ = surf.tessellation_uv(surface.tcb.resolution)
    if len(uv) != n:
        return np.zeros(n, dtype=bool)
    return surf.parameterization.in_holes(uv)


def _counted(n: int, used) -> np.ndarray:
    """Mask of the ``n`` data points that a fit used (``used``: the parameterization's, or of
    the data in another order, :func:`_reordered_distances`; None: all): the Deviation Map's
    statistics, colour range and (clouds) surface colours leave out those the fit left out
    (Drop Outliers)."""
    used = None if used is None else np.asarray(used, dtype=bool)
    return used if used is not None and len(used) == n else np.ones(n, dtype=bool)


def _reordered_distances(surf, points, faces, vertices=None, callback=None):
    """:func:`_data_distances` of the data the surface was fitted to stored in another order
    (Sort Elements), and the mask of the points the fit used in that order: the stored one
    when it uses all, else that of the data parameterized again (``TCBSurface.reordered``;
    None when they map to other parameters: then all points count, and the map says that the
    data changed)."""
    used = np.asarray(surf.parameterization.used, dtype=bool)
    if not used.all() or len(used) != len(points):  # (other vertices in no face: same_mesh)
        param = surf.reordered(points, faces)
        used = None if param is None else np.asarray(param.used, dtype=bool)
    return (*_data_distances(surf, points, faces is None, vertices, callback, used=used), used)


def _data_distances(surf, points, cloud, vertices=None, callback=None, used=False):
    """The Deviation Map's engine part (on the job's thread): (feet, distances, shading) of
    the data points; a cloud's feet are its closest surface points, a mesh needs none (None).
    ``shading``: for a cloud with the surface mesh's world ``vertices``, ``(vertices,
    values, has_data)`` of :func:`core.geometry.distances_at_vertices` from the counted
    points (0.9 s for 1e6 points, which had held up Blender in ``finish``), else None.
    ``used``: the mask of the points the fit used (:func:`_counted`; default: the stored one)."""
    if used is False:
        used = surf.parameterization.used
    if cloud:
        feet = np.asarray(surf.closest_points(points, callback=callback), dtype=np.float64)
        dist = np.linalg.norm(feet - points, axis=1)
        shading = None
        if vertices is not None:
            from ..core.geometry import distances_at_vertices

            counted = _counted(len(dist), used)
            shading = (vertices, *distances_at_vertices(vertices, feet[counted], dist[counted]))
        return feet, dist, shading
    dist = np.abs(np.asarray(surf.distances(points, callback=callback), dtype=np.float64))
    return None, dist, None


def _show_attribute_colors(context):
    screen = getattr(context, "screen", None)
    if screen is None:
        return
    for area in screen.areas:
        if area.type == "VIEW_3D":
            for space in area.spaces:
                if space.type == "VIEW_3D" and space.shading.type == "SOLID":
                    space.shading.color_type = "VERTEX"


class TCB_OT_toggle_net(bpy.types.Operator):
    """Show or hide the control net of the active TCB surface"""

    bl_idname = "tcb.toggle_net"
    bl_label = "Show/Hide Control Net"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        surface, net = result_objects(getattr(context, "active_object", None))
        if surface is None:
            cls.poll_message_set(no_surface_words(context))
        elif net is None:
            cls.poll_message_set(f"'{surface.name}' has no control net")
        return surface is not None and net is not None

    def execute(self, context):
        _, net = result_objects(context.active_object)
        if not net.users_scene:  # deleted (X), kept alive by the surface's pointer (user test)
            self.report({"ERROR"}, f"'{net.name}' was deleted: select the source and use Fit "
                                   "Surface to make a new control net (it replaces the result)")
            return {"CANCELLED"}
        if net.name not in context.view_layer.objects:
            # (in an excluded collection, it had not said which, nor what to do: user test)
            excluded = bridge.hiding_collections(context.view_layer, net, excluded=True)
            self.report({"ERROR"}, f"'{net.name}' is not in the current view layer" + (
                f": its collection {', '.join(repr(n) for n in excluded)} "
                f"{'is' if len(excluded) == 1 else 'are'} excluded from it; include "
                f"{'it' if len(excluded) == 1 else 'them'} (the checkbox beside the collection "
                "in the outliner)" if excluded else ""))
            return {"CANCELLED"}
        if net.visible_get():
            net.hide_set(True)
            return {"FINISHED"}
        # shown also when it was disabled in viewports (the outliner's monitor icon: each
        # press had flipped its hide state, and it never appeared: user test)
        net.hide_set(False)
        net.hide_viewport = False
        if not net.visible_get():
            self.report({"WARNING"}, f"'{net.name}' stays hidden: its collection is hidden or "
                                     "excluded in the outliner")
        return {"FINISHED"}


class TCB_OT_export_spline(bpy.types.Operator, ExportHelper):
    """Save the spline of the active TCB surface (knots, configuration, control points) as .npz"""

    bl_idname = "tcb.export_spline"
    bl_label = "Export Spline (.npz)"
    filename_ext = ".npz"
    filter_glob: StringProperty(default="*.npz", options={"HIDDEN"})
    # ('//' is taken relative to the .blend, _file_path: Blender had warned it was not)
    filepath: StringProperty(name="File Path", description="Filepath used for exporting the "
                             "file", maxlen=1024, subtype="FILE_PATH",
                             options={"PATH_SUPPORTS_BLEND_RELATIVE"})  # fmt: skip

    @classmethod
    def poll(cls, context):
        # (in Edit Mode too; the others' words when nothing fits: review of a batch script,
        # which got only "poll() failed, context is incorrect")
        if active_surface(context) is None:
            cls.poll_message_set(no_surface_words(context))
            return False
        return True

    def execute(self, context):
        try:
            surface = active_surface(context)
            if surface is None:
                raise bridge.SelectionError(no_surface_words(context))
            path = _file_path(self.filepath)
            stored_surface(surface).save(path)
        except _user_errors() as ex:
            self.report({"ERROR"}, str(ex))
            return {"CANCELLED"}
        except OSError as ex:  # (not the engine's temporary file's name: user test)
            self.report({"ERROR"}, f"Could not write {path}: {ex.strerror or ex}")
            return {"CANCELLED"}
        problems = [p for p in (net_vertex_problem(surface) or net_modifier_problem(surface),
                                net_shape_key_problem(surface)) if p]
        # (the saved spline is where the moved net puts the surface, as shown; it had been
        # saved without a word, away from the data: user test)
        moved = net_moved_note(surface, stored_surface(surface, use_net=False))
        if moved:
            problems.append(f"{moved}: the spline was saved where the moved net puts it, off "
                            "the data it was fitted to (Ctrl+Z the move, or move the net back, "
                            "to save the fitted one)")
        self.report({"WARNING"} if problems else {"INFO"},
                    f"TCB: saved {path}" + "".join(f"; {p}" for p in problems))
        return {"FINISHED"}


def _file_path(filepath: str) -> str:
    """The full path of a file path given to Export or Import Spline: ``//`` is relative to
    the .blend (it had been taken from the filesystem's root), and refused while the .blend
    is not saved (the file had been written to the folder Blender was started in, reported as
    "saved rel.npz"; user test)."""
    if filepath.startswith("//") and not bpy.data.filepath:
        raise bridge.SelectionError(
            f"'{filepath}' is relative to the .blend file, which is not saved yet: save the "
            ".blend file first, or give the file's full path")
    return os.path.abspath(os.path.expanduser(bpy.path.abspath(filepath)))


def _import_sources(context, surf, label: str):
    """``(sources, notes)`` of an imported spline: the selected objects (the add-on's results
    left out) when they are the data it was fitted to (:func:`source_mismatch`, as Refine
    takes them), else none, with a note saying why and what Refine and the Deviation Map
    then need. ``label``: the file's name, for the notes."""
    without = ("the result has no source object, which Refine and the Deviation Map need "
               "(select the scan it was fitted to, in the file's coordinates, and import again)")
    chosen = [o for o in context.selected_objects if not bridge._is_result(o)]
    if not chosen:
        return [], [without]
    try:
        data = bridge.read_selection(context)
    except bridge.SelectionError as ex:
        return [], [f"the selection was not taken as its source ({ex}); {without}"]
    names = ", ".join(repr(o.name) for o in data.sources)
    cloud = surf.parameterization.faces is None
    if cloud != (data.faces is None):
        what = ("a point cloud then, a mesh now" if cloud
                else "a mesh then, a point cloud now")
    else:
        what = source_mismatch(surf, data)[1]
    if what is None:
        return list(data.sources), [f"linked to its source {names}"]
    # the file's coordinates turned as Blender's OBJ importer turns them by default (Forward
    # -Z, Up Y: the file's (x, y, z) at (x, -z, y), by the object's rotation): said only then
    # (it had been said for any other coordinates: user test)
    p = data.points
    turned = np.c_[p[:, 0], p[:, 2], -p[:, 1]]
    axes = (" (it is the data turned as Blender's OBJ importer turns a file's axes by default: "
            "clear the scan's rotation, Alt+R, or import it with Forward Y and Up Z)"
            if what.startswith("other coordinates") and (
                surf.same_data_set(turned) or surf.fitted_to(turned, data.rounding)) else "")
    if len(surf.parameterization.uv) < len(data.points) and cloud == (data.faces is None):
        # (a spline of selected faces: its .npz keeps no list of them; review)
        without = ("the result has no source object, which Refine and the Deviation Map need "
                   "(a spline fitted to a part of a scan, its selected faces, is not linked to "
                   "the scan)")
    return [], [f"{names} {'is' if len(data.sources) == 1 else 'are'} not the data '{label}' "
                f"was fitted to ({what}){axes}: not taken as its source; {without}"]


class TCB_OT_import_spline(bpy.types.Operator, ImportHelper):
    """Make a TCB surface and its control net from a spline saved as .npz (Export Spline, the
    command line's --spline, TCBSurface.save); the selected scan it was fitted to becomes its
    source"""

    bl_idname = "tcb.import_spline"
    bl_label = "Import Spline (.npz)"
    bl_options = {"REGISTER", "UNDO"}
    filename_ext = ".npz"
    filter_glob: StringProperty(default="*.npz", options={"HIDDEN"})
    filepath: StringProperty(name="File Path", description="Filepath used for importing the "
                             "file", maxlen=1024, subtype="FILE_PATH",
                             options={"SKIP_PRESET", "HIDDEN", "PATH_SUPPORTS_BLEND_RELATIVE"})  # fmt: skip
    resolution: IntProperty(name="Resolution", default=64, soft_min=2, soft_max=512,
                            description="Grid steps of the surface mesh along the domain's "
                            "longer side (with Auto Resolution off)")  # fmt: skip
    auto_resolution: BoolProperty(
        name="Auto Resolution", default=True,
        description="The coarsest of 64, 128 and 256 whose flat triangles stay within the "
        "fit's max error of the spline",
    )  # fmt: skip
    live_net: BoolProperty(
        name="Live Net", default=True,
        description="Moving control-net vertices updates the surface (Geometry Nodes modifier)",
    )  # fmt: skip
    show_net: BoolProperty(name="Show Net", default=True)

    @classmethod
    def poll(cls, context):
        return _poll_object_mode(cls, context, surface=False)  # (with its words: user test)

    def _auto_resolution(self) -> bool:
        return auto_resolution_of(self)

    def execute(self, context):
        started = time.perf_counter()
        core = _core()
        # everything that reads the file is done before an object is made (a damaged file had
        # left a half-made result and a traceback: user test)
        try:
            check_settings(self)
            if not self.filepath or self.filepath.endswith(("/", "\\")):
                raise bridge.SelectionError("No file chosen: choose the .npz file of a spline")
            path = _file_path(self.filepath)
            auto = self._auto_resolution()
            # as a fit's result is stored (compact), tessellated and its resolution chosen
            try:
                with np.errstate(over="ignore", invalid="ignore"):  # (said below: not finite)
                    surf = _as_stored(lambda: core.TCBSurface.load(path), self.resolution,
                                      auto, holes=False)()
            except core.FileFormatError as ex:
                if "not a TCB surface file" in str(ex):  # (which files are, in Blender's words)
                    ex.args = (f"{ex}: Import Spline reads the .npz files that Export Spline, "
                               "the command line's --spline and TCBSurface.save write",)
                raise
            label = os.path.basename(path)
            resolution = chosen_resolution(surf, self.resolution) if auto else self.resolution
            with np.errstate(over="ignore", invalid="ignore"):
                mesh = surf.tessellate(resolution)
            if not (np.isfinite(mesh[0]).all() and np.abs(mesh[0]).max(initial=0.0) < 1e30):
                raise core.FileFormatError(f"{path} is damaged: its spline's points are not "
                                           "finite")
            opts = surf.options
            settings = dict(
                tolerance=float(opts.tolerance), relative=bool(opts.relative),
                criterion=str(opts.criterion).upper(),
                max_control_points=min(int(opts.max_control_points), 2**31 - 1),
                max_iterations=min(int(opts.max_iterations), 2**31 - 1), degree=str(surf.degree),
                mode=str(surf.mode).upper(), auto_smoothness=opts.smoothness == "auto",
                smoothness=0.0 if opts.smoothness == "auto" else float(opts.smoothness),
                resolution=resolution, auto_resolution=auto,
            )  # fmt: skip
            edited = int(surf.report.get("edited", 0))
            sources, notes = _import_sources(context, surf, label)
        except (*_user_errors(), OSError) as ex:
            return _refused_file(self, ex)
        name = os.path.splitext(label)[0] or "Spline"
        coll = bridge.result_collection(context, f"TCB {name}")
        surface, net = _new_result(coll, name, surf, resolution, tessellation=mesh)
        surface[IMPORTED_KEY] = path  # (Fit Surface makes a new result beside it: not replaced)
        set_up_result(context, surface, net, surf, sources, settings, live_net=self.live_net,
                      show_net=self.show_net)
        if edited:
            notes.append(f"{edited} of its control points {'was' if edited == 1 else 'were'} "
                         "edited after the fit (Refine fits the data again and replaces them)")
        stray = resolution_note(surf) if auto else None
        rep = surf.report
        text = (f"TCB: imported '{label}' as '{surface.name}': {len(surf.control_points)} "
                f"control points, RMS {bridge.length_text(rep.get('rms', np.nan))}, max "
                f"{bridge.length_text(rep.get('max', np.nan))} of its fit, mesh Resolution "
                f"{resolution}, "
                f"{time.perf_counter() - started:.2f} s")
        warn = bool(stray) or not sources
        self.report({"WARNING"} if warn else {"INFO"},
                    text + "".join(f"; {n}" for n in notes + ([stray] if stray else [])))
        return {"FINISHED"}


# the formats of core.meshio.READ_EXTENSIONS (core is imported lazily: tests check they match)
POINT_EXTENSIONS = (".xyz", ".txt", ".csv", ".pts", ".npy", ".npz", ".asc", ".ply", ".obj",
                    ".off")


def _count(n: int, word: str) -> str:
    return f"{n} {word}{'s' * (n != 1)}"


class TCB_OT_import_points(bpy.types.Operator, ImportHelper):
    """Make a mesh object of a scan or DEM file that Blender cannot import (text columns .xyz
    .txt .csv .pts, NumPy .npy .npz, DEM rasters: .npz with 'elevation', ESRI ASCII grid
    .asc), ready for Fit Surface. Points far from the world origin (map coordinates: UTM,
    national grids) keep the file's precision: the object's Location is put near them and the
    vertices are stored relative to it, as Fit Surface places its results. Several files
    selected in the file browser or dropped on the 3D viewport make an object each"""

    # .obj, .ply and .off are read too (as meshes of their triangles; a PLY without faces as
    # points), though Blender imports .obj and .ply itself: its importers store the file's
    # coordinates as they are in 32-bit floats around the world origin (0.5 apart at 4.2e6,
    # UTM northings) and its OBJ importer turns the axes by default (Forward -Z, Up Y), while
    # this one keeps the file's axes and, far from the origin, its precision; .off Blender
    # does not read at all. (Blender's importers keep quads, UVs and normals: the reader gives
    # triangles.)
    bl_idname = "tcb.import_points"
    bl_label = "Import Points"
    bl_options = {"REGISTER", "UNDO"}
    filter_glob: StringProperty(default=";".join(f"*{e}" for e in POINT_EXTENSIONS),
                                options={"HIDDEN"})  # fmt: skip
    filepath: StringProperty(name="File Path", description="Filepath used for importing the "
                             "file", maxlen=1024, subtype="FILE_PATH",
                             options={"SKIP_PRESET", "HIDDEN", "PATH_SUPPORTS_BLEND_RELATIVE"})  # fmt: skip
    # the file browser's selection and a drop (TCB_FH_import_points); scripts give filepath
    files: CollectionProperty(type=bpy.types.OperatorFileListElement,
                              options={"HIDDEN", "SKIP_SAVE"})  # fmt: skip
    directory: StringProperty(subtype="DIR_PATH", options={"HIDDEN", "SKIP_SAVE"})
    drop_invalid: BoolProperty(
        name="Leave Out Invalid Points", default=True,
        description="Leave out points with NaN or infinite coordinates and a DEM's or point "
        "file's no-data fill values (-9999 ...) far below all others, with a warning (off: "
        "such a file is refused)",
    )  # fmt: skip

    @classmethod
    def poll(cls, context):
        return _poll_object_mode(cls, context, surface=False)

    def invoke(self, context, event):
        if self.directory and any(f.name for f in self.files):  # dropped: no file browser
            if context.window is None:  # (background mode)
                return self.execute(context)
            names = [f.name for f in self.files if f.name]
            folder = os.path.basename(os.path.normpath(self.directory))
            title = names[0] if len(names) == 1 else f"{len(names)} files in {folder}"
            return context.window_manager.invoke_props_dialog(
                self, title=f"Import Points: {title}", confirm_text="Import")
        return ImportHelper.invoke(self, context, event)  # the file browser

    def _paths(self) -> list[str]:
        """The files to import: those selected in the file browser or dropped (``directory``
        and ``files``), else ``filepath`` (scripts)."""
        names = [f.name for f in self.files if f.name]
        if self.directory and names:
            return [os.path.join(self.directory, name) for name in names]
        return [self.filepath]

    def execute(self, context):
        paths = self._paths()
        # the imported files' reports, given after the note on the views framed (the status
        # bar shows the last report: a file's warnings, not that note)
        self._pending = []
        if len(paths) == 1:
            obj = self._import_file(context, paths[0])
            if obj is None:
                return {"CANCELLED"}
            made, refused = [obj], []
        else:
            made, refused = [], []
            for path in paths:  # (each file read, checked and made before the next)
                obj = self._import_file(context, path, several=True)
                if obj is None:
                    refused.append(os.path.basename(path))
                else:
                    made.append(obj)
        if made:
            for other in context.selected_objects:
                other.select_set(False)
            for obj in made:  # (the last one active)
                try:
                    obj.select_set(True)
                    context.view_layer.objects.active = obj
                except RuntimeError:  # (not in the view layer: cannot be)
                    pass
            self._frame_views(context, made)
        for level, text in self._pending:
            self.report(level, text)
        if len(paths) > 1:
            names = ", ".join(obj.name for obj in made)
            if not refused:
                self.report({"INFO"}, f"Imported {len(made)} files as {names}")
            elif made:
                self.report({"WARNING"}, f"Imported {len(made)} of {len(paths)} files, as "
                            f"{names}; refused {', '.join(refused)} (the errors above say why)")
            else:
                self.report({"ERROR"}, f"None of the {len(paths)} files was imported (the "
                            "errors above say why)")
        return {"FINISHED"} if made else {"CANCELLED"}

    def _frame_views(self, context, made: list) -> None:
        """Frame the 3D views of the open windows that do not reach all of the new objects
        (map coordinates far from a view at the world origin, a tile wider than its Clip End:
        the user saw nothing; :func:`bridge.frame_views`), with one INFO note. None in
        background mode."""
        areas = [area for window in context.window_manager.windows
                 for area in window.screen.areas if area.type == "VIEW_3D"]
        pts = [bridge.read_world_positions(o) for o in made if o.type == "MESH"]
        pts = np.concatenate(pts) if pts else np.empty((0, 3))
        if not areas or not len(pts):
            return
        notes = bridge.frame_views([a.spaces.active for a in areas], pts.min(axis=0),
                                   pts.max(axis=0))
        if not notes:
            return
        for area in areas:
            area.tag_redraw()
        views, its = (("the 3D view", "its") if len(notes) == 1
                      else (f"{len(notes)} 3D views", "their"))
        names = ", ".join(f"'{o.name}'" for o in made)
        raised = "; ".join(dict.fromkeys(n for n in notes if n))
        self.report({"INFO"}, f"Framed {views} on {names}, out of {its} clip range"
                    + (f"; {raised}" if raised else ""))

    def _import_spline(self, context, path: str, label: str):
        """The surface Import Spline makes of a spline file given to Import Points (dropped
        with point files, or chosen among them: the same extension), or None when it refuses
        the file (the ERROR report says why)."""
        before = set(bpy.data.objects)
        try:
            bpy.ops.tcb.import_spline(filepath=path)
        except RuntimeError as ex:  # (its ERROR report, raised here)
            text = str(ex).strip().removeprefix("Error:").strip()
            self.report({"ERROR"}, text if label in text else f"{label}: {text}")
            return None
        made = [o for o in bpy.data.objects if o not in before and o.tcb.role == "SURFACE"]
        return made[0] if made else None

    def _import_file(self, context, filepath: str, several: bool = False):
        """The new object of one file, or None when the file is refused (an ERROR report says
        why, prefixed with the file's name with ``several`` when it is not in it; nothing is
        left made)."""
        core = _core()
        from ..core.meshio import is_dem, read_geometry
        from ..core.parameterize import fill_value_rows, fill_value_words

        notes = []
        # everything that reads the file is done before anything is made (as Import Spline)
        try:
            if not filepath or filepath.endswith(("/", "\\")):
                raise bridge.SelectionError("No file chosen: choose a point file ("
                                            f"{' '.join(POINT_EXTENSIONS)})")
            path = _file_path(filepath)
            label = os.path.basename(path)
            with _warnings.catch_warnings(record=True) as caught:
                _warnings.simplefilter("always")
                # (a DEM's fill values come back as points: left out below, or refused)
                try:
                    points, faces = read_geometry(path, keep_fill_values=True)
                except core.FileFormatError as ex:
                    if "'control_points'" in str(ex) and "'knots'" in str(ex):
                        # a TCB spline (Export Spline's .npz), dropped or chosen here: the
                        # surface and net Import Spline makes of it
                        return self._import_spline(context, path, label)
                    raise
            notes += [str(w.message) for w in caught
                      if issubclass(w.category, (RuntimeWarning, UserWarning))]
            bad = ~np.isfinite(points).all(axis=1)
            if faces is not None:
                if bad.any():  # (the faces hold them: they cannot be left out)
                    raise core.FileFormatError(
                        f"{int(bad.sum())} of the {len(points)} vertices of {label} have NaN or "
                        "infinite coordinates; repair them in a mesh editor and import again")
            else:
                fill = fill_value_rows(points)
                what = fill_value_words(fill, len(points)) if fill is not None else None
                if fill is not None:
                    bad |= fill[0]
                if bad.any() and not self.drop_invalid:
                    k = int(bad.sum())
                    words = what or (f"{k} of the {len(points)} points "
                                     f"{'has' if k == 1 else 'have'} NaN or infinite "
                                     "coordinates")
                    raise core.FileFormatError(f"{label}: {words}; turn on Leave Out Invalid "
                                               "Points to leave them out")
                if bad.any():
                    nonfinite = int((~np.isfinite(points).all(axis=1)).sum())
                    if nonfinite:
                        notes.append(f"left out {_count(nonfinite, 'point')} with NaN or "
                                     "infinite coordinates")
                    if fill is not None:
                        notes.append(f"left out {_count(int(fill[0].sum()), 'point')} with "
                                     f"{'xyz'[fill[1]]} = {fill[2]:g} (a no-data fill value)")
                    points = points[~bad]
            if not len(points):
                raise core.FileFormatError(f"{label} holds no points" + (
                    " with finite coordinates" if bad.any() else ""))
            origin = bridge.local_origin(points)  # (0, 0, 0) unless far from the world origin
            local = points - origin
            with np.errstate(over="ignore"):
                if not np.isfinite(local.astype(np.float32)).all():
                    raise core.FileFormatError(
                        f"{label}: coordinates too large for Blender's 32-bit floats (largest "
                        f"{np.abs(points).max():.3g})")
        except (*_user_errors(), OSError) as ex:
            text = _refusal_text(ex, filepath)
            label = os.path.basename(filepath)
            if several and not text.startswith(label) and f"'{label}'" not in text:
                text = f"{label}: {text}"
            self.report({"ERROR"}, text)
            return None
        raster = faces is None and is_dem(path, points)
        name = os.path.splitext(label)[0] or "Points"
        layer = context.view_layer.active_layer_collection
        coll = (layer.collection if layer is not None and not layer.exclude
                else context.scene.collection)
        mesh = bridge.new_mesh(name, local, faces)
        try:
            obj = bridge.link_new_object(coll, name, mesh, origin)
        except RuntimeError as ex:  # (a collection linked from a library: read-only; review)
            for made in [o for o in bpy.data.objects if o.data == mesh]:
                bpy.data.objects.remove(made)
            bpy.data.meshes.remove(mesh)
            self.report({"ERROR"}, f"Cannot add '{name}' to the collection {coll.name!r} ({ex}); "
                        "make another collection active and import again")
            return None
        if raster:
            obj[RASTER_KEY] = True
        hidden = bridge.hiding_collections(context.view_layer, obj)
        if hidden:
            notes.append(f"'{obj.name}' is hidden: its collection {hidden[0]!r} is hidden in the "
                         "outliner (show it to see the points)")
        text = f"Imported {len(points)} points from {label}"
        if faces is not None:
            text += f" ({len(faces)} triangles)"
        if np.any(origin != 0):
            text += (f"; far from the world origin: '{obj.name}' is at "
                     f"({', '.join(f'{c:.10g}' for c in origin)}), its vertices relative to it "
                     "(32-bit floats keep the file's precision; View > Frame Selected shows "
                     "it)")
        if raster:
            text += ("; a DEM raster: Fit Surface fits it along its z, as heights over its x and "
                     "y (the Projection setting chooses another)")
        self._pending.append(({"INFO"}, text))
        for note in notes:  # (after the summary: the status bar shows the last report)
            self._pending.append(
                ({"WARNING"}, f"{label}: {note}" if not note.startswith(label) else note))
        return obj


def menu_import(self, context):
    """File > Import > TCB Spline (.npz) and TCB Points (.xyz .csv .asc ...)."""
    self.layout.operator(TCB_OT_import_spline.bl_idname, text="TCB Spline (.npz)")
    self.layout.operator(TCB_OT_import_points.bl_idname, text="TCB Points (.xyz .csv .asc ...)")


# the formats a drop from the file manager onto the 3D viewport imports: not .obj and .ply
# (Blender's own importers take those, as users expect; File > Import > TCB Points reads them).
# A .npz is points, a DEM, or a spline (Export Spline's format): Import Points hands a spline
# to Import Spline (a file handler is chosen by the extension alone; a second one for .npz
# would make Blender ask which, each drop)
DROP_EXTENSIONS = tuple(e for e in POINT_EXTENSIONS if e not in (".obj", ".ply"))


class TCB_FH_import_points(bpy.types.FileHandler):
    """Point files dropped from the file manager onto the 3D viewport: Import Points, an object
    each (after a dialog with its options)"""

    bl_idname = "TCB_FH_import_points"
    bl_label = "TCB Points"
    bl_import_operator = "tcb.import_points"
    bl_file_extensions = ";".join(DROP_EXTENSIONS)

    @classmethod
    def poll_drop(cls, context):
        # (in Object Mode, where Import Points runs: elsewhere the drop is refused visibly)
        return (context.area is not None and context.area.type == "VIEW_3D"
                and context.mode == "OBJECT")


classes = (
    TCB_OT_fit_surface,
    TCB_OT_refine,
    TCB_OT_retessellate,
    TCB_OT_deviation_map,
    TCB_OT_toggle_net,
    TCB_OT_export_spline,
    TCB_OT_import_spline,
    TCB_OT_import_points,
    TCB_FH_import_points,
)
