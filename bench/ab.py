"""This checkout against another revision on one benchmark scene: CPU time per path.

    .venv/bin/python -m relray.bench.ab REV [--scene environment] [--spp 16] [--size 128]
                                            [--pairs 8] [--reps 4]

A change's speed-up, measured the way this shared, noisy machine allows: ``REV`` (any
git revision) is unpacked with ``git archive`` into a temporary folder (its kernels get
their own numba cache entries, keyed by file path: its first run compiles them), then
each round runs one process of each tree, the order alternating from round to round.
A process builds and renders the scene (:func:`.profile_scenes.scene_bench`: cornell,
heavy, environment, textured, moving (the room as one body); ``peer_moving``, the
peers' moving scene of four bodies, :func:`.path_floor.floor_bench`; or any job file,
``--scene presets/moving/train.toml``: its frame 1; ``size``², ``spp``, 1 thread)
``reps`` times after one untimed render and prints its fastest process CPU time per path
(of the render call: :class:`.common.RelrayBench`). The result is the
median over the rounds of (this ÷ revision) with its quartiles: a paired ratio, so a
drift of the machine's load cancels within a round.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

#: The worker, run with a tree's parent on PYTHONPATH: only what every revision since the
#: per-scene profile has (``RelrayBench.render``; ``profile_scenes.scene_bench``, or in
#: revisions older than it ``scene_benches``, which builds every scene; ``peer_moving``
#: needs ``path_floor.floor_bench``, 2026-11-27).
WORKER = """
import sys, time
from pathlib import Path
from relray.bench import profile_scenes
scene, spp, size, reps, tmp = sys.argv[1], *map(int, sys.argv[2:5]), Path(sys.argv[5])
heavy = 1_000_000 if scene == "heavy" else 2000
if scene.endswith(".toml"):
    from relray.bench.common import RelrayBench
    from relray.core.scene.job import load_job
    bench = RelrayBench(load_job(Path(scene)))
elif scene == "peer_moving":
    from relray.bench import path_floor
    bench = path_floor.floor_bench("moving", tmp, heavy)
elif hasattr(profile_scenes, "scene_bench"):
    bench = profile_scenes.scene_bench(scene, tmp, heavy)
else:
    bench = profile_scenes.scene_benches(tmp, heavy)[scene]
bench.render(spp=1, width=16, height=16, threads=1)
best = min(bench.render(spp=spp, width=size, height=size, threads=1).cpu
           for _ in range(reps))
print(1e9 * best / (spp * size * size))
"""


def ns_per_path(tree: Path, scene: str, spp: int, size: int, reps: int, tmp: Path) -> float:
    """One worker process of ``tree`` (a folder named ``relray``): its fastest CPU ns per
    path."""
    env = {**os.environ, "PYTHONPATH": str(tree.parent)}
    out = subprocess.run([sys.executable, "-c", WORKER, scene, str(spp), str(size),
                          str(reps), str(tmp)], capture_output=True, text=True, env=env,
                         cwd=tree.parent, check=True).stdout
    return float(out.split()[-1])


def paired_ratios(here: list[float], there: list[float]) -> dict[str, float]:
    """Median and quartiles of here[i] / there[i] over the rounds."""
    r = [a / b for a, b in zip(here, there, strict=True)]
    q = statistics.quantiles(r, n=4) if len(r) > 1 else [r[0]] * 3
    return {"median": statistics.median(r), "q1": q[0], "q3": q[2], "pairs": len(r)}


def unpack(rev: str, repo: Path, into: Path) -> Path:
    """``git archive rev`` of ``repo`` unpacked into ``into/relray``."""
    tree = into / "relray"
    tree.mkdir(parents=True)
    archive = subprocess.run(["git", "-C", str(repo), "archive", rev], capture_output=True,
                             check=True).stdout
    subprocess.run(["tar", "-x", "-C", str(tree)], input=archive, check=True)
    return tree


def main(argv: list[str] | None = None) -> None:
    """The command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("rev", help="the git revision to compare with, e.g. HEAD~3")
    ap.add_argument("--scene", default="environment")
    ap.add_argument("--spp", type=int, default=16)
    ap.add_argument("--size", type=int, default=128)
    ap.add_argument("--pairs", type=int, default=8)
    ap.add_argument("--reps", type=int, default=4)
    a = ap.parse_args(argv)
    if a.scene.endswith(".toml"):
        a.scene = str(Path(a.scene).resolve())
    here = Path(__file__).resolve().parents[1]
    with tempfile.TemporaryDirectory() as tmp:
        there = unpack(a.rev, here, Path(tmp) / "rev")
        trees = {"here": here, a.rev: there}
        work = Path(tmp) / "scenes"
        for tree in trees.values():  # compile (or load) each tree's kernels, untimed
            ns_per_path(tree, a.scene, 1, 16, 1, work)
        runs: dict[str, list[float]] = {k: [] for k in trees}
        for k in range(a.pairs):
            for name in (list(trees) if k % 2 == 0 else list(trees)[::-1]):
                runs[name].append(ns_per_path(trees[name], a.scene, a.spp, a.size, a.reps,
                                              work))
    s = paired_ratios(runs["here"], runs[a.rev])
    print(f"{a.scene}, {a.size}², {a.spp} spp, 1 thread: CPU ns per path, this checkout "
          f"{statistics.median(runs['here']):.0f}, {a.rev} {statistics.median(runs[a.rev]):.0f};"
          f" this ÷ {a.rev}, median of {s['pairs']} alternated pairs: {s['median']:.2f} "
          f"(quartiles {s['q1']:.2f}–{s['q3']:.2f})")


if __name__ == "__main__":
    main()
