"""Error against time on the Cornell box: relray (β = 0) against Cycles, and adaptive sampling.

Series (each against its *own* converged reference, ``ref_factor`` × the largest spp,
rendered with another seed):

- ``relray``: plain sampling at each spp of the ladder;
- ``relray adaptive``: ``noise_threshold`` t over a ladder of thresholds at a fixed cap
  (the largest spp): the curve a user gets by turning the threshold knob;
- ``cycles``: Cycles without adaptive sampling at each spp;
- ``cycles adaptive``: Cycles' adaptive sampling (threshold 0.01, Blender's default)
  with the spp as its cap.

Runs are interleaved per ladder step (relray, cycles, cycles adaptive, then the adaptive
relray runs), the whole ladder ``repeats`` times with seeds 0, 1, …; the tables use the
medians of time and error over the repeats.  Both renderers use ``threads`` threads.
The converged images are also compared with each other (ΔE00), for full global
illumination and for direct light only (max_depth 2 = Cycles' 0 bounces).
"""

from __future__ import annotations

import hashlib
import statistics
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from relray.bench import common as cm
from relray.bench.cycles_anchor import CyclesWorker, bpy_available, cycles_bounces, scene_npz
from relray.core.render import frames as render


@dataclass
class ConvergenceConfig:
    """Sizes and ladders of one convergence run."""

    width: int = 128
    height: int = 128
    spp: list[int] = field(default_factory=lambda: [4, 8, 16, 32, 64, 128, 256])
    thresholds: list[float] = field(
        default_factory=lambda: [0.2, 0.14, 0.1, 0.07, 0.05, 0.035, 0.025])
    repeats: int = 3
    ref_factor: int = 16
    threads: int = 2
    max_depth: int = 8
    cycles_threshold: float = 0.01

    @property
    def ref_spp(self) -> int:
        return self.ref_factor * max(self.spp)


def _key(*parts: Any) -> str:
    return hashlib.sha1(repr(parts).encode()).hexdigest()[:12]


def references(cfg: ConvergenceConfig, bench: cm.RelrayBench, cy: CyclesWorker | None,
               tmp: Path, npz: Path | None) -> dict[str, Any]:
    """Converged images: relray and Cycles, full GI and direct only (Cycles' are cached in
    ``tmp`` by scene file hash, settings and Blender version; relray's are rendered)."""
    out: dict[str, Any] = {"seconds": {}}
    for label, depth in (("full", cfg.max_depth), ("direct", 2)):
        r = bench.render(spp=cfg.ref_spp, width=cfg.width, height=cfg.height,
                         threads=cfg.threads, max_depth=depth, seed=1000)
        out[f"relray_{label}"] = r.rgb
        out["seconds"][f"relray_{label}"] = r.wall
        if cy is None or npz is None:
            continue
        key = _key(hashlib.sha1(npz.read_bytes()).hexdigest(), cfg.ref_spp, depth,
                   cy.version, cfg.width, cfg.height)
        cache = tmp / f"cycles_ref_{label}_{key}.npy"
        if cache.exists():
            out[f"cycles_{label}"] = np.load(cache)
            out["seconds"][f"cycles_{label}"] = float("nan")
        else:
            img, wall, _ = cy.render(cfg.ref_spp, tmp / "ref.exr", cfg.threads,
                                     cycles_bounces(depth), seed=1000)
            np.save(cache, img)
            out[f"cycles_{label}"] = img
            out["seconds"][f"cycles_{label}"] = wall
    return out


def compare_converged(refs: dict[str, Any]) -> list[dict[str, Any]]:
    """ΔE00 and mean-colour ratios between relray's and Cycles' converged images."""
    rows = []
    for label in ("direct", "full"):
        a, b = refs.get(f"relray_{label}"), refs.get(f"cycles_{label}")
        if a is None or b is None:
            continue
        de = cm.delta_e00(a, b)
        ma, mb = a.mean(axis=(0, 1)), b.mean(axis=(0, 1))
        rows.append({"light": "direct only" if label == "direct" else "full GI",
                     "de00_mean": float(de.mean()), "de00_median": float(np.median(de)),
                     "de00_p95": float(np.percentile(de, 95)),
                     "rel_mse": cm.rel_mse(a, b),
                     "mean_ratio_r": ma[0] / mb[0], "mean_ratio_g": ma[1] / mb[1],
                     "mean_ratio_b": ma[2] / mb[2],
                     "luminance_ratio": cm.mean_luminance(a) / cm.mean_luminance(b)})
    return rows


def run(cfg: ConvergenceConfig, tmp: Path, use_cycles: bool = True,
        log=print) -> dict[str, Any]:
    """All runs of the module docstring; returns raw rows, medians, refs and the config."""
    tmp.mkdir(parents=True, exist_ok=True)
    bench = cm.RelrayBench(cm.make_job(cm.job_dict(), width=cfg.width, height=cfg.height,
                                     max_depth=cfg.max_depth))
    use_cycles = use_cycles and bpy_available()
    cy = None
    npz = None
    if use_cycles:
        npz = scene_npz(bench.job, bench.scene, cfg.width, cfg.height, tmp / "cornell.npz")
        cy = CyclesWorker(npz, log=tmp / "cycles_worker.log")
        cy.start()
    try:
        if cy is not None:
            cy.render(1, tmp / "warm.exr", cfg.threads)  # warm-up (shaders, BVH)
        log(f"  references: {cfg.ref_spp} spp at {cfg.width}x{cfg.height}")
        refs = references(cfg, bench, cy, tmp, npz)
        raw: list[dict[str, Any]] = []

        def record(series: str, x: float, seed: int, img: np.ndarray, wall: float,
                   cpu: float, spp_mean: float) -> None:
            ref = refs["cycles_full" if series.startswith("cycles") else "relray_full"]
            raw.append({"series": series, "x": x, "seed": seed, "wall_s": wall, "cpu_s": cpu,
                        "spp_mean": spp_mean, "rel_mse": cm.rel_mse(img, ref),
                        "de00": cm.mean_de00(img, ref), "load1": cm.load_average()[0]})

        cap = max(cfg.spp)
        for seed in range(cfg.repeats):
            log(f"  repeat {seed + 1}/{cfg.repeats}")
            for spp in cfg.spp:
                r = bench.render(spp=spp, width=cfg.width, height=cfg.height,
                                 threads=cfg.threads, seed=seed)
                record("relray", spp, seed, r.rgb, r.wall, r.cpu, r.spp_mean)
                if cy is not None:
                    img, wall, cpu = cy.render(spp, tmp / "run.exr", cfg.threads,
                                               cycles_bounces(cfg.max_depth), seed=seed)
                    record("cycles", spp, seed, img, wall, cpu, spp)
                    img, wall, cpu = cy.render(spp, tmp / "run.exr", cfg.threads,
                                               cycles_bounces(cfg.max_depth), adaptive=True,
                                               threshold=cfg.cycles_threshold, seed=seed)
                    record("cycles adaptive", spp, seed, img, wall, cpu, float("nan"))
            for t in cfg.thresholds:
                r = bench.render(spp=cap, width=cfg.width, height=cfg.height,
                                 threads=cfg.threads, seed=seed, noise_threshold=t)
                record("relray adaptive", t, seed, r.rgb, r.wall, r.cpu, r.spp_mean)
        diagnosis = adaptive_diagnosis(bench, cfg, refs["relray_full"])
    finally:
        if cy is not None:
            cy.close()
    return {"raw": raw, "diagnosis": diagnosis, "medians": medians(raw),
            "converged": compare_converged(refs),
            "refs": {k: v for k, v in refs.items() if k != "seconds"},
            "ref_seconds": refs["seconds"], "config": asdict(cfg),
            "cycles_version": cy.version if cy is not None else None}


def adaptive_diagnosis(bench: cm.RelrayBench, cfg: ConvergenceConfig,
                       ref: np.ndarray) -> list[dict[str, Any]]:
    """Why adaptive sampling does (not) pay: per threshold, which pixels stopped early,
    how biased and how noisy they are, against a plain render of the same mean spp.

    Relative luminance errors (x - r) / max(r, 1e-3) per pixel; "stopped" pixels are those
    with fewer samples than the cap.  A stopping rule that judges a pixel by the same
    samples it averages stops the pixels whose first samples happened to agree (missed
    the rare bright paths): they come out too dark (negative bias) and noisier than the
    plain render in the same pixels.  ``Film.converged`` limits this with a first pass of
    ``render.ADAPTIVE_FIRST_PASS`` samples and a 3x3 window; ``bias_stopped_paired`` is
    the luminance of the stopped pixels over that of a plain render at the cap with the
    *same* seed (the same first samples), minus 1: the selection bias alone.
    """
    cap = max(cfg.spp)
    rows = []
    full = bench.render(spp=cap, width=cfg.width, height=cfg.height, threads=cfg.threads,
                        seed=0)
    yf = (full.rgb @ cm.LUMA).ravel()
    for t in cfg.thresholds:
        a = bench.render(spp=cap, width=cfg.width, height=cfg.height, threads=cfg.threads,
                         seed=0, noise_threshold=t)
        n = max(1, int(round(a.spp_mean)))
        p = bench.render(spp=n, width=cfg.width, height=cfg.height, threads=cfg.threads,
                         seed=0)
        spp = a.film.samples_per_pixel.ravel()
        yr = (ref @ cm.LUMA).ravel()

        def rel(img, yr=yr):
            return ((img @ cm.LUMA).ravel() - yr) / np.maximum(yr, 1e-3)

        ra, rp = rel(a.rgb), rel(p.rgb)
        st = spp < cap
        early = spp <= 16
        first = spp <= render.ADAPTIVE_FIRST_PASS
        ya = (a.rgb @ cm.LUMA).ravel()
        paired = float(ya[st].sum() / yf[st].sum() - 1.0) if st.any() else float("nan")

        def rms(x, m):
            return float(np.sqrt(np.mean(x[m] ** 2))) if m.any() else float("nan")

        rows.append({
            "threshold": t, "cap": cap, "mean_spp": a.spp_mean, "plain_spp": n,
            "cpu_adaptive_s": a.cpu, "cpu_plain_s": p.cpu,
            "cpu_per_sample_ratio": (a.cpu / a.spp_mean) / (p.cpu / n),
            "rel_mse_adaptive": cm.rel_mse(a.rgb, ref), "rel_mse_plain": cm.rel_mse(p.rgb, ref),
            "stopped_fraction": float(st.mean()), "stopped_by_16spp": float(early.mean()),
            "stopped_at_first_pass": float(first.mean()), "bias_stopped_paired": paired,
            "bias_stopped": float(ra[st].mean()) if st.any() else float("nan"),
            "bias_stopped_plain": float(rp[st].mean()) if st.any() else float("nan"),
            "rms_stopped": rms(ra, st), "rms_stopped_plain": rms(rp, st),
            "rms_capped": rms(ra, ~st), "rms_capped_plain": rms(rp, ~st)})
    return rows


def medians(raw: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (series, x): medians of time and error over the repeats."""
    groups: dict[tuple[str, float], list[dict[str, Any]]] = {}
    for r in raw:
        groups.setdefault((r["series"], r["x"]), []).append(r)
    out = []
    for (series, x), rs in groups.items():
        row = {"series": series, "x": x, "n": len(rs)}
        for k in ("wall_s", "cpu_s", "spp_mean", "rel_mse", "de00", "load1"):
            row[k] = statistics.median(r[k] for r in rs)
        out.append(row)
    return out


def curve(med: list[dict[str, Any]], series: str, time_key: str,
          err_key: str) -> tuple[list[float], list[float]]:
    """(times, errors) of one series, sorted by time."""
    pts = sorted((r[time_key], r[err_key]) for r in med if r["series"] == series)
    return [p[0] for p in pts], [p[1] for p in pts]


def error_levels(med: list[dict[str, Any]], err_key: str, spp: list[int]) -> list[float]:
    """Two error levels that both plain curves reach (so no ratio is extrapolated).

    The high level is what Cycles (else relray) reaches at the 2nd spp of the ladder; the
    low level is the larger of the two curves' lowest errors, i.e. the lowest error
    that both renderers reached within the ladder.
    """
    have = {r["series"] for r in med}
    anchor = "cycles" if "cycles" in have else "relray"
    by_x = {r["x"]: r[err_key] for r in med if r["series"] == anchor}
    high = by_x[spp[1]] if len(spp) > 1 else by_x[spp[0]]
    low = max(min(r[err_key] for r in med if r["series"] == s)
              for s in ("relray", anchor))
    return [high, low] if low < high else [high]


def equal_error(med: list[dict[str, Any]], spp: list[int]) -> list[dict[str, Any]]:
    """Time ratios A / B at equal error, for both metrics and both clocks.

    Pairs: relray vs cycles; relray vs cycles adaptive; relray adaptive vs cycles
    adaptive; relray adaptive vs relray.  Plain curves may be extrapolated by their end
    points' power law (flagged); adaptive curves flatten at their spp cap, so a level
    outside them is reported as not reached (NaN).
    """
    rows = []
    have = {r["series"] for r in med}
    pairs = [(a, b) for a, b in (("relray", "cycles"), ("relray", "cycles adaptive"),
                                 ("relray adaptive", "cycles adaptive"),
                                 ("relray adaptive", "relray")) if a in have and b in have]
    for err_key in ("rel_mse", "de00"):
        for lvl_i, level in enumerate(error_levels(med, err_key, spp)):
            for time_key in ("wall_s", "cpu_s"):
                for a, b in pairs:
                    ta, xa = cm.time_at_error(*curve(med, a, time_key, err_key), level,
                                              extrapolate="adaptive" not in a)
                    tb, xb = cm.time_at_error(*curve(med, b, time_key, err_key), level,
                                              extrapolate="adaptive" not in b)
                    rows.append({"metric": err_key, "level_index": lvl_i, "level": level,
                                 "clock": time_key, "a": a, "b": b, "time_a_s": ta,
                                 "time_b_s": tb, "ratio_a_over_b": ta / tb,
                                 "extrapolated": bool(xa or xb)})
    return rows


def adaptive_gain(med: list[dict[str, Any]], time_key: str = "cpu_s") -> list[dict[str, Any]]:
    """For each adaptive run: its error over the plain curve's error at the same time.

    The plain curve is interpolated in log-log; < 1 means adaptive sampling wins at equal
    time.  Outside the plain curve's time range the power law of its end points is used.
    """
    rows = []
    for a, b in (("relray adaptive", "relray"), ("cycles adaptive", "cycles")):
        for err_key in ("rel_mse", "de00"):
            tb, eb = curve(med, b, time_key, err_key)
            if len(tb) < 2:
                continue
            lt, le = np.log(tb), np.log(eb)
            for r in (r for r in med if r["series"] == a):
                x = np.log(r[time_key])
                i = int(np.clip(np.searchsorted(lt, x) - 1, 0, len(lt) - 2))
                f = (x - lt[i]) / (lt[i + 1] - lt[i])
                plain = float(np.exp(le[i] + f * (le[i + 1] - le[i])))
                rows.append({"series": a, "x": r["x"], "metric": err_key, "clock": time_key,
                             "time_s": r[time_key], "error": r[err_key],
                             "plain_error_at_same_time": plain,
                             "ratio": r[err_key] / plain,
                             "inside_plain_range": bool(lt[0] <= x <= lt[-1])})
    return rows
