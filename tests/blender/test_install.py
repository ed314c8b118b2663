"""The extension as a user gets it: Blender's validator accepts it, it installs from the zip,
enables, registers its operators and panels, and unregisters cleanly."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ADDON = "bl_ext.user_default.tcb_surface"


def blender_ext(bpy) -> list[str]:
    scripts = Path(bpy.utils.resource_path("LOCAL")) / "scripts"
    cli = scripts / "addons_core" / "bl_pkg" / "cli" / "blender_ext.py"
    tags = scripts / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    assert cli.exists(), cli
    return [sys.executable, str(cli)], ["--valid-tags", str(tags)]


@pytest.mark.parametrize("target", ["manifest", "zip"])
def test_blender_validator_accepts_manifest_and_zip(bpy_module, extension_zip, target):
    cmd, tags = blender_ext(bpy_module)
    path = ROOT if target == "manifest" else extension_zip
    proc = subprocess.run(
        [*cmd, "validate", *tags, str(path)], capture_output=True, text=True, check=False
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Success parsing TOML" in proc.stdout


def test_zip_contents_exclude_dev_files_and_numpy(extension_zip):
    names = zipfile.ZipFile(extension_zip).namelist()
    assert "__init__.py" in names and "blender_manifest.toml" in names
    assert any(n.startswith("core/") for n in names)
    assert any(n.startswith("tcb_addon/") for n in names)
    tops = {n.split("/")[0] for n in names}
    assert not tops & {"tests", "scripts", "benchmarks", "data", ".git", ".venv", "dist"}, tops
    wheels = [n for n in names if n.startswith("wheels/")]
    assert wheels and all("scipy-" in w and "manylinux" in w for w in wheels), wheels
    assert {w.split("-")[2] for w in wheels} == {"cp311", "cp313"}
    assert not any("numpy" in n for n in names)
    assert not any("__pycache__" in n for n in names)


def test_install_enables_the_extension_and_its_scipy_wheel(installed, blender_user_dir):
    bpy = installed
    assert ADDON in bpy.context.preferences.addons
    pkg_dir = Path(bpy.utils.user_resource("EXTENSIONS")) / "user_default" / "tcb_surface"
    assert (pkg_dir / "blender_manifest.toml").exists()
    assert pkg_dir.is_relative_to(blender_user_dir)
    mod = sys.modules[ADDON]
    assert Path(mod.__file__).parent == pkg_dir
    # Blender unpacked the wheel of its own Python (3.11), not the cp313 one
    site = (
        Path(bpy.utils.user_resource("EXTENSIONS"))
        / ".local"
        / "lib"
        / "python3.11"
        / "site-packages"
    )
    infos = list(site.glob("scipy-*.dist-info"))
    assert len(infos) == 1, infos
    assert "cp311" in (infos[0] / "WHEEL").read_text()


def test_engine_imports_inside_the_extension(addon):
    import importlib

    core = importlib.import_module(ADDON + ".core")
    assert core.__name__ == ADDON + ".core"
    assert issubclass(core.TCBError, Exception)


def test_operators_and_panels_registered(installed):
    bpy = installed
    for op in (
        "fit_surface",
        "refine",
        "retessellate",
        "deviation_map",
        "toggle_net",
        "export_spline",
        "import_spline",
    ):
        assert hasattr(bpy.ops.tcb, op), op
        assert getattr(bpy.ops.tcb, op).get_rna_type().identifier.startswith("TCB_OT_")
    fit = bpy.ops.tcb.fit_surface.get_rna_type()
    assert {"REGISTER", "UNDO"} <= set(bpy.types.TCB_OT_fit_surface.bl_options)
    for key in ("tolerance", "relative", "max_control_points", "max_iterations", "degree", "mode",
                "smoothness", "auto_smoothness", "resolution"):  # fmt: skip
        assert key in fit.properties.keys(), key
    for panel in ("TCB_PT_fit", "TCB_PT_result"):
        cls = getattr(bpy.types, panel)
        assert cls.bl_space_type == "VIEW_3D" and cls.bl_region_type == "UI"
        assert cls.bl_category == "TCB"
    assert hasattr(bpy.types.Scene, "tcb_settings") and hasattr(bpy.types.Object, "tcb")


def test_unregister_and_register_again(installed, addon):
    bpy = installed
    addon.unregister()
    assert not hasattr(bpy.ops.tcb, "fit_surface") or not _op_registered(bpy, "TCB_OT_fit_surface")
    assert not hasattr(bpy.types, "TCB_PT_fit")
    assert not hasattr(bpy.types.Scene, "tcb_settings")
    assert not _import_menu_entries(bpy)  # (File > Import > TCB Spline goes with it)
    assert not _drop_handlers(bpy)  # (and the drop of point files on the 3D viewport)
    addon.register()
    assert _op_registered(bpy, "TCB_OT_fit_surface")
    assert hasattr(bpy.types, "TCB_PT_fit")
    assert len(_import_menu_entries(bpy)) == 1
    assert len(_drop_handlers(bpy)) == 1


def _drop_handlers(bpy) -> list:
    """The registered file handlers of the extension (Import Points on a drop)."""
    return [h for h in bpy.types.FileHandler.__subclasses__()
            if h.bl_idname == "TCB_FH_import_points" and hasattr(bpy.types, h.bl_idname)]


def _import_menu_entries(bpy) -> list:
    """The functions of File > Import that the extension added (its Import Spline entry)."""
    return [f for f in bpy.types.TOPBAR_MT_file_import._dyn_ui_initialize()
            if getattr(f, "__name__", "") == "menu_import"
            and "tcb_surface" in getattr(f, "__module__", "")]


def test_disable_and_enable_through_preferences(installed):
    bpy = installed
    bpy.ops.preferences.addon_disable(module=ADDON)
    assert ADDON not in bpy.context.preferences.addons
    assert not _op_registered(bpy, "TCB_OT_fit_surface")
    assert not _drop_handlers(bpy)
    bpy.ops.preferences.addon_enable(module=ADDON)
    assert ADDON in bpy.context.preferences.addons
    assert _op_registered(bpy, "TCB_OT_fit_surface")
    assert len(_drop_handlers(bpy)) == 1


def _op_registered(bpy, idname: str) -> bool:
    try:
        bpy.ops.tcb.fit_surface.get_rna_type()
    except KeyError:
        return False
    return hasattr(bpy.types, idname)
