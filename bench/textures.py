"""The cost of image textures: a textured vs the untextured Cornell box, paths per CPU-second.

    .venv/bin/python bench/textures.py [--spp 16] [--size 128] [--rounds 3] [--threads 1]
                                       [--baseline DIR/relray] [--csv bench/results]

The textured box is presets/cornell.toml with every wall, the floor, the ceiling and the
two blocks textured: a 512² base-colour checker (8-bit PNG, sRGB, repeated 4× by
uv_scale) on the white surfaces, a 256² roughness map and a 256² flat normal map
(0.5, 0.5, 1) on the blocks, a 256² colour noise on the red and green walls. Both
variants are prepared once and warmed up (numba compilation, the RGB→spectrum table,
the pyramids), then rendered alternately ``--rounds`` times; the report gives the median
paths per CPU-second of each and their ratio. ``--baseline`` also measures the cost
of the texture check for *untextured* scenes: bench/throughput.py on the Cornell box with
this code and with the code before textures, alternated (:func:`baseline_rows`).
bench/report.py turns the CSVs into RESULTS.md's "Textures" section.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import OpenImageIO as oiio

from relray.bench import common as cm


def write_png(path: Path, pixels: np.ndarray) -> Path:
    """An 8-bit PNG of ``pixels`` (H, W, C) in [0, 1] (row 0 = the top row)."""
    h, w, c = pixels.shape
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(w, h, c, "uint8"))
    out.write_image(np.ascontiguousarray(np.round(np.clip(pixels, 0, 1) * 255).astype(np.uint8)))
    out.close()
    return path


def textured_cornell(folder: Path) -> dict:
    """The Cornell job dict with textures (module docstring), images written to folder."""
    rng = np.random.default_rng(0)
    checker = (np.indices((512, 512)) // 32).sum(axis=0) % 2
    write_png(folder / "checker.png", np.repeat((0.35 + 0.4 * checker)[..., None], 3, 2))
    write_png(folder / "noise.png", 0.3 + 0.5 * rng.random((256, 256, 3)))
    write_png(folder / "rough.png", 0.3 + 0.7 * rng.random((256, 256, 1)))
    write_png(folder / "flat.png", np.tile([0.5, 0.5, 1.0], (256, 256, 1)))
    data = cm.job_dict()
    for m in data["materials"]:
        if m["name"] == "white":
            m.update(base_color_texture="checker.png", uv_scale=[4.0, 4.0],
                     roughness_texture="rough.png", normal_texture="flat.png")
        elif m["name"] in ("red", "green"):
            m.update(base_color_texture="noise.png")
    return data


def rows(spp: int, size: int, threads: int, rounds: int) -> list[dict]:
    """Paths per CPU-second of the untextured and the textured Cornell box (module
    docstring): one row per variant with the median, the runs and the ratio."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        keys = {"spp": spp, "width": size, "height": size, "threads": threads}
        runs = {"untextured": cm.RelrayBench(cm.make_job(cm.job_dict(), **keys)),
                "textured": cm.RelrayBench(cm.make_job(textured_cornell(folder),
                                                       folder / "cornell.toml", **keys))}
        renderers = {k: b.renderer() for k, b in runs.items()}
        for k, b in runs.items():  # warm-up: compile, tables, pyramids
            b.render(renderer=renderers[k])
        rates: dict[str, list[float]] = {k: [] for k in runs}
        for _ in range(rounds):
            for k, b in runs.items():
                r = b.render(renderer=renderers[k])
                rates[k].append(r.paths / r.cpu)
    base = statistics.median(rates["untextured"])
    return [{"variant": k, "size": size, "spp": spp, "threads": threads, "rounds": rounds,
             "paths_per_cpu_s": statistics.median(v), "over_untextured":
             statistics.median(v) / base, "runs": " ".join(f"{x:.0f}" for x in v)}
            for k, v in rates.items()]


def baseline_rows(baseline: Path, spp: int, rounds: int,
                  labels: tuple[str, str] = ("before textures", "with textures")) -> list[dict]:
    """The untextured Cornell box (presets/cornell.toml, its 256², ``spp``, 1 thread)
    with ``bench/throughput.py`` of this checkout and of ``baseline`` (a copy of earlier
    code, e.g. ``git archive <commit> | tar -x -C DIR/relray``), alternated ``rounds``
    times after one warm-up run of each (kernel compilation); ``labels`` name (the
    earlier code, this code). With the code before textures: the cost of the texture
    check for scenes without textures."""
    here = Path(__file__).resolve().parents[1]
    job = here / "presets" / "cornell.toml"
    trees = dict(zip(labels, (baseline, here), strict=True))
    rates: dict[str, list[float]] = {k: [] for k in trees}
    for k_round in range(rounds + 1):
        for name, tree in trees.items():
            env = {**os.environ, "PYTHONPATH": str(tree.parent)}
            out = subprocess.run([sys.executable, str(tree / "bench" / "throughput.py"),
                                  str(job), "--spp", str(spp), "--threads", "1",
                                  "--repeat", "1"], capture_output=True, text=True,
                                 env=env, cwd=tree.parent, check=True).stdout
            rate = float(re.search(r"paths/CPU-s\s+([0-9.]+) M", out).group(1)) * 1e6
            if k_round:
                rates[name].append(rate)
    base = statistics.median(rates[labels[0]])
    return [{"code": k, "spp": spp, "rounds": rounds,
             "paths_per_cpu_s": statistics.median(v),
             "over_before": statistics.median(v) / base,
             "runs": " ".join(f"{x:.0f}" for x in v)} for k, v in rates.items()]


#: the last revision before the second wave (moving bodies, textures, environment maps,
#: stars, the viewport; issue 12's regression check)
SECOND_WAVE_BASE = "9dcd0fe^"


def second_wave_rows(tmp: Path, spp: int, rounds: int) -> list[dict]:
    """:func:`baseline_rows` against the code of :data:`SECOND_WAVE_BASE` (unpacked from
    git into ``tmp``): the static, untextured Cornell box before the second wave and now."""
    base = Path(tmp) / "second_wave_base" / "relray"
    base.mkdir(parents=True, exist_ok=True)
    archive = subprocess.run(["git", "archive", SECOND_WAVE_BASE], cwd=cm.REPO,
                             capture_output=True, check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(base)], input=archive, check=True)
    return baseline_rows(base, spp, rounds,
                         (f"before the second wave ({SECOND_WAVE_BASE})", "this code"))


def main() -> None:
    """The command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--baseline", type=Path, help="a copy of the code before textures "
                    "(the folder named relray): also measure the untextured cost")
    ap.add_argument("--baseline-label", default="before textures",
                    help="what the baseline code is, for the table (e.g. 'before the "
                    "second wave (9dcd0fe^)')")
    ap.add_argument("--csv", type=Path, help="folder to write textures.csv (and "
                    "textures_baseline.csv) into, e.g. bench/results")
    a = ap.parse_args()
    tex = rows(a.spp, a.size, a.threads, a.rounds)
    print(f"Cornell {a.size}² {a.spp} spp, threads={a.threads}, median of {a.rounds} "
          f"alternated renders (load {cm.load_average()[0]:.2f}):")
    for r in tex:
        print(f"  {r['variant']:10s} {r['paths_per_cpu_s'] / 1e6:.3f} M paths/CPU-s  "
              f"×{r['over_untextured']:.3f}  ({r['runs']})")
    if a.csv:
        cm.write_csv(a.csv / "textures.csv", tex)
    if a.baseline:
        ab = baseline_rows(a.baseline.resolve(), 16, a.rounds,
                           (a.baseline_label, "this code"))
        for r in ab:
            print(f"  {r['code']:16s} {r['paths_per_cpu_s'] / 1e6:.3f} M paths/CPU-s  "
                  f"×{r['over_before']:.3f}  ({r['runs']})")
        if a.csv:
            cm.write_csv(a.csv / "textures_baseline.csv", ab)


if __name__ == "__main__":
    main()
