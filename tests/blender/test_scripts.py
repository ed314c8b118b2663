"""scripts/fit_in_blender.py end to end, in a subprocess (its own bpy, its own temporary
Blender user folders): a small fit with export and a tiny render, and bad input."""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SCRIPT = ROOT / "scripts" / "fit_in_blender.py"


@pytest.fixture(scope="module", autouse=True)
def _need_bpy():
    if importlib.util.find_spec("bpy") is None:
        if os.environ.get("TCB_SKIP_BLENDER") == "1":
            pytest.skip("TCB_SKIP_BLENDER=1: the bpy wheel is not installed")
        pytest.fail("the bpy wheel is not installed (bash scripts/test installs it; set "
                    "TCB_SKIP_BLENDER=1 to skip the Blender tests)", pytrace=False)  # fmt: skip


def run_script(*args, timeout=300) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(SCRIPT), *map(str, args)],
        capture_output=True, text=True, cwd=ROOT, timeout=timeout, check=False,
    )  # fmt: skip


def obj_counts(path: Path) -> tuple[int, int]:
    v = f = 0
    with open(path) as fh:
        for line in fh:
            if line.startswith("v "):
                v += 1
            elif line.startswith("f "):
                f += 1
    return v, f


def test_fit_export_render_nefertiti(tmp_path, clean_scene):
    blend, obj, png = tmp_path / "a" / "nef.blend", tmp_path / "nef.obj", tmp_path / "nef.png"
    proc = run_script(
        ROOT / "data" / "nefertiti.off", "-o", blend, "--tolerance", "1e-2",
        "--max-control-points", "120", "--resolution", "16", "--export", obj,
        "--render", png, "--render-size", "64x48", "--samples", "1",
    )  # fmt: skip
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out
    assert blend.is_file() and blend.stat().st_size > 0, out
    assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", out
    nv, nf = obj_counts(obj)
    assert nv > 0 and nf > 0, out
    # the report table
    for row in ("knots", "control points", "RMS error", "max error", "total"):
        assert row in proc.stdout, out
    rows = [ln for ln in proc.stdout.splitlines() if ln.startswith("control points")]
    cps = int(rows[0].split()[-1])
    assert 0 < cps <= 120
    # the saved camera (F12 in the .blend) frames the surface and its whole net (the net's
    # outer points had run off the picture)
    bpy = clean_scene
    from bpy_extras.object_utils import world_to_camera_view

    bpy.ops.wm.open_mainfile(filepath=str(blend))
    scene = bpy.context.scene
    net = next(o for o in bpy.data.objects if o.tcb.role == "NET")
    seen = [world_to_camera_view(scene, scene.camera, net.matrix_world @ v.co)
            for v in net.data.vertices]
    assert len(seen) >= 10 and all(0 <= c.x <= 1 and 0 <= c.y <= 1 and c.z > 0 for c in seen)


def test_fit_point_cloud_xyz_without_render(tmp_path):
    import numpy as np

    t = np.linspace(-1.0, 1.0, 15)
    x, y = np.meshgrid(t, t)
    pts = np.c_[x.ravel(), y.ravel(), 0.2 * (x * x - y * y).ravel()]
    src = tmp_path / "saddle.xyz"
    np.savetxt(src, pts)
    blend, ply = tmp_path / "saddle.blend", tmp_path / "saddle.ply"
    proc = run_script(src, "-o", blend, "--tolerance", "1e-2", "--max-control-points", "80",
                      "--resolution", "8", "--export", ply, "--no-deviation",
                      "--smoothness", "auto", "--projection", "z")  # fmt: skip
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert blend.is_file() and ply.is_file() and ply.read_bytes().startswith(b"ply")
    row = [ln for ln in proc.stdout.splitlines() if ln.startswith("smoothness")]
    assert len(row) == 1 and row[0].endswith("(auto)"), proc.stdout


def test_a_dem_raster_is_fitted_along_z_as_on_the_command_line(tmp_path):
    """A sloping DEM tile (.asc) is fitted along z (core.meshio.is_raster, the object marked
    as Import Points marks it): the surface ends at the tile's straight edges (on its tilted
    best-fit plane, the script's Auto before, more than 1 m past them)."""
    import numpy as np

    j, i = np.meshgrid(np.arange(40), np.arange(30))
    z = 100.0 + 3.0 * j + 4.0 * np.sin(j / 6.0) + 3.0 * np.cos(i / 5.0)  # (17 degrees)
    src = tmp_path / "slope.asc"
    src.write_text("ncols 40\nnrows 30\nxllcorner 0\nyllcorner 0\ncellsize 10\n"
                   + "\n".join(" ".join(f"{v:.6f}" for v in row) for row in z) + "\n")
    blend, ply = tmp_path / "slope.blend", tmp_path / "slope.ply"
    proc = run_script(src, "-o", blend, "--max-control-points", "150", "--max-iterations", "2",
                      "--resolution", "16", "--export", ply, "--no-deviation")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "is a DEM raster (Import Points): fitted along its z" in proc.stdout + proc.stderr
    from core.meshio import read_geometry

    verts = read_geometry(ply)[0]
    past = max((5.0 - verts[:, :2]).max(), (verts[:, 0] - 395.0).max(),
               (verts[:, 1] - 295.0).max())
    assert past < 1e-3, past


def test_bad_smoothness_is_refused(tmp_path):
    proc = run_script(ROOT / "data" / "nefertiti.off", "-o", tmp_path / "x.blend",
                      "--smoothness", "lots", timeout=60)
    # an option error is bad input like the others: one line (not argparse's usage first)
    assert "nonnegative number or 'auto'" in _error_line(proc)
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert not (tmp_path / "x.blend").exists()


def _error_line(proc) -> str:
    assert proc.returncode == 1, proc.stdout + proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.startswith("fit_in_blender: error:")]
    assert len(lines) == 1, proc.stderr
    return lines[0]


def test_missing_input_fails_with_one_line(tmp_path):
    proc = run_script(tmp_path / "nope.off", "-o", tmp_path / "x.blend", timeout=60)
    assert "input file not found" in _error_line(proc)
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "x.blend").exists()


def test_closed_mesh_fails_with_one_line(tmp_path):
    src = tmp_path / "tetra.off"
    src.write_text("OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n")
    proc = run_script(src, "-o", tmp_path / "t.blend")
    line = _error_line(proc)
    assert "closed" in line, line
    assert "Traceback" not in proc.stderr
    assert not (tmp_path / "t.blend").exists()


def test_a_mesh_with_a_hole_is_fitted_with_fill_holes(tmp_path):
    """The script's error said "turn on Fill Holes in the fit settings" and it had no such
    option (user test)."""
    g = range(12)
    verts = [(x / 11, y / 11, 0.1 * ((x - 5) ** 2 - (y - 5) ** 2) / 25) for y in g for x in g]
    cells = [(y, x) for y in range(11) for x in range(11) if not (4 <= x <= 5 and 4 <= y <= 5)]
    quads = [(12 * y + x, 12 * y + x + 1, 12 * y + x + 13, 12 * y + x + 12) for y, x in cells]
    src = tmp_path / "holed.off"
    src.write_text(f"OFF\n{len(verts)} {len(quads)} 0\n"
                   + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in verts)
                   + "".join("4 " + " ".join(map(str, q)) + "\n" for q in quads))
    proc = run_script(src, "-o", tmp_path / "h.blend", "--resolution", "8", "--no-deviation")
    assert "pass --fill-holes" in _error_line(proc)
    proc = run_script(src, "-o", tmp_path / "h.blend", "--resolution", "8", "--no-deviation",
                      "--fill-holes")
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert (tmp_path / "h.blend").is_file()


@pytest.mark.parametrize("option, value, words", [
    ("--tolerance", "-1", "--tolerance must be 0 (refine to the budget) or at least 1e-09"),
    ("--tolerance", "nan", "--tolerance must be 0 (refine to the budget) or at least 1e-09"),
    ("--tolerance", "1e-12", "--tolerance must be 0 (refine to the budget) or at least 1e-09"),
    ("--max-iterations", "99999999999", "--max-iterations must be at most 2147483647"),
    ("--max-control-points", "5", "--max-control-points must be at least 10, got 5"),
    ("--max-iterations", "0", "--max-iterations must be at least 1, got 0"),
    ("--resolution", "0", "--resolution must be at least 2, got 0"),
    ("--resolution", "100000", "--resolution must be at most 2048, got 100000"),
])
def test_option_values_beyond_the_fit_settings_limits_are_refused(tmp_path, option, value, words):
    # Blender's settings would clamp them silently (a tolerance of -1 ran as 1e-9: user test)
    proc = run_script(ROOT / "data" / "nefertiti.off", "-o", tmp_path / "x.blend", option, value,
                      timeout=60)
    assert words in _error_line(proc)
    assert not (tmp_path / "x.blend").exists()


def test_the_script_limits_are_the_fit_settings_limits(addon):
    spec = importlib.util.spec_from_file_location("fit_in_blender_limits", SCRIPT)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    props = addon.tcb_addon.properties
    settings = props.FitSettings.__annotations__
    # (soft limits: the operators refuse values beyond them, operators.check_settings)
    assert (script.MIN_BUDGET == props.MIN_BUDGET
            == settings["max_control_points"].keywords["soft_min"])
    assert script.MAX_RESOLUTION == props.MAX_RESOLUTION
    assert "max" not in settings["resolution"].keywords


def test_outputs_over_the_input_or_where_they_cannot_be_written_are_refused_first(tmp_path):
    src = tmp_path / "scan.obj"
    n = 12
    src.write_text("".join(f"v {i} {j} {0.1 * (i - j) ** 2}\n" for i in range(n) for j in range(n))
                   + "".join(f"f {i * n + j + 1} {(i + 1) * n + j + 1} {i * n + j + 2}\n"
                             for i in range(n - 1) for j in range(n - 1)))
    before = src.read_bytes()
    link = tmp_path / "same.obj"
    os.link(src, link)
    (tmp_path / "d.png").mkdir()
    for args, words in (
        (["--export", src], "--export"),
        (["--export", tmp_path / "." / "scan.obj"], "is the input file"),
        (["--render", src / "r.png"], "is a file, not a folder"),
        (["--export", src / "sub" / "s.obj"], "is a file, not a folder"),
        (["--export", link], "is the input file"),  # (a hard link: review)
        (["--render", tmp_path / "d.png"], "is a folder: give a file name"),
    ):
        proc = run_script(src, "-o", tmp_path / "x.blend", *args, timeout=60)
        assert words in _error_line(proc)
        assert proc.stdout == ""  # refused before Blender started
    assert src.read_bytes() == before and not (tmp_path / "x.blend").exists()
