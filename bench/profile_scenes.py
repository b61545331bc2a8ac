"""Where each nanosecond of a path goes, per benchmark scene (issue 12, item 5).

The stage profile of :func:`.throughput.profile_table` (Embree, shade, NEE shadows,
sampling, film, glue; each stage timed with the thread's CPU clock by wrapping the
core's functions) for every scene the benchmark renders, 1 thread:

- ``cornell``: the Cornell box (presets/cornell.toml);
- ``heavy``: the box with a displaced-grid floor of about a million triangles
  (:func:`.throughput.heavy_job`);
- ``environment``: ground, sphere and box lit only by an environment map with a small
  sun (:mod:`.environment`);
- ``textured``: the box with base-colour, roughness and normal textures (:mod:`.textures`);
- ``moving``: the box with the whole room as one moving velocity group
  (:func:`.velocity_groups.grouped_scene`).

    .venv/bin/python -m relray.bench.profile_scenes [--size 128] [--spp 16]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

from relray.bench import common as cm
from relray.bench import environment, textures, throughput, velocity_groups
from relray.core.scene.job import parse_job

SCENES = ("cornell", "heavy", "environment", "textured", "moving")


#: The benchmark scenes, in the order of the profile's columns.
SCENES = ("cornell", "heavy", "environment", "textured", "moving")


def scene_bench(name: str, tmp: Path, heavy_triangles: int) -> cm.RelrayBench:
    """One benchmark scene (module docstring), its files written into ``tmp``."""
    tmp.mkdir(parents=True, exist_ok=True)
    if name == "cornell":
        return cm.RelrayBench(cm.make_job(cm.job_dict()))
    if name == "heavy":
        return cm.RelrayBench(throughput.heavy_job(tmp, heavy_triangles)[0])
    if name == "environment":
        env_dir = tmp / "profile_env"
        env_dir.mkdir(exist_ok=True)
        environment.write_map(env_dir / "sky.exr")
        return cm.RelrayBench(parse_job(environment.job_data(64, 64, 1, 1, 0),
                                        env_dir / "job.toml"))
    if name == "textured":
        tex_dir = tmp / "profile_tex"
        tex_dir.mkdir(exist_ok=True)
        return cm.RelrayBench(cm.make_job(textures.textured_cornell(tex_dir),
                                          tex_dir / "job.toml"))
    if name == "moving":
        cornell = scene_bench("cornell", tmp, heavy_triangles)
        return cm.RelrayBench(cornell.job,
                              scene=velocity_groups.grouped_scene(cornell.scene, 1))
    raise ValueError(f"unknown benchmark scene {name!r} (one of {', '.join(SCENES)})")


def scene_benches(tmp: Path, heavy_triangles: int) -> dict[str, cm.RelrayBench]:
    """Every benchmark scene, by name."""
    return {name: scene_bench(name, tmp, heavy_triangles) for name in SCENES}


def rows(tmp: Path, spp: int, size: int, heavy_triangles: int,
         repeat: int = 1) -> list[dict[str, Any]]:
    """One row per (scene, stage): CPU seconds, share and ns per path (1 thread), plus a
    "total" row per scene with the paths per CPU-second and the Embree share."""
    out = []
    for name, bench in scene_benches(tmp, heavy_triangles).items():
        m = throughput.measure_bench(bench, 1, repeat, profile=True, spp=spp, width=size,
                                     height=size)
        for r in throughput.profile_table(m):
            out.append({"scene": name, **r})
        out.append({"scene": name, "stage": "total", "seconds": m["cpu_s"], "share": 1.0,
                    "ns_per_path": 1e9 * m["cpu_s"] / max(m["paths"], 1),
                    "paths_per_cpu_s": m["paths_per_cpu_s"],
                    "embree_share": m["embree_share"], "rays_per_path": m["rays_per_path"],
                    "spp": spp, "size": size})
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--heavy", type=int, default=1_000_000, help="heavy scene triangles")
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        table = rows(Path(tmp), a.spp, a.size, a.heavy)
    for scene in SCENES:
        part = [r for r in table if r["scene"] == scene]
        total = part[-1]
        print(f"## {scene}: {total['ns_per_path']:.0f} ns per path, Embree "
              f"{100 * total['embree_share']:.0f} %")
        for r in part[:-1]:
            if r["seconds"] > 0:
                print(f"  {r['stage']:45s} {r['ns_per_path']:8.0f} ns")


if __name__ == "__main__":
    main()
