"""Properties: the fit settings (shared by the panel and the operators) and per-object result data.

``FitSettings`` is a mixin of annotations used twice: by :class:`TCB_PG_settings` (the panel's
values, stored on the scene) and by the Fit operator, so every tunable is an operator property
(*Adjust Last Operation* works) and the panel passes its values to the button.

A fitted surface object carries ``object.tcb`` (:class:`TCB_PG_object`): its role, the source
objects, the net/surface partner, the statistics of the last fit and the settings it used. The
spline itself is stored as bytes in the custom property ``object["tcb_spline"]`` (see
``operators.SPLINE_KEY``), so Refine and re-tessellation work after saving and reopening.
"""

import struct

import bpy
from bpy.props import (
    BoolProperty,
    CollectionProperty,
    EnumProperty,
    FloatProperty,
    IntProperty,
    PointerProperty,
    StringProperty,
)

# the Smoothness default as Blender stores it (a 32-bit float): a property at this value and
# never set (FitSettings.smoothness_set) was left at the default, which the engine
# cross-validates on sparse clouds
DEFAULT_SMOOTHNESS = struct.unpack("f", struct.pack("f", 1e-4))[0]


def _smoothness_set(self, _context) -> None:
    """The Smoothness field's update: it was set (FitSettings.smoothness_set). Blender calls it
    for a value typed in, set by a script (also an operator's keyword argument) or copied by
    the panel's button, the same value too."""
    self.smoothness_set = True


# the finest tessellation offered (Fit's and Re-tessellate's Resolution)
MAX_RESOLUTION = 2048
# the smallest budget of control points (the engine's RefineOptions)
MIN_BUDGET = 10
# The numeric settings have soft limits only (the sliders' range): a hard limit made Blender
# clamp a value beyond it without a word (a script's tolerance of -0.01 became 1e-9 and ran to
# the budget; a Resolution of 100000 became 2048, a minute's tessellation; user test), and the
# operators refuse such values instead (operators.check_settings).


class FitSettings:
    """The tunables of a fit (annotations only; mixed into a PropertyGroup and an Operator)."""

    tolerance: FloatProperty(
        name="Tolerance",
        description=(
            "Allowed distance from the input points to the surface, as the Criterion measures "
            "it (RMS, the default: their root-mean-square distance; Max: the largest): "
            "relative to the bounding-box diagonal of the input, or a distance in Blender "
            "units, the unit of the objects' coordinates before the scene's Unit Scale (see "
            "Relative); 0: refine until Max Control Points or Max Iterations"
        ),
        default=1e-3, soft_min=1e-6, soft_max=0.1, precision=6, step=0.01,
    )  # fmt: skip
    relative: BoolProperty(
        name="Relative",
        description="Tolerance is a fraction of the input's bounding-box diagonal, not a distance",
        default=True,
    )
    criterion: EnumProperty(
        name="Criterion",
        description="Which error the tolerance bounds",
        items=(("RMS", "RMS", "Root-mean-square distance of the input points"),
               ("MAX", "Max", "Largest distance of an input point")),
        default="RMS",
    )  # fmt: skip
    max_control_points: IntProperty(
        name="Max Control Points",
        description="Stop refining when the spline would have more control points than this",
        default=2000, soft_min=MIN_BUDGET, soft_max=20000,
    )  # fmt: skip
    max_iterations: IntProperty(
        name="Max Iterations",
        description="Largest number of fits (the first ones of a fit with a tolerance size "
        "the control net to it)",
        default=20, soft_min=1, soft_max=100,
    )  # fmt: skip
    degree: EnumProperty(
        name="Degree",
        description="Polynomial degree of the spline",
        items=(("2", "Quadratic", "Degree 2 (C1 smooth)"),
               ("3", "Cubic", "Degree 3 (C2 smooth): more accurate on smooth surfaces for the "
                "same number of control points, a little slower")),
        default="2",
    )
    mode: EnumProperty(
        name="Mode",
        description="Spline space built on the knots",
        items=(
            ("TCB", "TCB", "Triangle configuration B-splines"),
            ("DCB", "DCB", "Delaunay configuration B-splines"),
        ),
        default="TCB",
    )
    smoothness: FloatProperty(
        name="Smoothness",
        description="Weight of the smoothing term of the least-squares fit (0 = none); used "
        "when Auto Smoothness is off. Left at its default (0.0001, never set) on a sparse "
        "cloud (under 2 points per control point), or when the error stopped falling above "
        "the tolerance, it is chosen by cross-validation; a value set, 0.0001 too, is used as "
        "it is",
        default=DEFAULT_SMOOTHNESS, soft_min=0.0, soft_max=1.0, precision=6, step=0.001,
        update=_smoothness_set,
    )  # fmt: skip
    # the Smoothness was set (typed, by a script, or copied by the panel from a field that was):
    # its value is the user's even when it is the default's (it had been cross-validated on a
    # sparse cloud as the default is, with no way to ask for 0.0001 itself)
    # (drawn as a pin beside the field when it holds at the default's value, so that a value
    # reset to the default, which sets it too, can be given back to the engine: review)
    smoothness_set: BoolProperty(
        name="Smoothness Given",
        description="Use the Smoothness 0.0001 as it is (it was typed, reset or set by a "
        "script); off: the default, chosen by cross-validation on sparse or thin data or when "
        "the error stopped falling above the tolerance",
        default=False, options={"HIDDEN"},
    )  # fmt: skip
    auto_smoothness: BoolProperty(
        name="Auto Smoothness",
        description=(
            "Choose the smoothing weight by cross-validation: the one that best predicts points "
            "left out of the fit (slower; more accurate on dense scans of smooth shapes, "
            "smoother on meshes)"
        ),
        default=False,
    )  # fmt: skip
    drop_outliers: BoolProperty(
        name="Drop Outliers",
        description=(
            "Leave out points far from all others (stray scan returns) instead of stopping "
            "with an error that names them, and spikes and pits inside the cloud; on a mesh, "
            "dissolve its spike vertices (a vertex raised far out of its neighbours' surface)"
        ),
        default=False,
    )  # fmt: skip
    fill_holes: BoolProperty(
        name="Fill Holes",
        description=(
            "Meshes with holes (borders inside the outer one, as a scan's gaps): let the "
            "surface span them, held smooth, instead of stopping with an error. Point clouds: "
            "cover the gaps inside the cloud (occlusions, dropouts), which the surface mesh "
            "otherwise leaves open"
        ),
        default=False,
    )  # fmt: skip
    projection: EnumProperty(
        name="Projection",
        description=(
            "Direction a point cloud is projected along (a height field over the plane across "
            "it): chosen from the data, or a world axis. Still checked for folds; a cloud too "
            "noisy for that check is fitted only along a given axis (not used for meshes, "
            "which are mapped through their faces)"
        ),
        items=(("AUTO", "Auto", "The best-fit plane, or a direction the cloud is less steep "
                "over; a DEM raster imported with Import Points: along its z"),
               ("X", "World X", "Project along the world X axis"),
               ("Y", "World Y", "Project along the world Y axis"),
               ("Z", "World Z", "Project along the world Z axis (terrain, height maps)")),
        default="AUTO",
    )  # fmt: skip
    resolution: IntProperty(
        name="Resolution",
        description=(
            "Subdivisions of the output surface mesh along the longer side of the domain (at "
            "least 8 across the shorter one; a long or ragged domain, filling under half the "
            "square on its longer side, gets as many grid cells as a half-filled square; finer "
            "where steep parts are crowded). 1024 gives about 0.8 million vertices in 10-20 s, "
            "2048 about 3 million in about 40 s (Re-tessellate shows its progress; "
            "Esc cancels)"
        ),
        # (4096: 12 million vertices, about 4 minutes and 7 GiB with Blender waiting: user test)
        default=64, soft_min=2, soft_max=512,
    )  # fmt: skip
    auto_resolution: BoolProperty(
        name="Auto Resolution",
        description=(
            "Choose the Resolution of the surface mesh: the coarsest of 64, 128 and 256 whose "
            "flat triangles stay within the fit's max error of the spline, else 256 with a "
            "warning (a tight fit needs a fine mesh: at 64 one fitted to 0.01% strayed 9 times "
            "its error). Off: the Resolution given. A script that gives a Resolution (and not "
            "this) gets it"
        ),
        default=True,
    )  # fmt: skip


FIT_KEYS = (
    "tolerance", "relative", "criterion", "max_control_points", "max_iterations", "degree", "mode",
    "smoothness", "auto_smoothness", "drop_outliers", "fill_holes", "projection", "resolution",
    "auto_resolution",
    "smoothness_set",  # (after "smoothness": copying that one sets it; the panel copies in order)
)  # fmt: skip


class ResultSettings:
    """What a fit makes of its result (annotations only; mixed into the sidebar's settings
    and the fit operator, which the panel's button copies them to)."""

    show_net: BoolProperty(name="Show Net", default=True)
    live_net: BoolProperty(
        name="Live Net",
        description="Moving control-net vertices updates the surface (Geometry Nodes modifier)",
        default=True,
    )
    # Fit Surface run again on the same source updates its result in place (user test: every
    # run added a surface, a net and a collection, each with its stored spline, to the file)
    replace: BoolProperty(
        name="Replace Previous Result",
        description=(
            "Fit into the existing TCB result of the same source objects: its surface, net and "
            "collection are updated in place (materials and the object's own modifiers stay; "
            "Ctrl+Z brings the old result back). Off: add a new result beside it"
        ),
        default=True,
    )  # fmt: skip
    # patches of one mesh fitted one at a time had left gaps of 2-3 times the tolerance
    # between their surfaces (core.join)
    join_neighbours: BoolProperty(
        name="Join Neighbours",
        description=(
            "Edit Mode: join the surface of the selected faces to the surfaces already fitted "
            "to the mesh's neighbouring patches, along the border they share (the patches "
            "then meet to a share of the tolerance; knots are added along that border where "
            "needed; the neighbours are not changed). Point clouds fitted along a given "
            "direction (DEM tiles along their z, a World axis): join to the surfaces of the "
            "tiles fitted before that reach this one's border. Off: fit on their own"
        ),
        default=True,
    )  # fmt: skip


RESULT_KEYS = ("show_net", "live_net", "replace", "join_neighbours")


class TCB_PG_settings(FitSettings, ResultSettings, bpy.types.PropertyGroup):
    """Fit settings shown in the sidebar (``scene.tcb_settings``)."""


class TCB_PG_source(bpy.types.PropertyGroup):
    object: PointerProperty(type=bpy.types.Object, name="Source")


class TCB_PG_object(bpy.types.PropertyGroup):
    """Result data of a TCB surface / net object (``object.tcb``)."""

    role: EnumProperty(
        items=(("NONE", "None", ""), ("SURFACE", "Surface", ""), ("NET", "Control Net", ""),
               ("DEVIATION", "Deviation Points", ""), ("WEIGHTS", "Live-Net Weights", "")),
        default="NONE",
    )  # fmt: skip
    sources: CollectionProperty(type=TCB_PG_source)
    surface: PointerProperty(type=bpy.types.Object, name="Surface")
    net: PointerProperty(type=bpy.types.Object, name="Control Net")
    deviation_points: PointerProperty(type=bpy.types.Object, name="Deviation Points")
    weights: PointerProperty(type=bpy.types.Object, name="Live-Net Weights")

    # statistics of the last fit / refine
    knots: IntProperty(name="Knots")
    control_points: IntProperty(name="Control Points")
    iterations: IntProperty(name="Iterations")
    rms: FloatProperty(name="RMS", precision=6)
    max: FloatProperty(name="Max", precision=6)
    rms_rel: FloatProperty(name="RMS (relative)", precision=6)
    max_rel: FloatProperty(name="Max (relative)", precision=6)
    # a point cloud's RMS over its area (core.refine.area_weights; 0 for a mesh)
    rms_area: FloatProperty(name="RMS over area", precision=6)
    seconds: FloatProperty(name="Seconds", precision=2)
    stop_reason: StringProperty(name="Stopped")  # why the adaptive loop stopped
    holes_filled: IntProperty(name="Holes Spanned")  # holes the surface spans (Fill Holes)
    # the share of a mesh's area where the surface folds over it (core.surface.mesh_folds)
    folded: FloatProperty(name="Folded Over", precision=6)
    # the data's scatter across a smooth surface (core.parameterize.local_noise; 0: not
    # measured, as for a cloud that met its tolerance), and over the diagonal
    noise: FloatProperty(name="Noise", precision=6)
    noise_rel: FloatProperty(name="Noise (relative)", precision=6)
    # a patch joined to its neighbours (core.join): the shared border edges (0: not joined)
    # and the largest gap left between the borders, over the diagonal
    joined_edges: IntProperty(name="Joined Edges")
    join_gap_rel: FloatProperty(name="Joined Gap (relative)", precision=6)
    # settings of the last fit / refine
    tolerance: FloatProperty(precision=6)
    relative: BoolProperty()
    criterion: StringProperty()
    max_control_points: IntProperty()
    max_iterations: IntProperty()
    degree: StringProperty()
    mode: StringProperty()
    smoothness: FloatProperty(precision=6)  # the value used (the chosen one with auto)
    auto_smoothness: BoolProperty()
    # the value used was cross-validated although Auto Smoothness was off (sparse cloud, stall)
    smoothness_cross_validated: BoolProperty()
    smoothness_smoother: BoolProperty()
    resolution: IntProperty()
    auto_resolution: BoolProperty()  # (Refine chooses the resolution again)
    # deviation map (distance of the surface vertices to the data)
    has_deviation: BoolProperty()
    deviation_max: FloatProperty(precision=6)  # top of the color range
    deviation_rms: FloatProperty(precision=6)  # of the fitted data points' distances
    deviation_data_max: FloatProperty(precision=6)  # the largest of those distances
    deviation_rms_rel: FloatProperty(precision=6)  # both over the data's diagonal
    deviation_data_max_rel: FloatProperty(precision=6)
    # a mesh's: the largest distance of the surface's vertices to the mesh (where it has
    # faces), which sees what the data-to-surface one cannot: a rim that dips past the mesh's
    # border (a hemisphere's, 0.045 against 0.020: user test); 0 for clouds
    deviation_surface_max: FloatProperty(precision=6)


classes = (TCB_PG_settings, TCB_PG_source, TCB_PG_object)


def register_props():
    bpy.types.Scene.tcb_settings = PointerProperty(type=TCB_PG_settings)
    bpy.types.Object.tcb = PointerProperty(type=TCB_PG_object)


def unregister_props():
    del bpy.types.Object.tcb
    del bpy.types.Scene.tcb_settings


def draw_fit_settings(layout, owner, short_labels: bool = False) -> None:
    """Draw the fit settings of ``owner`` (the fit operator or the scene's settings): one
    layout for the operator's redo panel and the sidebar."""
    layout.use_property_split = True
    layout.use_property_decorate = False
    col = layout.column()
    row = col.row(align=True)
    row.prop(owner, "tolerance")
    row.prop(owner, "relative", text="", icon="DRIVER_DISTANCE")
    if not owner.relative:  # a distance in Blender units: said as the scene shows lengths
        from .bridge import length_text  # (user test: a mm scene read it as millimetres)

        shown = length_text(owner.tolerance)
        if shown != f"{owner.tolerance:.4g}":
            col.label(text=f"Tolerance {shown} in the scene's units", icon="INFO")
    for key in ("criterion", "max_control_points", "max_iterations", "degree", "mode",
                "smoothness", "drop_outliers", "fill_holes", "projection", "resolution",
                *RESULT_KEYS):
        if short_labels and key == "max_control_points":
            col.prop(owner, key, text="Max Control Pts")
        elif key in ("smoothness", "resolution"):
            row = col.row(align=True)
            sub = row.row(align=True)
            sub.active = not getattr(owner, f"auto_{key}")
            sub.prop(owner, key)
            if (key == "smoothness" and owner.smoothness_set and not owner.auto_smoothness
                    and owner.smoothness == DEFAULT_SMOOTHNESS):
                row.prop(owner, "smoothness_set", text="", icon="PINNED")
            row.prop(owner, f"auto_{key}", text="", icon="AUTO")
        else:
            col.prop(owner, key)
