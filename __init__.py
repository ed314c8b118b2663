"""TCB Surface: a Blender extension (the repository root is the extension package).

No module-level ``import bpy``: the numerical engine in ``core/`` must import without Blender,
and Blender-only code lives in ``tcb_addon/``, imported lazily by :func:`register`.
"""


def register():
    from . import tcb_addon

    tcb_addon.register()


def unregister():
    from . import tcb_addon

    tcb_addon.unregister()
