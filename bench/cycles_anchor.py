"""Cycles as the anchor: relray's scene handed to a bpy subprocess, rendered on demand.

    with CyclesWorker(scene_npz(job, scene, 64, 64, tmp)) as cy:
        img, wall, cpu = cy.render(spp=64, threads=2, max_bounces=6, out=tmp / "a.exr")

The worker (:mod:`.cycles_worker`) stays alive between renders, so runs of relray and
Cycles can be interleaved (A B A B) without paying for Blender's start-up each time.
Only the ``bpy.ops.render.render`` call is timed, in the worker (wall and the worker's
CPU time, all Cycles threads included).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

from relray.bench import common as cm
from relray.core.scene import motion
from relray.core.scene.description import Job
from relray.core.scene.geometry import Scene

WORKER = Path(__file__).with_name("cycles_worker.py")
MARK = "@@CYCLES@@"


def bpy_available() -> bool:
    """True when ``import bpy`` works in this interpreter's environment (a subprocess)."""
    r = subprocess.run([sys.executable, "-c", "import bpy"], capture_output=True)
    return r.returncode == 0


def cycles_bounces(max_depth: int) -> int:
    """Cycles' ``max_bounces`` equal to relray's ``max_depth`` (path segments).

    relray counts the camera segment and the light segment: direct light only is
    max_depth 2, which Cycles calls 0 bounces.
    """
    return max(0, int(max_depth) - 2)


def scene_npz(job: Job, scene: Scene, width: int, height: int, path: Path) -> Path:
    """Write what the worker needs to rebuild ``scene`` in Blender (triangles, materials,
    camera) to ``path``.  Only Lambert + RGB emission materials are supported (enough
    for the Cornell box); anything else raises ValueError.
    """
    mats = []
    for m in scene.materials:
        if m.metallic or m.transmission or m.emission_blackbody or m.emission_line or \
                m.emission_spectrum is not None:
            raise ValueError(f"material {m.name!r}: only Lambert + RGB emission for Cycles")
        mats.append({"name": m.name, "base_color": list(m.base_color),
                     "emission": list(m.emission), "emission_strength": m.emission_strength,
                     "one_sided": bool(m.one_sided_emission)})
    if scene.lights or np.any(scene.background):
        raise ValueError("analytic lights and a sky are not exported to Cycles")
    cam = motion.resolve_camera(job, scene)
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(path, triangles=np.asarray(scene.triangles, np.float64),
             material_ids=np.asarray(scene.material_ids, np.int32),
             materials=np.array(json.dumps(mats)), fov=float(cam.fov),
             rotation=np.asarray(cam.rotation, np.float64),
             position=np.asarray(cam.position, np.float64), width=int(width),
             height=int(height))
    return path


def read_exr_rgb(path: Path) -> np.ndarray:
    """float64 (h, w, 3) linear RGB of an EXR, row 0 = top (OpenImageIO's order)."""
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise OSError(f"cannot read {path}: {oiio.geterror()}")
    try:
        px = inp.read_image(0, 0, 0, 3, "float")
    finally:
        inp.close()
    return np.asarray(px, np.float64)


class CyclesWorker(cm.WorkerProcess):
    """A bpy subprocess that builds one scene and renders it on demand."""

    def __init__(self, scene_file: Path, log: Path | None = None):
        super().__init__(MARK, "Cycles worker", log)
        self.scene_file = Path(scene_file)

    def start(self) -> None:
        """Start the worker and build the scene."""
        hello = self._spawn([sys.executable, str(WORKER)])
        self.version = hello.get("version", "?")
        self._call({"cmd": "setup", "scene": str(self.scene_file)})

    def render(self, spp: int, out: Path, threads: int, max_bounces: int = 6,
               adaptive: bool = False, threshold: float = 0.01,
               seed: int = 0) -> tuple[np.ndarray, float, float]:
        """Render; returns (linear RGB float64 (h, w, 3), wall s, CPU s)."""
        r = self._call({"cmd": "render", "spp": int(spp), "adaptive": bool(adaptive),
                        "threshold": float(threshold), "seed": int(seed),
                        "max_bounces": int(max_bounces), "threads": int(threads),
                        "out": str(out)})
        img = read_exr_rgb(Path(out))
        Path(out).unlink(missing_ok=True)
        return img, float(r["wall"]), float(r["cpu"])
