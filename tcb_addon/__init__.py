"""Blender side of TCB Surface: properties, operators, panels and the bpy <-> numpy bridge.

Thin by design: all mathematics lives in ``core``. For now (spline-space milestone) it registers
nothing; the operators and panels arrive with the Blender-extension issue.
"""

_classes: tuple = ()


def register():
    import bpy

    for cls in _classes:
        bpy.utils.register_class(cls)


def unregister():
    import bpy

    for cls in reversed(_classes):
        bpy.utils.unregister_class(cls)
