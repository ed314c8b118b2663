"""Sidebar panels: View3D > Sidebar > TCB.

They only read properties and place operator buttons; they must draw without errors whatever is
selected (nothing, a camera, a result object, ...).
"""

import bpy

from . import bridge
from .operators import (NO_DATA_KEY, SPLINE_KEY, converted_problem, folded_over, is_max,
                        live_link_problem, live_moved_problem, net_copy_note,
                        net_modifier_problem, net_shape_key_problem, net_vertex_problem,
                        result_objects, source_words, stack_problem, uneven_density)
from .properties import FIT_KEYS, RESULT_KEYS, draw_fit_settings


class _TCBPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "TCB"


class TCB_PT_fit(_TCBPanel, bpy.types.Panel):
    bl_label = "TCB Surface"
    bl_idname = "TCB_PT_fit"

    def draw(self, context):
        layout = self.layout
        settings = getattr(context.scene, "tcb_settings", None)
        if settings is None:
            layout.label(text="TCB settings are not registered", icon="ERROR")
            return
        draw_fit_settings(layout, settings, short_labels=True)

        problem = bridge.selection_problem(context)
        row = layout.row()
        row.scale_y = 1.4
        row.enabled = problem is None
        op = row.operator("tcb.fit_surface", icon="MOD_SMOOTH")
        for key in FIT_KEYS + RESULT_KEYS:
            setattr(op, key, getattr(settings, key))
        if problem:
            layout.label(text=problem, icon="INFO")
        elif context.mode == "EDIT_MESH":
            layout.label(text="Fits the selected faces (or vertices)", icon="INFO")
        # a spline saved by Export Spline, the command line or a script, as a result
        layout.operator("tcb.import_spline", icon="IMPORT")


class TCB_PT_result(_TCBPanel, bpy.types.Panel):
    bl_label = "Result"
    bl_idname = "TCB_PT_result"
    bl_parent_id = "TCB_PT_fit"

    @classmethod
    def poll(cls, context):
        obj = getattr(context, "active_object", None)
        return obj is not None and hasattr(obj, "tcb") and result_objects(obj)[0] is not None

    def draw(self, context):
        layout = self.layout
        surface, net = result_objects(context.active_object)
        st = surface.tcb

        def length(x):  # (as the scene shows lengths: user test)
            return bridge.length_text(x, context.scene)
        col = layout.column(align=True)
        col.label(text=surface.name, icon="SURFACE_NSURFACE")
        source = source_words(surface)
        if source:
            col.label(text=source, icon="INFO")
        grid = col.grid_flow(columns=2, even_columns=True, align=True)
        for label, value in (
            ("Knots", f"{st.knots}"),
            ("Control Points", f"{st.control_points}"),
            ("Iterations", f"{st.iterations}"),
            ("RMS", length(st.rms)),
            *((("RMS over Area", length(st.rms_area)),) if uneven_density(st.rms, st.rms_area)
              else ()),
            ("Max", length(st.max)),
            ("RMS (of diagonal)", f"{100 * st.rms_rel:.3g} %"),
            ("Max (of diagonal)", f"{100 * st.max_rel:.3g} %"),
            ("Tolerance (" + ("max" if is_max(st) else "RMS") + ")",
             f"{100 * st.tolerance:.3g} %" if st.relative else length(st.tolerance)),
            ("Smoothness" + (" (auto)" if st.auto_smoothness else
                             " (cross-validated)" if st.smoothness_cross_validated else
                             " (default swung)" if st.smoothness_smoother else ""),
             f"{st.smoothness:.3g}"),
            *((("Holes Spanned", f"{st.holes_filled}"),) if st.holes_filled else ()),
            *((("Folded Over", f"{100 * st.folded:.2g} %"),) if folded_over(st) else ()),
            # a patch joined to its neighbours: how far apart the borders are left
            *((("Joined Gap (of diagonal)", f"{100 * st.join_gap_rel:.2g} %"),)
              if st.joined_edges else ()),
            # the scan's noise, measured, which a tolerance below it would have the net follow
            # (user test: the summary said it, the panel did not)
            *((("Noise (of diagonal)", f"{100 * st.noise_rel:.3g} %"),) if st.noise > 0
              else ()),
            # the engine's time (the summary's is the operator's, with reading and the objects
            # made: 0.40 s there, 0.25 here; user test)
            ("Engine Seconds", f"{st.seconds:.2f}"),
        ):
            grid.label(text=label)
            grid.label(text=value)
        if st.stop_reason:
            col.label(text=f"Stopped: {st.stop_reason}")
        if SPLINE_KEY not in surface:
            col.label(text="No spline stored: refit from the source", icon="ERROR")
        for problem in (converted_problem(surface), net_vertex_problem(surface),
                        live_link_problem(surface), net_modifier_problem(surface),
                        net_shape_key_problem(surface), stack_problem(surface)):
            if problem:
                col.label(text=problem[0].upper() + problem[1:], icon="ERROR")
        copy = net_copy_note(context.active_object)
        if copy:
            col.label(text=copy, icon="INFO")
        moved = live_moved_problem(surface)
        if moved:
            col.label(text=moved[0].upper() + moved[1:], icon="INFO")

        layout.separator()
        row = layout.row(align=True)
        row.operator("tcb.refine", icon="MOD_MULTIRES")
        row.operator("tcb.retessellate", text="", icon="FILE_REFRESH")
        if net is not None:
            hidden = net.name in context.view_layer.objects and not net.visible_get()
            layout.operator("tcb.toggle_net", text="Show Net" if hidden else "Hide Net",
                            icon="HIDE_ON" if hidden else "HIDE_OFF")  # fmt: skip
        layout.operator("tcb.deviation_map", icon="MOD_VERTEX_WEIGHT")
        if st.has_deviation:
            box = layout.box()
            # a map made before these statistics had their own properties: the color range
            top = st.deviation_data_max or st.deviation_max
            box.label(text=f"Data to surface: RMS {length(st.deviation_rms)}, max {length(top)}")
            if st.deviation_data_max_rel > 0:
                box.label(text=f"({100 * st.deviation_rms_rel:.3g} %, "
                               f"{100 * st.deviation_data_max_rel:.3g} % of the diagonal)")
            if st.deviation_surface_max > 0:  # (a mesh: the colours' top is the larger)
                box.label(text=f"Surface to mesh: max {length(st.deviation_surface_max)}")
            n = len(bridge.RAMP_STOPS)
            for i in reversed(range(n)):
                lo = st.deviation_max * bridge.RAMP_STOPS[i]
                box.label(text=length(lo) + (" (max)" if i == n - 1 else ""),
                          icon=legend_icon(bridge.LEGEND_ICONS[i]))  # fmt: skip
            # a cloud's surface vertices far from all data, a mesh's over its filled holes
            if surface.get(NO_DATA_KEY, 0):
                box.label(text="no data nearby", icon=legend_icon("SEQUENCE_COLOR_09"))
        layout.operator("tcb.export_spline", icon="EXPORT")


def legend_icon(name: str) -> str:
    """``name`` if this Blender has that icon, else its newer name: the SEQUENCE_COLOR_* icons
    of Blender 4.2 are STRIP_COLOR_* in 5.0 (an unknown icon makes the panel fail to draw)."""
    icons = bpy.types.UILayout.bl_rna.functions["label"].parameters["icon"].enum_items
    if name in icons:
        return name
    new = name.replace("SEQUENCE_COLOR_", "STRIP_COLOR_")
    return new if new in icons else "NONE"


classes = (TCB_PT_fit, TCB_PT_result)
