"""Compile (or load) the render kernels before the first frame needs them.

``python -m relray.core.warmup`` renders a tiny frame of :data:`WARMUP_JOB` (a static
and a moving sphere, a point and an area light, every AOV, the default spectral model)
and of the same scene without the moving sphere, then a static Lambert scene plain and in
the variants of :func:`lambert_variants` (a sky, smooth shading, no light, a map,
textures, a moving box), which
runs every numba kernel a frame uses, so their machine code lands in the kernel
cache (``relray.core.kernel_cache_dir``). A later process that renders loads the kernels
from there in about a second instead of compiling them for tens of seconds. The Blender
add-on starts this in a child process when it is enabled (``relblend.warmup``), so the
first F12 does not stall and Blender's interface never waits on a compiler.
"""

from __future__ import annotations

import copy
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from .output.imageio import write_pixels
from .render.frames import build_renderer
from .scene.job import parse_job
from .scene.motion import frame_events

#: The frame the warm-up renders (job-format.md): small, but through every kernel.
WARMUP_JOB: dict[str, Any] = {
    "render": {"width": 8, "height": 8, "spp": 2, "max_depth": 3, "threads": 1},
    "output": {"formats": ["exr"], "aovs": ["depth", "doppler", "lab_time"]},
    "camera": {"position": [0.0, -4.0, 1.0], "look_at": [0.0, 0.0, 1.0], "fov": 40.0},
    "motion": {"beta": [0.0, 0.3, 0.0]},
    "materials": [{"name": "grey", "base_color": [0.5, 0.5, 0.5]},
                  {"name": "glass", "transmission": 1.0, "roughness": 0.0},
                  {"name": "metal", "metallic": 1.0, "roughness": 0.3}],
    "objects": [
        {"shape": "sphere", "center": [0.0, 0.0, 1.0], "radius": 0.5, "material": "grey",
         "subdivisions": 1},
        {"shape": "sphere", "center": [1.0, 0.0, 1.0], "radius": 0.3, "material": "glass",
         "subdivisions": 1, "velocity": [0.0, 0.0, 0.5]},
        {"shape": "box", "center": [0.0, 0.0, -0.1], "size": [4.0, 4.0, 0.2],
         "material": "metal"}],
    "lights": [{"type": "point", "position": [0.0, -2.0, 3.0], "power": 100.0},
               {"type": "area", "position": [0.0, 0.0, 3.0], "direction": [0.0, 0.0, -1.0],
                "size": [1.0, 1.0], "power": 50.0}],
}


#: A static Lambert scene of flat faces lit by an emissive quad: what whole paths in one
#: kernel call trace (render/whole_paths.py), the Cornell box's kind of scene.
LAMBERT_JOB: dict[str, Any] = {
    **{k: WARMUP_JOB[k] for k in ("render", "output", "camera", "motion")},
    "materials": [{"name": "grey", "base_color": [0.5, 0.5, 0.5]},
                  {"name": "lamp", "base_color": [0.8, 0.8, 0.8], "emission": [1.0, 1.0, 1.0],
                   "emission_strength": 5.0}],
    "objects": [
        {"shape": "box", "center": [0.0, 0.0, 1.0], "size": [1.0, 1.0, 1.0],
         "material": "grey"},
        {"shape": "quad", "material": "lamp",
         "corners": [[-0.5, -0.5, 3.0], [0.5, -0.5, 3.0], [0.5, 0.5, 3.0], [-0.5, 0.5, 3.0]]}],
}


def _write_image(path: Path, pixels: np.ndarray) -> str:
    """A float EXR of (h, w, c) ``pixels``; returns its file name."""
    px = np.ascontiguousarray(pixels, np.float32)
    write_pixels(path, path, px, oiio.ImageSpec(px.shape[1], px.shape[0], px.shape[2],
                                                oiio.FLOAT))
    return path.name


def lambert_variants(folder: Path) -> list[dict[str, Any]]:
    """:data:`LAMBERT_JOB` under a constant sky, with a smooth-shaded sphere, with both,
    without its light, under an environment map, with both and an image texture (the
    default fly-by's kind), with that under the map instead, the smooth one and the
    textured one lit by the map alone (an HDRI-lit scene), with its box moving, and with
    its box moving under the sky: the SIMD lanes (``render/lane_paths.py``:
    :data:`LAMBERT_JOB` itself, the first three, the textured one, the four under the map
    and the moving box under the lamp alone) and the whole-path kernel (the one without a
    light, the moving box under the sky, as the train and Terrell presets) are compiled
    apart for each kind (``lane_paths.kernel``, ``whole_paths.kernel``). Their 8 × 4 map
    and 2 × 2 texture are written into ``folder``."""
    sky = _write_image(folder / "sky.exr", np.full((4, 8, 3), 0.5))
    checker = _write_image(folder / "checker.exr", np.indices((2, 2, 3)).sum(axis=0) % 2)
    under_sky = {**LAMBERT_JOB, "scene": {"background": [0.1, 0.1, 0.1]}}
    smooth = copy.deepcopy(LAMBERT_JOB)
    smooth["objects"].append({"shape": "sphere", "center": [0.0, 0.0, 2.0], "radius": 0.3,
                              "material": "grey", "subdivisions": 1})
    dark = copy.deepcopy(LAMBERT_JOB)  # no light: the lanes have nothing to sample
    dark["objects"] = dark["objects"][:1]
    env = {**LAMBERT_JOB, "scene": {"environment": {"file": sky}}}
    tex = copy.deepcopy({**smooth, "scene": under_sky["scene"]})
    tex["materials"][0]["base_color_texture"] = checker
    moving = copy.deepcopy(LAMBERT_JOB)
    moving["objects"][0]["velocity"] = [0.0, 0.0, 0.5]
    moving_sky = {**moving, "scene": under_sky["scene"]}
    # the map as the only light, nothing else glowing (lane_paths.MAP_LIGHT): the lamp
    # and its material left out
    map_lit = [{**job, "scene": env["scene"],
                "materials": [m for m in job["materials"] if m["name"] != "lamp"],
                "objects": [o for o in job["objects"] if o["material"] != "lamp"]}
               for job in (smooth, tex)]
    return [under_sky, smooth, {**smooth, "scene": under_sky["scene"]}, dark, env, tex,
            {**tex, "scene": env["scene"]}, *map_lit, moving, moving_sky]


def warmup_jobs(folder: Path) -> list[dict[str, Any]]:
    """:data:`WARMUP_JOB`, the same without its moving sphere, :data:`LAMBERT_JOB` and
    :func:`lambert_variants` (their files in ``folder``): the kernels are typed per
    argument (a scene without moving objects passes other types), and the Lambert scenes
    take the SIMD lanes or the whole-path kernel, compiled per kind, so every kind is
    compiled."""
    static = dict(WARMUP_JOB)
    static["objects"] = [o for o in WARMUP_JOB["objects"] if "velocity" not in o]
    return [static, WARMUP_JOB, LAMBERT_JOB, *lambert_variants(folder)]


def warm() -> float:
    """Render a frame of each of :func:`warmup_jobs` in memory; returns the seconds."""
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="relray-warmup-") as tmp:
        folder = Path(tmp)
        for data in warmup_jobs(folder):
            job = parse_job(copy.deepcopy(data), folder / "warmup.toml")
            renderer = build_renderer(job)
            frame, event = frame_events(job)[0]
            film, _ = renderer.render(event, frame)
            film.resolve(renderer.to_rgb)
    return time.perf_counter() - t0


def main() -> int:
    seconds = warm()
    print(f"relray: render kernels ready ({seconds:.1f} s)", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
