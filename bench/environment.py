"""Environment-map lighting: next-event estimation + MIS against BSDF sampling only.

    .venv/bin/python bench/environment.py [--size 96x64] [--spp 4,8,16,32,64]
                                          [--bsdf-spp 16,64,256,1024] [--ref-spp 2048]
                                          [--threads 2] [--repeats 2] [--png DIR]

A diffuse scene (a ground quad, a sphere and a box, all grey Lambertian) lit only by an
environment map: a dim blue sky (0.3, 0.4, 0.6) over a brown ground (0.1, 0.08, 0.05),
and a small bright sun (2 × 2 texels of a 256 × 128 map, 2.8° × 2.8°, radiance 3000,
40° above the horizon). Each series renders its own spp ladder (BSDF sampling needs
far more samples for the same error); ``nee`` is the
renderer as shipped, ``bsdf only`` the same with ``env_nee`` of
:func:`..core.render.frames.prepare` False (the internal switch that leaves the map out
of the light table: it is then reached by BSDF sampling only, with MIS weight 1). Error:
relative MSE
(:func:`.common.rel_mse`) against one reference rendered with NEE at ``--ref-spp`` and
another seed; time: the process CPU time of the render (both threads), so the machine's
other load changes it less than wall time. Each point is the median over ``--repeats``
seeds. Prints a markdown table and the speed-up at equal error (log-log interpolation of
the bsdf-only curve, :func:`.common.time_at_error`). ``--png DIR`` writes the
reference and each series' largest-spp image as sRGB PNGs (exposure 1, clipped).
"""

from __future__ import annotations

import argparse
import math
import statistics
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
import OpenImageIO as oiio

from relray.bench import common as cm
from relray.core.render.frames import build_renderer
from relray.core.scene.job import parse_job
from relray.core.scene.motion import frame_events


def write_map(path: Path, width: int = 256, height: int = 128) -> Path:
    """The sky + ground + sun map (module docstring), an EXR (top row first)."""
    px = np.zeros((height, width, 3), np.float32)  # row 0 = top here (file order)
    px[: height // 2] = (0.3, 0.4, 0.6)
    px[height // 2:] = (0.1, 0.08, 0.05)
    row = int(round((0.5 - 40.0 / 180.0) * height))  # 40° above the horizon
    col = int(0.40 * width)
    px[row:row + 2, col:col + 2] = 3000.0
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(width, height, 3, oiio.FLOAT))
    out.write_image(px)
    out.close()
    return path


def job_data(width: int, height: int, spp: int, threads: int, seed: int) -> dict:
    grey = {"name": "grey", "base_color": [0.6, 0.6, 0.6], "roughness": 1.0}
    return {
        "render": {"width": width, "height": height, "spp": spp, "max_depth": 4,
                   "seed": seed, "threads": threads},
        "camera": {"position": [0.0, -6.0, 2.5], "look_at": [0.0, 0.0, 0.6], "fov": 45.0},
        "scene": {"environment": {"file": "sky.exr"}},
        "materials": [grey],
        "objects": [
            {"shape": "quad", "corners": [[-8, -8, 0], [8, -8, 0], [8, 8, 0], [-8, 8, 0]],
             "material": "grey"},
            {"shape": "sphere", "center": [-0.9, 0.3, 0.8], "radius": 0.8,
             "material": "grey"},
            {"shape": "box", "center": [1.0, 0.5, 0.6], "size": [1.2, 1.2, 1.2],
             "material": "grey"},
        ],
    }


def render(folder: Path, nee: bool, **kw) -> tuple[np.ndarray, float]:
    """(linear RGB, CPU seconds) of one render."""
    job = parse_job(job_data(**kw), folder / "job.toml")
    r = build_renderer(job, env_nee=nee)
    ev = dict(frame_events(job))
    f = min(ev)
    c0 = time.process_time()
    film, _ = r.render(ev[f], f)
    cpu = time.process_time() - c0
    return film.resolve(r.to_rgb).rgba[..., :3].astype(np.float64), cpu


def rows(width: int, height: int, nee_spp: list[int], bsdf_spp: list[int], ref_spp: int,
         threads: int, repeats: int, png: Path | None = None) -> list[dict[str, Any]]:
    """The table: per series and spp the medians over ``repeats`` seeds of the CPU time
    and the relative MSE against the NEE reference (its row: series "reference")."""
    ladders = {"nee": nee_spp, "bsdf only": bsdf_spp}
    common = {"width": width, "height": height, "threads": threads}
    out: list[dict[str, Any]] = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        write_map(folder / "sky.exr")
        render(folder, True, spp=1, seed=0, **common)   # compile the kernels
        load0 = cm.load_average()[0]
        ref, ref_cpu = render(folder, True, spp=ref_spp, seed=1000, **common)
        out.append({"series": "reference", "spp": ref_spp, "cpu_s": ref_cpu, "rel_mse": 0.0,
                    "width": width, "height": height, "threads": threads, "load": load0})
        for label, nee in (("nee", True), ("bsdf only", False)):
            for spp in ladders[label]:
                errs, cpus = [], []
                for seed in range(repeats):
                    img, cpu = render(folder, nee, spp=spp, seed=seed, **common)
                    errs.append(cm.rel_mse(img, ref))
                    cpus.append(cpu)
                out.append({"series": label, "spp": spp, "cpu_s": statistics.median(cpus),
                            "rel_mse": statistics.median(errs), "width": width,
                            "height": height, "threads": threads,
                            "load": cm.load_average()[0]})
            if png is not None:
                write_png(png / f"env_{label.replace(' ', '_')}.png", img)
        if png is not None:
            write_png(png / "env_reference.png", ref)
    return out


def speedups(table: list[dict[str, Any]]) -> list[tuple[float, float, float, bool]]:
    """(rel. MSE, NEE CPU s, BSDF-only CPU s at that error, extrapolated) per NEE row."""
    curve = {k: ([r["cpu_s"] for r in table if r["series"] == k],
                 [r["rel_mse"] for r in table if r["series"] == k])
             for k in ("nee", "bsdf only")}
    out = []
    for t, e in zip(*curve["nee"], strict=True):
        tb, extra = cm.time_at_error(*curve["bsdf only"], e)
        if math.isfinite(tb):
            out.append((e, t, tb, extra))
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="96x64")
    ap.add_argument("--spp", default="4,8,16,32,64")
    ap.add_argument("--bsdf-spp", default="16,64,256,1024")
    ap.add_argument("--ref-spp", type=int, default=2048)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=2)
    ap.add_argument("--png", type=Path, default=None)
    a = ap.parse_args(argv)
    w, h = (int(x) for x in a.size.split("x"))
    table = rows(w, h, [int(x) for x in a.spp.split(",")],
                 [int(x) for x in a.bsdf_spp.split(",")], a.ref_spp, a.threads, a.repeats,
                 a.png)
    print(f"# environment NEE + MIS vs BSDF sampling only ({w}x{h}, max_depth 4, "
          f"{a.threads} threads, reference {a.ref_spp} spp in {table[0]['cpu_s']:.1f} CPU s)")
    print(f"load average at the start {table[0]['load']:.2f}, at the end "
          f"{table[-1]['load']:.2f}; {cm.cpu_model()}\n")
    print("| series | spp | CPU s | rel. MSE |")
    print("|---|---|---|---|")
    for r in table[1:]:
        print(f"| {r['series']} | {r['spp']} | {r['cpu_s']:.2f} | {r['rel_mse']:.4g} |")
    print()
    for e, t, tb, extra in speedups(table):
        print(f"rel. MSE {e:.4g}: NEE+MIS {t:.2f} CPU s, BSDF only {tb:.2f} CPU s"
              f"{' (extrapolated)' if extra else ''}: {tb / t:.1f}x")

def write_png(path: Path, rgb: np.ndarray) -> None:
    """Linear Rec.709 -> 8-bit sRGB PNG (clipped)."""
    c = np.clip(rgb, 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    path.parent.mkdir(parents=True, exist_ok=True)
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 3, oiio.UINT8))
    out.write_image(np.ascontiguousarray((s * 255 + 0.5).astype(np.uint8)))
    out.close()

if __name__ == "__main__":
    main()
