"""Child process of test_bpy_module.py: the linux-x64 zip renders with its OWN wheels.

Run as ``python -S platform_zip_check.py ZIP SITE_DIR`` where SITE_DIR holds only bpy,
numpy and bpy's own requirements (symlinks): none of the core's dependencies is
importable except the wheels that Blender installs from the zip. Prints one JSON line.
"""

from __future__ import annotations

import json
import os
import sys
import time
import zipfile
from pathlib import Path

zip_path, site_dir = Path(sys.argv[1]), sys.argv[2]
sys.path.insert(0, site_dir)
sys.path.insert(0, str(Path(__file__).resolve().parent))
for name in ("numba", "embreex", "colour", "scipy", "llvmlite"):
    try:
        __import__(name)
    except ImportError:
        continue
    raise SystemExit(f"{name} is importable before the install: the check would prove nothing")

import bpy  # noqa: E402

t0 = time.perf_counter()
assert bpy.ops.extensions.package_install_files(
    filepath=str(zip_path), repo="user_default", enable_on_install=False) == {"FINISHED"}
target = Path(bpy.utils.user_resource("EXTENSIONS")) / "user_default" / "relray"
with zipfile.ZipFile(zip_path) as zf:  # stable numba cache keys across runs
    for info in zf.infolist():
        f = target / info.filename
        if f.is_file():
            stamp = time.mktime((*info.date_time, 0, 0, -1))
            os.utime(f, (stamp, stamp))
assert bpy.ops.preferences.addon_enable(module="bl_ext.user_default.relray") == {"FINISHED"}
install_s = time.perf_counter() - t0

import numba  # noqa: E402
import scenes  # noqa: E402

scenes.build_cornell(width=32, height=32, samples=8)
t0 = time.perf_counter()
bpy.ops.render.render()
render_s = time.perf_counter() - t0
engine = sys.modules["bl_ext.user_default.relray.relblend.engine"]
res = engine.RESULTS[1]
print(json.dumps({
    "numba": numba.__file__,
    "user_dir": os.environ["BLENDER_USER_RESOURCES"],
    "install_seconds": install_s,
    "render_seconds": render_s,
    "mean": float(res["rgba"][..., :3].mean()),
    "shape": list(res["rgba"].shape),
}))
