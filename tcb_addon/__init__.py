"""Blender side of TCB Surface: properties, operators, panels and the bpy <-> numpy bridge.

Thin by design: all mathematics lives in ``core`` (imported lazily by the operators, as the
extension's own subpackage). Modules:

- ``bridge``: read the selection into numpy arrays, write meshes and attributes;
- ``properties``: fit settings (scene) and result data (``object.tcb``);
- ``operators``: ``bpy.ops.tcb.*`` (fit, refine, re-tessellate, deviation map, net, export,
  import; File > Import > TCB Spline and TCB Points, and point files dropped on the 3D
  viewport);
- ``ui``: the View3D > Sidebar > TCB panels.
"""


def _classes():
    from . import operators, properties, ui

    return (*properties.classes, *operators.classes, *ui.classes)


def register():
    import bpy

    from . import live, operators, properties

    for cls in _classes():
        bpy.utils.register_class(cls)
    properties.register_props()
    bpy.types.TOPBAR_MT_file_import.append(operators.menu_import)
    if live.on_load not in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.append(live.on_load)
    if live.on_save not in bpy.app.handlers.save_pre:
        bpy.app.handlers.save_pre.append(live.on_save)
    # enabled with a file open: its groups are brought up to date once the data is accessible
    bpy.app.timers.register(_upgrade_open_file, first_interval=0.0)


def _upgrade_open_file():
    from . import live

    live.upgrade_groups()
    return None  # once


def unregister():
    import bpy

    from . import live, operators, properties

    if live.on_load in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(live.on_load)
    if live.on_save in bpy.app.handlers.save_pre:
        bpy.app.handlers.save_pre.remove(live.on_save)
    if bpy.app.timers.is_registered(_upgrade_open_file):
        bpy.app.timers.unregister(_upgrade_open_file)
    operators.clear_cache()
    bpy.types.TOPBAR_MT_file_import.remove(operators.menu_import)
    properties.unregister_props()
    for cls in reversed(_classes()):
        bpy.utils.unregister_class(cls)
