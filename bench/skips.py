"""Skip what a scene does not need: each skip measured against the same work not skipped.

Every row renders two variants of the Cornell box that produce the same image (or, for
``rgb``, the model the user could switch to) and compares their CPU time per sample
per pixel, interleaved (A B A B) and reduced to medians.  A is what relray does, B the
work the skip avoids:

- rgb when Doppler is off: A ``spectral = "cie1931"`` with ``doppler = false``, B
  ``spectral = "rgb"`` (here the roles are reversed: B is the path A could take);
- the β = 0 path: A β = 0, B β = 1e-9 ŷ (the same picture through the general boost);
- no glossy/dielectric code: A the diffuse box, B metallic = transmission = 1e-4 on
  every material (the GGX and glass branches run and contribute nothing);
- NEE towards lights that exist: A a black background (2 light triangles), B a
  background of 1e-6 (a sky light enters the NEE table);
- BVH once per animation: A one ``relray render`` of a 24-frame fly-by, B one
  ``relray render --frames i-i`` per frame.

The second wave's skips (each B adds the feature so that it does nothing visible):

- no velocity-group traversal without moving bodies: B adds a 1 cm sphere far behind the
  camera moving at 0.1 c (one velocity group that no ray hits);
- no texture fetch for untextured materials: B gives every material a 1 × 1 base-colour
  texture of its own colour (the same picture through the texture path);
- no environment sampling without a map: B adds a 1 × 1 environment map of radiance
  1e-6 (the map enters the NEE table and every miss looks it up);
- no star pass without stars: B adds the Hipparcos stars to magnitude 6 at brightness
  1e-9 (the star pass splats them, each occlusion-tested, all invisible).
"""

from __future__ import annotations

import os
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from relray.bench import common as cm


def _write_texel(path: Path, rgb: list[float]) -> Path:
    """A 1 × 1 linear EXR of ``rgb``."""
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(1, 1, 3, oiio.FLOAT))
    out.write_image(np.asarray(rgb, np.float32).reshape(1, 1, 3))
    out.close()
    return path


def _second_wave_jobs(tmp: Path) -> dict[str, Any]:
    """The B jobs of the second wave's skips (module docstring), by row name."""
    tmp.mkdir(parents=True, exist_ok=True)
    moving = cm.job_dict()
    moving["objects"] = [*moving["objects"],
                         {"name": "speck", "shape": "sphere", "center": [0.0, -50.0, 1.0],
                          "radius": 0.01, "material": "white", "velocity": [0.1, 0.0, 0.0]}]
    textured = cm.job_dict()
    textured["materials"] = [
        dict(m, base_color_texture=str(_write_texel(tmp / f"skip_{m['name']}.exr",
                                                    m["base_color"])))
        for m in textured["materials"]]
    env = cm.job_dict()
    env["scene"] = dict(env["scene"], environment={
        "file": str(_write_texel(tmp / "skip_sky.exr", [1e-6, 1e-6, 1e-6]))})
    stars = cm.job_dict()
    stars["scene"] = dict(stars["scene"], stars={"catalog": "hipparcos",
                                                 "magnitude_limit": 6.0, "brightness": 1e-9})
    return {"no velocity-group traversal without moving bodies": cm.make_job(moving),
            "no texture fetch for untextured materials": cm.make_job(textured),
            "no environment sampling without a map": cm.make_job(env),
            "no star pass without stars": cm.make_job(stars)}


def _variant_jobs(tmp: Path | None = None
                  ) -> dict[str, tuple[Any, Any, dict[str, Any], dict[str, Any]]]:
    """name -> (job A, job B, render kwargs A, render kwargs B); ``tmp``: where the
    second wave's rows write their images (None: those rows are left out)."""
    base = cm.job_dict()
    plain = cm.make_job(base)
    glossy = cm.job_dict()
    glossy["materials"] = [dict(m, metallic=1e-4, transmission=1e-4) for m in base["materials"]]
    sky = cm.job_dict()
    sky["scene"] = dict(sky["scene"], background=[1e-6, 1e-6, 1e-6])
    second = {} if tmp is None else {name: (plain, job, {}, {})
                                      for name, job in _second_wave_jobs(tmp).items()}
    return {
        "rgb when Doppler is off": (plain, plain, {"spectral": "cie1931", "doppler": False},
                                    {"spectral": "rgb", "doppler": False}),
        "β = 0 path (no boost)": (plain, plain, {"beta": (0.0, 0.0, 0.0)},
                                  {"beta": (0.0, 1e-9, 0.0)}),
        "no glossy/dielectric code": (plain, cm.make_job(glossy), {}, {}),
        "NEE only towards existing lights": (plain, cm.make_job(sky), {}, {}),
        **second,
    }


def variant_rows(spp: int, width: int, height: int, threads: int, repeat: int,
                 ref_spp: int, tmp: Path | None = None) -> list[dict[str, Any]]:
    """The rendered rows of the skip table (module docstring), with error at ``spp``;
    ``tmp``: a folder for the second wave's images (None: without those rows)."""
    rows = []
    for name, (ja, jb, ka, kb) in _variant_jobs(tmp).items():
        benches = [cm.RelrayBench(ja), cm.RelrayBench(jb) if jb is not ja else None]
        benches[1] = benches[1] or benches[0]
        kws = [dict(ka), dict(kb)]
        betas = [k.pop("beta", None) for k in kws]
        frs = [b.renderer(spp=spp, width=width, height=height, threads=threads, **k)
               for b, k in zip(benches, kws, strict=True)]
        for b, fr, beta in zip(benches, frs, betas, strict=True):
            b.render(beta=beta, renderer=fr)  # warm-up
        times: list[list[float]] = [[], []]
        imgs: list[np.ndarray] = [np.zeros(0), np.zeros(0)]
        for _ in range(repeat):
            for i in (0, 1):
                r = benches[i].render(beta=betas[i], renderer=frs[i])
                times[i].append(r.cpu)
                imgs[i] = r.rgb
        ref = benches[0].render(beta=betas[0], spp=ref_spp, width=width, height=height,
                                threads=threads, seed=1000, **kws[0]).rgb
        ca, cb = (statistics.median(t) / spp for t in times)
        prep_b = benches[1].prep(kws[1].get("spectral", benches[1].job.render.spectral))
        rows.append({
            "skip": name, "cpu_per_spp_A_s": ca, "cpu_per_spp_B_s": cb, "B_over_A": cb / ca,
            "rel_mse_A": cm.rel_mse(imgs[0], ref), "rel_mse_B": cm.rel_mse(imgs[1], ref),
            "lights_A": benches[0].prep(kws[0].get("spectral", "cie1931")).lights.count,
            "lights_B": prep_b.lights.count,
            "spp": spp, "width": width, "height": height, "threads": threads,
            "repeat": repeat})
    return rows


def _cli(args: list[str]) -> float:
    """Wall seconds of one ``relray`` command (a fresh process, as a user runs it)."""
    env = dict(os.environ)
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "relray.core.cli", *args], check=True, env=env,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t


def animation_rows(tmp: Path, frames: int, separate: int, spp: int,
                   threads: int) -> list[dict[str, Any]]:
    """A ``frames``-frame fly-by: one ``relray render`` against one process per frame.

    ``separate`` frames are rendered one process each (frames 1…separate) and the time
    per frame is extrapolated to ``frames``; the single run renders all of them.
    Both write their EXR and PNG files into ``tmp``.
    """
    data = cm.job_dict(cm.FLYBY)
    data["scene"] = dict(data["scene"], include=str(cm.REPO / "presets" / "cornell.toml"))
    # the job moves to ``tmp``: its texture files stay where the preset names them
    data["materials"] = [{k: str(cm.FLYBY.parent / v) if k.endswith("_texture") else v
                          for k, v in m.items()} for m in data.get("materials", [])]
    data["render"] = dict(data["render"], spp=spp, threads=threads)
    data["output"] = dict(data["output"], dir=str(tmp / "flyby_out"))
    job = cm.write_job(data, tmp / "flyby_bench.toml")
    once = _cli(["render", str(job), "--frames", f"1-{frames}", "--overwrite", "--quiet"])
    each = [_cli(["render", str(job), "--frames", f"{f}-{f}", "--overwrite", "--quiet"])
            for f in range(1, separate + 1)]
    per_once = once / frames
    imp = subprocess.run([sys.executable, "-c", "import time; t = time.perf_counter(); "
                          "import colour; print(time.perf_counter() - t)"],
                         capture_output=True, text=True, check=True)
    per_each = statistics.median(each)
    b = cm.RelrayBench(cm.make_job(data, tmp / "flyby_bench.toml"))
    t = time.perf_counter()
    b.prep("cie1931")
    prepare_s = time.perf_counter() - t
    return [{"skip": f"BVH once per animation ({frames}-frame fly-by)",
             "wall_per_frame_A_s": per_once, "wall_per_frame_B_s": per_each,
             "B_over_A": per_each / per_once, "frames": frames,
             "separate_measured": separate, "prepare_in_process_s": prepare_s,
             "colour_import_s": float(imp.stdout.strip()),
             "width": data["render"]["width"], "height": data["render"]["height"],
             "spp": spp, "threads": threads}]


def heavy_prepare_row(heavy_rows: list[dict[str, Any]], frames: int) -> dict[str, Any]:
    """What building the heavy scene's BVH per frame would add (from :func:`heavy_scene`)."""
    h = [r for r in heavy_rows if r["scene"] == "heavy"][0]
    per_frame = h["wall_s"]
    return {"skip": f"BVH once per animation, heavy scene ({h['triangles']:,} triangles)",
            "prepare_s": h["prepare_s"], "build_scene_s": h["build_scene_s"],
            "render_wall_s": h["wall_s"], "frames": frames,
            "B_over_A": (per_frame + h["prepare_s"] + h["build_scene_s"]) / per_frame}
