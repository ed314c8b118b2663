"""Blender test harness: build the extension zip, install it into a temporary user folder with
Blender's own operator, exactly as a user would, and hand the ``bpy`` module to the tests.

- The zip is built once per session by ``scripts/build_extension.py --platform linux-x64`` into
  a temporary folder (scipy wheels come from the ``wheels/`` cache after the first run).
- ``BLENDER_USER_RESOURCES`` (and the more specific ``BLENDER_USER_*`` folders) point into a
  temporary directory *before* ``import bpy``: bpy loads the preferences and adds the extension
  site-packages to ``sys.path`` at import time, so setting them later would mix in the real
  user folder.
- No bpy -> the Blender tests FAIL, unless ``TCB_SKIP_BLENDER=1`` is set (then they skip).
- The installed add-on is ``bl_ext.user_default.tcb_surface``; its engine is
  ``bl_ext.user_default.tcb_surface.core``, a different module from the repository's ``core``
  that the core tests import, so both live in one pytest process.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
ADDON = "bl_ext.user_default.tcb_surface"
TIMINGS: dict[str, float] = {}


def _skip_or_fail(msg: str):
    if os.environ.get("TCB_SKIP_BLENDER") == "1":
        pytest.skip(f"TCB_SKIP_BLENDER=1: {msg}")
    pytest.fail(f"{msg} (set TCB_SKIP_BLENDER=1 to skip the Blender tests)", pytrace=False)


@pytest.fixture(scope="session")
def blender_user_dir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("blender_user")


@pytest.fixture(scope="session")
def extension_zip(tmp_path_factory) -> Path:
    """The linux-x64 zip, built by scripts/build_extension.py with Blender's own builder."""
    import importlib.util

    if importlib.util.find_spec("bpy") is None:
        _skip_or_fail("the bpy wheel is not installed (bash scripts/test installs it)")
    out = tmp_path_factory.mktemp("dist")
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, str(ROOT / "scripts" / "build_extension.py"), "--platform", "linux-x64",
         "--out", str(out)],
        capture_output=True, text=True, cwd=ROOT, check=False,
    )  # fmt: skip
    TIMINGS["build_zip"] = time.perf_counter() - t0
    if proc.returncode != 0:
        pytest.fail(f"building the extension failed:\n{proc.stdout}\n{proc.stderr}", pytrace=False)
    zips = sorted(out.glob("tcb_surface-*-linux_x64.zip"))
    assert len(zips) == 1, (proc.stdout, proc.stderr)
    return zips[0]


@pytest.fixture(scope="session")
def bpy_module(blender_user_dir):
    """``bpy``, imported with the user folders redirected into a temporary directory."""
    if "bpy" in sys.modules:
        import bpy

        if Path(bpy.utils.resource_path("USER")) != blender_user_dir:
            pytest.fail("bpy was imported before the Blender test fixture could redirect "
                        "BLENDER_USER_RESOURCES", pytrace=False)  # fmt: skip
        return bpy
    os.environ["BLENDER_USER_RESOURCES"] = str(blender_user_dir)
    for sub, var in (("config", "CONFIG"), ("scripts", "SCRIPTS"), ("extensions", "EXTENSIONS"),
                     ("datafiles", "DATAFILES")):  # fmt: skip
        os.environ[f"BLENDER_USER_{var}"] = str(blender_user_dir / sub)
    t0 = time.perf_counter()
    try:
        import bpy
    except ImportError as ex:
        _skip_or_fail(f"bpy cannot be imported: {ex}")
    TIMINGS["import_bpy"] = time.perf_counter() - t0
    return bpy


@pytest.fixture(scope="session")
def installed(bpy_module, extension_zip, blender_user_dir):
    """The extension, installed from the zip and enabled; yields ``bpy``."""
    bpy = bpy_module
    t0 = time.perf_counter()
    result = bpy.ops.extensions.package_install_files(
        filepath=str(extension_zip), repo="user_default", enable_on_install=True
    )
    TIMINGS["install_zip"] = time.perf_counter() - t0
    assert result == {"FINISHED"}, result
    assert ADDON in bpy.context.preferences.addons, "the extension was not enabled"
    yield bpy


@pytest.fixture
def addon(installed):
    """The installed add-on's package (``bl_ext.user_default.tcb_surface``)."""
    return sys.modules[ADDON]


@pytest.fixture
def clean_scene(installed):
    """An empty scene (factory settings would reload the preferences, so objects are removed)."""
    bpy = installed
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    for coll in list(bpy.data.collections):
        bpy.data.collections.remove(coll)
    for mesh in list(bpy.data.meshes):
        bpy.data.meshes.remove(mesh)
    bpy.context.view_layer.update()
    yield bpy


def pytest_terminal_summary(terminalreporter):
    if TIMINGS:
        terminalreporter.write_line(
            "blender timings: " + ", ".join(f"{k} {v:.2f} s" for k, v in TIMINGS.items())
        )
