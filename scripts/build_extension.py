#!/usr/bin/env python3
"""Build the installable extension zips (one per platform) into ``dist/``.

Usage (through the wrapper, which sets up ``.venv`` first)::

    bash scripts/build_extension                        # all platforms, Python 3.11 + 3.13 wheels
    bash scripts/build_extension --platform linux-x64   # one zip, for the tests
    bash scripts/build_extension --validate-only        # run Blender's validator on the manifest

What it does:

1. Downloads the scipy wheels that match the scipy of ``.venv`` for every requested platform and
   Python version into ``wheels/`` (git-ignored; kept as a cache, so a rebuild is offline).
   numpy is never bundled: Blender ships it.
2. Keeps ``wheels = [...]`` and ``platforms = [...]`` of ``blender_manifest.toml`` in sync with
   those wheels (a full build rewrites the two lists when scipy changes; commit the result).
3. Stages the extension in ``dist/.stage/`` (hard links of the git-visible files, so uncommitted
   work is included and ignored files are not; then the manifest's ``[build]``
   ``paths_exclude_pattern`` applies) with a manifest restricted to the requested platforms.
4. Runs Blender's own builder ``build --split-platforms`` and validator ``validate`` on every zip.
   The builder is ``bl_pkg/cli/blender_ext.py`` from the ``bpy`` wheel, or a real Blender with
   ``--blender PATH`` (``blender --command extension ...``).

Python versions: Blender 4.2-5.0 run CPython 3.11 and 5.1+ run 3.13 (bpy 5.1 is cp313-only), so
each zip carries both wheels. Blender's installer picks the wheel of its own Python (checked in
the sources of Blender 4.2.13, 4.2.23 and 5.0.1); Blender 4.2.0 ignored the Python tag and would
install the cp313 wheel, hence ``blender_version_min = "4.2.13"``. ``--python 3.11`` builds
zips with the 3.11 wheels only.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = ROOT / "blender_manifest.toml"

# Blender platform name -> the pip ``--platform`` tag to download for it. macOS: the oldest
# deployment target scipy publishes (the OpenBLAS builds; the Accelerate ones need macOS 14).
PLATFORMS = {
    "linux-x64": "manylinux_2_17_x86_64",
    "windows-x64": "win_amd64",
    "macos-arm64": "macosx_12_0_arm64",
    "macos-x64": "macosx_10_13_x86_64",
}
PYTHONS = ("3.11", "3.13")
BUNDLED = ("scipy",)  # numpy is never bundled: Blender ships it


def log(msg: str) -> None:
    print(f"[build_extension] {msg}", file=sys.stderr, flush=True)


def wheel_matches_platform(filename: str, platform: str) -> bool:
    tag = filename[:-4].split("-")[-1]
    if platform == "linux-x64":
        return "manylinux" in tag and tag.endswith("x86_64")
    if platform == "windows-x64":
        return tag == "win_amd64"
    if platform == "macos-arm64":
        return tag.startswith("macosx_") and tag.endswith(("_arm64", "universal2"))
    if platform == "macos-x64":
        return tag.startswith("macosx_") and tag.endswith(("_x86_64", "universal2"))
    raise ValueError(platform)


def ensure_wheel(package: str, version: str, platform: str, python: str, wheels_dir: Path) -> Path:
    """The wheel of ``package==version`` for (platform, python): from ``wheels_dir`` or PyPI."""
    cp = "cp" + python.replace(".", "")
    pattern = f"{package}-{version}-{cp}-{cp}-*.whl"

    def existing() -> list[Path]:
        return sorted(
            p for p in wheels_dir.glob(pattern) if wheel_matches_platform(p.name, platform)
        )

    found = existing()
    if not found:
        wheels_dir.mkdir(parents=True, exist_ok=True)
        cmd = [
            sys.executable, "-m", "pip", "download", f"{package}=={version}",
            "--only-binary=:all:", "--no-deps", "--python-version", python,
            "--platform", PLATFORMS[platform], "-d", str(wheels_dir), "-q",
        ]  # fmt: skip
        log(f"downloading {package} {version} for {platform} / Python {python}")
        subprocess.run(cmd, check=True)
        found = existing()
    if len(found) != 1:
        raise SystemExit(
            f"expected one {pattern} wheel for {platform} in {wheels_dir}, found {found}"
        )
    return found[0]


def replace_toml_list(text: str, key: str, values: list[str]) -> str:
    """Replace (or append before ``[build]``) the top-level ``key = [...]`` array of ``text``."""
    body = "".join(f'  "{v}",\n' for v in values)
    block = f"{key} = [\n{body}]"
    rx = re.compile(rf"^{key} = \[.*?^\]", re.DOTALL | re.MULTILINE)
    if rx.search(text):
        return rx.sub(lambda _m: block, text, count=1)
    head, sep, tail = text.partition("\n[")
    return f"{head.rstrip()}\n\n{block}\n{sep}{tail}"


def toml_list(text: str, key: str) -> list[str]:
    import tomllib

    return list(tomllib.loads(text).get(key, []))


def staged_files() -> list[str]:
    """Root-relative paths of the files a git checkout of the work tree would see."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"],
            cwd=ROOT, check=True, capture_output=True,
        ).stdout  # fmt: skip
        return sorted({p for p in out.decode().split("\0") if p and (ROOT / p).is_file()})
    except (OSError, subprocess.CalledProcessError):
        files = []
        prune = {"dist", "wheels", "__pycache__"}
        for dirpath, dirnames, filenames in os.walk(ROOT):
            dirnames[:] = [d for d in dirnames if not d.startswith(".") and d not in prune]
            rel = Path(dirpath).relative_to(ROOT)
            files += [str(rel / f) for f in filenames]
        return sorted(files)


def link_or_copy(src: Path, dst: Path) -> None:
    dst.parent.mkdir(parents=True, exist_ok=True)
    try:
        os.link(src, dst)
    except OSError:
        shutil.copy2(src, dst)


def bpy_scripts_dir() -> Path | None:
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        return None
    hits = sorted(Path(spec.origin).parent.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    return hits[-1].parents[3] if hits else None


def blender_ext_command(blender: str | None) -> list[str]:
    if blender:
        return [blender, "--factory-startup", "--command", "extension"]
    scripts = bpy_scripts_dir()
    if scripts is None:
        raise SystemExit(
            "Blender's extension builder not found: install the bpy wheel "
            "(bash scripts/build_extension does it) or pass --blender /path/to/blender"
        )
    return [sys.executable, str(scripts / "addons_core/bl_pkg/cli/blender_ext.py")]


def valid_tags_args(blender: str | None) -> list[str]:
    """Blender's own list of valid tags (what ``blender --command extension`` enforces)."""
    if blender:
        return []  # Blender passes its own list
    scripts = bpy_scripts_dir()
    tags = scripts / "modules/_bpy_internal/extensions/tags.py" if scripts else None
    return ["--valid-tags", str(tags)] if tags and tags.exists() else []


def run_blender_ext(cmd: list[str], *args: str) -> str:
    proc = subprocess.run([*cmd, *args], capture_output=True, text=True, check=False)
    out = (proc.stdout + proc.stderr).strip()
    if proc.returncode != 0 or "FATAL_ERROR" in out:
        raise SystemExit(f"{' '.join(args[:1])} failed ({proc.returncode}):\n{out}")
    return out


def validate(cmd: list[str], tags: list[str], path: Path) -> str:
    return run_blender_ext(cmd, "validate", *tags, str(path))


def build(
    platforms: list[str],
    pythons: list[str],
    out_dir: Path,
    wheels_dir: Path,
    blender: str | None = None,
    update_manifest: bool | None = None,
) -> list[Path]:
    t0 = time.perf_counter()
    cmd = blender_ext_command(blender)
    tags = valid_tags_args(blender)
    text = MANIFEST.read_text()

    # 1. wheels for every requested (platform, python)
    wheels: list[Path] = []
    for package in BUNDLED:
        version = importlib.metadata.version(package)
        for platform in platforms:
            for python in pythons:
                wheels.append(ensure_wheel(package, version, platform, python, wheels_dir))
    rel = [f"./wheels/{w.name}" for w in wheels]

    # 2. the repository manifest lists all platforms and wheels of a full build
    full = set(platforms) == set(PLATFORMS) and set(pythons) == set(PYTHONS)
    if update_manifest is None:
        update_manifest = full
    if update_manifest:
        new = replace_toml_list(text, "platforms", list(platforms))
        new = replace_toml_list(new, "wheels", rel)
        if new != text:
            MANIFEST.write_text(new)
            log("updated platforms/wheels in blender_manifest.toml (commit it)")
            text = new
    elif not set(rel) <= set(toml_list(text, "wheels")):
        log("note: blender_manifest.toml lists other wheels; a full build updates the list")

    # 3. stage: git-visible files (hard links) + the selected wheels + a restricted manifest
    stage = out_dir / ".stage"
    shutil.rmtree(stage, ignore_errors=True)
    stage.mkdir(parents=True)
    for f in staged_files():
        if f == MANIFEST.name or f.startswith(("wheels/", "dist/")):
            continue
        link_or_copy(ROOT / f, stage / f)
    for w in wheels:
        link_or_copy(w, stage / "wheels" / w.name)
    staged = replace_toml_list(text, "platforms", list(platforms))
    staged = replace_toml_list(staged, "wheels", rel)
    (stage / MANIFEST.name).write_text(staged)

    # 4. Blender's builder, then Blender's validator on the manifest and on every zip
    validate(cmd, tags, stage)
    out_dir.mkdir(parents=True, exist_ok=True)
    run_blender_ext(
        cmd, "build", "--source-dir", str(stage), "--output-dir", str(out_dir),
        "--split-platforms", *tags,
    )  # fmt: skip
    import tomllib

    meta = tomllib.loads(staged)
    zips = []
    for platform in platforms:
        z = out_dir / f"{meta['id']}-{meta['version']}-{platform.replace('-', '_')}.zip"
        validate(cmd, tags, z)
        zips.append(z)
        log(f"built {z.relative_to(ROOT) if z.is_relative_to(ROOT) else z} "
            f"({z.stat().st_size / 1e6:.1f} MB), validated")  # fmt: skip
    shutil.rmtree(stage, ignore_errors=True)
    log(f"done in {time.perf_counter() - t0:.1f} s")
    return zips


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--platform", action="append", choices=sorted(PLATFORMS),
                    help="build only this platform (repeatable; default: all)")  # fmt: skip
    ap.add_argument("--python", default=",".join(PYTHONS),
                    help="comma-separated Python versions of the bundled wheels (default: %(default)s)")  # fmt: skip
    ap.add_argument(
        "--out", type=Path, default=ROOT / "dist", help="output directory (default: dist/)"
    )
    ap.add_argument(
        "--wheels", type=Path, default=ROOT / "wheels", help="wheel cache (default: wheels/)"
    )
    ap.add_argument(
        "--blender", help="use this Blender executable's builder instead of the bpy wheel's"
    )
    ap.add_argument("--validate-only", action="store_true",
                    help="only run Blender's validator on the repository's manifest")  # fmt: skip
    args = ap.parse_args(argv)

    if args.validate_only:
        print(validate(blender_ext_command(args.blender), valid_tags_args(args.blender), ROOT))
        return 0
    pythons = [p.strip() for p in args.python.split(",") if p.strip()]
    bad = [p for p in pythons if p not in PYTHONS]
    if bad:
        ap.error(f"unsupported --python {bad}; choose from {PYTHONS}")
    for z in build(args.platform or list(PLATFORMS), pythons, args.out.resolve(), args.wheels.resolve(),
                   blender=args.blender):  # fmt: skip
        print(z)
    return 0


if __name__ == "__main__":
    sys.exit(main())
