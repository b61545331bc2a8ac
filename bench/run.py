"""Run the benchmark suite and write CSVs, plots and RESULTS.md.

    .venv/bin/python -m relray.bench.run            # make bench: bench/results/, bench/RESULTS.md
    .venv/bin/python -m relray.bench.run --quick    # make bench-quick: bench/results/quick/

Sections (``--only a,b``): ``throughput`` (Cornell throughput and the stage profile),
``scaling`` (1 against 2 threads), ``heavy`` (≥ 1 M triangles), ``beta`` (the |β|
sweep), ``skips`` (the skip table), ``moving`` (the cost of velocity groups),
``convergence`` (error against time, relray against
Cycles, adaptive sampling), ``mitsuba`` (Mitsuba 3 ``scalar_spectral`` and
``llvm_ad_spectral`` as peers: converged agreement, equal-error CPU time and paths per
CPU-second at 1 thread; Mitsuba runs in its own venv from ``make mitsuba-venv``, a
variant that cannot start is reported with its reason), ``peer_scenes`` (the heavy,
the environment-lit and the textured scenes against Mitsuba 3 and Cycles),
``peer_load`` (the heavy mesh's load + BVH time against Mitsuba's).  Cycles needs ``bpy`` (5.0.1)
in the environment; without it the Cycles series are left out and RESULTS.md says so.
Generated meshes and cached references go to ``OUT/tmp`` (git-ignored).
``python -m relray.bench.report --out OUT`` rewrites the plots and RESULTS.md from the
CSVs without rendering.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from relray.bench import common as cm
from relray.bench import (
    convergence,
    embree_floor,
    environment,
    first_render,
    mitsuba_peer,
    moving_rays,
    path_floor,
    peer_scenes,
    profile_scenes,
    report,
    skips,
    textures,
    throughput,
    velocity_groups,
)

SECTIONS = ("throughput", "scaling", "heavy", "beta", "skips", "moving", "environment",
            "textures", "first", "profiles", "convergence", "mitsuba", "peer_scenes",
            "peer_load")
BETAS = [0.0, 0.5, 0.9, 0.99, 0.999]


@dataclass
class Plan:
    """Sizes of every section; :data:`FULL`, :data:`QUICK` and :data:`SMOKE` below."""

    name: str
    tp_size: int = 256
    tp_spp: int = 64
    tp_repeat: int = 3
    scale_spp: int = 32
    scale_repeat: int = 3
    heavy_triangles: int = 1_000_000
    profile_size: int = 128  # the per-scene profiles (bench/profile_scenes.py), 1 thread
    profile_spp: int = 16
    heavy_size: int = 256
    heavy_spp: int = 16
    heavy_repeat: int = 3
    beta_size: int = 128
    beta_spp: int = 16
    beta_ref_factor: int = 16
    beta_repeat: int = 3
    skip_size: int = 128
    skip_spp: int = 16
    skip_ref_spp: int = 256
    skip_repeat: int = 3
    moving_size: int = 128
    moving_spp: int = 16
    moving_repeat: int = 5
    moving_pairs: int = 41
    moving_rays: int = 200_000
    env_size: tuple[int, int] = (96, 64)
    env_spp: tuple[int, ...] = (4, 8, 16, 32, 64)
    env_bsdf_spp: tuple[int, ...] = (16, 64, 256, 1024)
    env_ref_spp: int = 2048
    env_repeat: int = 2
    tex_size: int = 128
    tex_spp: int = 16
    tex_rounds: int = 3
    first_render: bool = True  # three Blender sessions, two of them compiling kernels
    # the untextured Cornell box against the code before the second wave (its kernels
    # compile in a child process first: a minute)
    tex_baseline: bool = True
    anim_frames: int = 24
    anim_separate: int = 24
    anim_spp: int = 16
    floor_rays: int = 1 << 18
    wait_idle_s: float = 600.0
    probe_s: float = 0.4
    conv: convergence.ConvergenceConfig = field(default_factory=convergence.ConvergenceConfig)
    mitsuba: mitsuba_peer.MitsubaConfig = field(default_factory=mitsuba_peer.MitsubaConfig)
    peers: peer_scenes.PeerScenesConfig = field(
        default_factory=peer_scenes.PeerScenesConfig)


FULL = Plan("full")
QUICK = Plan("quick", tp_size=256, tp_spp=8, tp_repeat=3, scale_spp=8, scale_repeat=1,
             profile_size=64, profile_spp=4,
             heavy_size=128, heavy_spp=8, heavy_repeat=1, beta_size=48, beta_spp=8,
             beta_repeat=1, skip_size=64, skip_spp=8, skip_ref_spp=128, skip_repeat=2,
             moving_size=64, moving_spp=8, moving_repeat=2, moving_pairs=4,
             moving_rays=20_000, env_size=(48, 32),
             env_spp=(4, 16), env_bsdf_spp=(16, 256), env_ref_spp=512, env_repeat=1,
             tex_size=64, tex_spp=8, tex_rounds=2, first_render=False, tex_baseline=False,
             anim_frames=8, anim_spp=2, anim_separate=1, wait_idle_s=0.0,
             conv=convergence.ConvergenceConfig(width=64, height=64,
                                                spp=[4, 8, 16, 32, 64, 128],
                                                thresholds=[0.1, 0.05], repeats=2,
                                                ref_factor=8),
             mitsuba=mitsuba_peer.MitsubaConfig(width=64, height=64, spp=[4, 16, 64],
                                                repeats=2, ref_spp=1024, tp_size=128,
                                                tp_spp=4, tp_repeats=2),
             peers=peer_scenes.PeerScenesConfig(width=48, height=48, spp=[4, 16],
                                                repeats=2, ref_spp=256,
                                                heavy_triangles=200_000, load_repeats=1,
                                                orientation_size=32, orientation_spp=64))
SMOKE = Plan("smoke", tp_size=16, tp_spp=2, tp_repeat=1, scale_spp=2, scale_repeat=1,
             profile_size=8, profile_spp=1,
             heavy_triangles=20_000, heavy_size=16, heavy_spp=2, heavy_repeat=1,
             beta_size=8, beta_spp=2, beta_ref_factor=2, beta_repeat=1, skip_size=8,
             skip_spp=2, skip_ref_spp=4, skip_repeat=1, moving_size=8, moving_spp=2,
             moving_repeat=1, moving_pairs=2, moving_rays=2_000, env_size=(8, 8),
             env_spp=(1, 2), env_bsdf_spp=(2, 4),
             env_ref_spp=8, env_repeat=1, tex_size=8, tex_spp=1, tex_rounds=1,
             tex_baseline=False,
             first_render=False, anim_frames=0, anim_separate=0,
             anim_spp=1, wait_idle_s=0.0, probe_s=0.05, floor_rays=1 << 10,
             conv=convergence.ConvergenceConfig(width=8, height=8, spp=[1, 2, 4],
                                                thresholds=[0.5], repeats=1, ref_factor=2),
             mitsuba=mitsuba_peer.MitsubaConfig(width=8, height=8, spp=[4, 16], repeats=1,
                                                ref_spp=64, ref_threads=1, tp_size=8,
                                                tp_spp=4, tp_repeats=1),
             peers=peer_scenes.PeerScenesConfig(width=8, height=8, spp=[4, 16], repeats=1,
                                                ref_spp=16, ref_threads=1,
                                                heavy_triangles=20_000, load_repeats=1,
                                                orientation_spp=0))


def run(plan: Plan, out: Path, md: Path | None, sections: tuple[str, ...] = SECTIONS,
        use_cycles: bool = True, use_mitsuba: bool = True, log=print) -> dict[str, Any]:
    """Run ``sections`` of ``plan``; write CSVs and meta.json into ``out``, then the report."""
    out.mkdir(parents=True, exist_ok=True)
    tmp = out / "tmp"
    tmp.mkdir(exist_ok=True)
    threads = os.cpu_count() or 1
    meta: dict[str, Any] = {"sections": {}}
    if (out / "meta.json").exists() and set(sections) != set(SECTIONS):
        meta = json.loads((out / "meta.json").read_text())  # a partial rerun: keep the rest
    meta.update({"plan": plan.name, "machine": cm.machine_info(), "threads": threads,
                 "command": " ".join(["python -m relray.bench.run", *sys.argv[1:]])})
    t_start = time.perf_counter()
    log(f"relray bench ({plan.name}) -> {out}; load {meta['machine']['load_average']}")
    cm.warm_up()
    meta["cpu_share_start"] = cm.cpu_share(seconds=plan.probe_s)

    def section(name: str):
        meta["sections"][name] = {"load_before": cm.load_average(), "t0": time.perf_counter(),
                                  "date": time.strftime("%Y-%m-%d %H:%M"),
                                  "cpu": f"{cm.cpu_model()} ({cm.cpu_isa()})",
                                  "python_loop_s": cm.interpreter_seconds()}
        log(f"[{name}] load {cm.load_average()[0]:.2f}")

    def done(name: str, **extra: Any) -> None:
        s = meta["sections"][name]
        s["seconds"] = time.perf_counter() - s.pop("t0")
        s["load_after"] = cm.load_average()
        s.update(extra)

    if "throughput" in sections:
        idle = cm.wait_for_idle(timeout=plan.wait_idle_s, log=log) if plan.wait_idle_s else {}
        section("throughput")
        meta["sections"]["throughput"]["wait"] = idle
        cornell = cm.RelrayBench(cm.make_job(cm.job_dict()))
        rows = []
        for mode in ("cie1931", "rgb"):
            m = throughput.measure_bench(cornell, 1, plan.tp_repeat, profile=True,
                                         spp=plan.tp_spp, width=plan.tp_size,
                                         height=plan.tp_size, spectral=mode)
            m.update({"scene": "cornell", "mode": mode, "width": plan.tp_size,
                      "height": plan.tp_size, "spp": plan.tp_spp})
            rows.append(m)
        cm.write_csv(out / "throughput.csv", rows)
        cm.write_csv(out / "profile.csv", throughput.profile_table(rows[0]))
        cm.write_csv(out / "embree_floor.csv", [
            embree_floor.measure(cornell.prep("cie1931").accel, cornell.scene.triangles,
                                 rays=plan.floor_rays)])
        size = min(plan.tp_size, 128)
        cm.write_csv(out / "shade_breakdown.csv",
                     throughput.shade_breakdown(cornell, size, size,
                                                fastmath=plan.name == "full"))
        done("throughput")
    if "scaling" in sections:
        idle = cm.wait_for_idle(timeout=plan.wait_idle_s, log=log) if plan.wait_idle_s else {}
        section("scaling")
        meta["sections"]["scaling"]["wait"] = idle
        meta["sections"]["scaling"]["cpu_share"] = cm.cpu_share(seconds=plan.probe_s)
        cornell = cm.RelrayBench(cm.make_job(cm.job_dict()))
        rows = throughput.thread_scaling(cornell, plan.scale_spp, plan.tp_size, plan.tp_size,
                                         plan.scale_repeat, (1, threads) if threads > 1 else (1,),
                                         probe_s=plan.probe_s)
        cm.write_csv(out / "scaling.csv", rows)
        done("scaling")
    if "heavy" in sections:
        section("heavy")
        rows = throughput.heavy_scene(tmp, plan.heavy_triangles, plan.heavy_spp,
                                      plan.heavy_size, plan.heavy_size, 1, plan.heavy_repeat)
        cm.write_csv(out / "heavy.csv", rows)
        done("heavy")
    if "beta" in sections:
        section("beta")
        rows = throughput.beta_sweep(None, BETAS, plan.beta_spp, plan.beta_ref_factor,
                                     plan.beta_size, plan.beta_size, threads, plan.beta_repeat)
        cm.write_csv(out / "beta_sweep.csv", rows)
        done("beta")
    if "skips" in sections:
        section("skips")
        rows = skips.variant_rows(plan.skip_spp, plan.skip_size, plan.skip_size, threads,
                                  plan.skip_repeat, plan.skip_ref_spp, tmp)
        if plan.anim_frames:
            rows += skips.animation_rows(tmp, plan.anim_frames, plan.anim_separate,
                                         plan.anim_spp, threads)
        if (out / "heavy.csv").exists():
            rows.append(skips.heavy_prepare_row(cm.read_csv(out / "heavy.csv"),
                                                plan.anim_frames))
        cm.write_csv(out / "skips.csv", rows)
        done("skips")
    if "moving" in sections:
        section("moving")
        rows = velocity_groups.group_rows(plan.moving_spp, plan.moving_size, plan.moving_size,
                                          threads, plan.moving_repeat)
        cm.write_csv(out / "velocity_groups.csv", rows)
        cm.write_csv(out / "velocity_group_pairs.csv", velocity_groups.pair_rows(
            plan.moving_spp, plan.moving_size, plan.moving_size, threads,
            plan.moving_pairs))
        cm.write_csv(out / "moving_emitter_noise.csv",
                     velocity_groups.noise_rows(plan.moving_spp, plan.moving_size,
                                                plan.moving_size, threads))
        cm.write_csv(out / "moving_rays.csv", [
            {"query": k, "ns_per_ray": v, "rays": plan.moving_rays}
            for k, v in moving_rays.ray_costs(plan.moving_rays).items()])
        done("moving")
    if "environment" in sections:
        section("environment")
        cm.write_csv(out / "environment_nee.csv", environment.rows(
            *plan.env_size, list(plan.env_spp), list(plan.env_bsdf_spp), plan.env_ref_spp,
            threads, plan.env_repeat))
        done("environment")
    if "textures" in sections:
        section("textures")
        cm.write_csv(out / "textures.csv", textures.rows(plan.tex_spp, plan.tex_size,
                                                         threads, plan.tex_rounds))
        if plan.tex_baseline:
            cm.write_csv(out / "textures_baseline.csv",
                         textures.second_wave_rows(tmp, 16, max(plan.tex_rounds, 5)))
        done("textures")
    if "first" in sections and plan.first_render:
        section("first")
        cm.write_csv(out / "first_render.csv", first_render.rows())
        cm.write_csv(out / "viewport_first.csv", first_render.viewport_rows())
        cm.write_csv(out / "first_cli.csv", first_render.cli_rows())
        done("first")
    if "profiles" in sections:
        section("profiles")
        cm.write_csv(out / "profile_scenes.csv",
                     profile_scenes.rows(tmp, plan.profile_spp, plan.profile_size,
                                         plan.heavy_triangles))
        cm.write_csv(out / "path_floor.csv",
                     path_floor.rows(tmp, plan.profile_size, plan.profile_spp,
                                     plan.heavy_triangles))
        done("profiles")
    if "convergence" in sections:
        section("convergence")
        cfg = plan.conv
        cfg.threads = threads
        res = convergence.run(cfg, tmp, use_cycles=use_cycles, log=log)
        cm.write_csv(out / "convergence_raw.csv", res["raw"])
        cm.write_csv(out / "convergence_medians.csv", res["medians"])
        cm.write_csv(out / "converged_compare.csv", res["converged"])
        cm.write_csv(out / "adaptive_diagnosis.csv", res["diagnosis"])
        cm.write_csv(out / "equal_error.csv", convergence.equal_error(res["medians"], cfg.spp))
        report.plot_converged(res["refs"], out / "converged.png")
        gain = convergence.adaptive_gain(res["medians"], "cpu_s")
        gain += convergence.adaptive_gain(res["medians"], "wall_s")
        cm.write_csv(out / "adaptive_gain.csv", gain)
        done("convergence", config=res["config"], cycles_version=res["cycles_version"],
             ref_seconds=res["ref_seconds"])
    if "mitsuba" in sections:
        section("mitsuba")
        mcfg = plan.mitsuba
        if not use_mitsuba:
            mcfg = replace(mcfg, variants=())
        res = mitsuba_peer.run(mcfg, tmp, log=log)
        if not use_mitsuba:
            res["status"] = [{"variant": v, "ran": False, "reason": "left out (--no-mitsuba)",
                              "version": ""} for v in mitsuba_peer.VARIANTS]
        for name in ("status", "converged", "raw", "medians", "equal_error", "throughput",
                     "throughput_raw"):
            cm.write_csv(out / f"mitsuba_{name}.csv", res[name])
        report.plot_mitsuba_converged(res["refs"], out / "mitsuba_converged.png")
        done("mitsuba", config=res["config"], simd=mitsuba_peer.simd(),
             versions={r["variant"]: r["version"] for r in res["status"]})
    if "peer_scenes" in sections:
        _run_peer_scenes(plan, out, tmp, use_cycles, use_mitsuba, section, done, log)
    if "peer_load" in sections:
        section("peer_load")
        cfg = plan.peers
        raw = peer_scenes.load_times(tmp, cfg.heavy_triangles, cfg.load_repeats,
                                     cfg.variants if use_mitsuba else (), log=log)
        cm.write_csv(out / "peer_load_raw.csv", raw)
        cm.write_csv(out / "peer_load.csv", peer_scenes.load_medians(raw))
        done("peer_load", repeats=cfg.load_repeats, triangles=cfg.heavy_triangles)
    meta["cpu_share_end"] = cm.cpu_share(seconds=plan.probe_s)
    meta["load_end"] = cm.load_average()
    meta["total_seconds"] = time.perf_counter() - t_start
    (out / "meta.json").write_text(json.dumps(meta, indent=1, default=str))
    if md is not None:
        report.write(out, md)
        log(f"wrote {md}")
    log(f"done in {meta['total_seconds']:.0f} s")
    return meta


def _run_peer_scenes(plan: Plan, out: Path, tmp: Path, use_cycles: bool, use_mitsuba: bool,
                     section, done, log) -> None:
    """The ``peer_scenes`` section: the heavy, environment-lit, textured and moving scenes
    against Mitsuba 3 and Cycles (:mod:`.peer_scenes`), CSVs ``peer_*.csv`` and the
    ``peer_converged*.png`` plots."""
    section("peer_scenes")
    cfg = plan.peers
    if not use_mitsuba:
        cfg = replace(cfg, variants=())
    if not use_cycles:
        cfg = replace(cfg, cycles=False)
    res = peer_scenes.run(replace(cfg, load_repeats=0), tmp, log=log)  # (section peer_load)
    if not use_mitsuba:
        res["status"] += [{"scene": s, "peer": v, "ran": False,
                           "reason": "left out (--no-mitsuba)", "version": ""}
                          for s in cfg.scenes for v in mitsuba_peer.VARIANTS]
    for name in ("status", "converged", "raw", "medians", "equal_error", "orientation"):
        cm.write_csv(out / f"peer_{name}.csv", res[name])
    for scenes, png in ((("heavy", "environment"), "peer_converged.png"),
                        (("textured",), "peer_converged_textured.png"),
                        (("moving",), "peer_converged_moving.png")):
        report.plot_peer_converged({k: v for k, v in res["refs"].items()
                                    if k.split("_", 1)[0] in scenes}, out / png)
    done("peer_scenes", config=res["config"], simd=mitsuba_peer.simd())


def main(argv: list[str] | None = None) -> None:
    """The command line (module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="the < 3 minute configuration")
    ap.add_argument("--out", type=Path, help="folder for CSVs and plots")
    ap.add_argument("--md", type=Path, help="RESULTS.md to write")
    ap.add_argument("--only", help=f"comma-separated sections of {','.join(SECTIONS)}")
    ap.add_argument("--no-cycles", action="store_true", help="leave Cycles out")
    ap.add_argument("--no-mitsuba", action="store_true", help="leave Mitsuba 3 out")
    a = ap.parse_args(argv)
    plan = QUICK if a.quick else FULL
    out = a.out or (cm.RESULTS / "quick" if a.quick else cm.RESULTS)
    md = a.md or (out / "RESULTS.md" if a.quick else cm.REPO / "bench" / "RESULTS.md")
    sections = tuple(a.only.split(",")) if a.only else SECTIONS
    bad = set(sections) - set(SECTIONS)
    if bad:
        ap.error(f"unknown sections {sorted(bad)}; choose from {SECTIONS}")
    run(plan, out, md, sections, use_cycles=not a.no_cycles, use_mitsuba=not a.no_mitsuba)


if __name__ == "__main__":
    main()
