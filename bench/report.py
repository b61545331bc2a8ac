"""Plots and RESULTS.md from the CSVs and meta.json that :mod:`relray.bench.run` writes.

    .venv/bin/python -m relray.bench.report --out bench/results --md bench/RESULTS.md

Only what is in ``OUT`` is reported (a section that was not run is listed as missing).
The plots are PNGs next to the CSVs; RESULTS.md links them relative to its own folder.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import statistics
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from relray.bench import common as cm

GOAL_PATHS = 1.5e6
GOAL_EMBREE = 0.5
GOAL_SCALING = 1.8
GOAL_RATIO = 0.5
GOAL_BETA = 1.2
SERIES_STYLE = {"relray": ("tab:blue", "o-"), "relray adaptive": ("tab:cyan", "s--"),
                "cycles": ("tab:red", "o-"), "cycles adaptive": ("tab:orange", "s--")}


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


# ----------------------------------------------------------------------------- plots
def _display(rgb: np.ndarray) -> np.ndarray:
    """Linear Rec.709 → sRGB-encoded [0, 1] (the 'Standard' view) for a figure."""
    x = np.clip(rgb, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def plot_converged(refs: dict[str, np.ndarray], path: Path) -> Path | None:
    """relray's and Cycles' converged images and their ΔE00 map, full GI and direct."""
    rows = [k for k in ("full", "direct") if f"cycles_{k}" in refs and f"relray_{k}" in refs]
    if not rows:
        return None
    plt = _plt()
    fig, ax = plt.subplots(len(rows), 3, figsize=(9, 3.1 * len(rows)), squeeze=False)
    for i, k in enumerate(rows):
        a, b = refs[f"relray_{k}"], refs[f"cycles_{k}"]
        de = cm.delta_e00(a, b)
        ax[i, 0].imshow(_display(a))
        ax[i, 0].set_title(f"relray ({k})")
        ax[i, 1].imshow(_display(b))
        ax[i, 1].set_title(f"Cycles ({k})")
        im = ax[i, 2].imshow(de, cmap="magma", vmin=0, vmax=5)
        ax[i, 2].set_title(f"ΔE00 (mean {de.mean():.2f})")
        fig.colorbar(im, ax=ax[i, 2], fraction=0.046)
        for x in ax[i]:
            x.set_xticks([])
            x.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _series_panel(a, med: list[dict[str, Any]], clock: str, err: str, xlabel: str,
                  ylabel: str) -> None:
    """One log-log panel: every series of SERIES_STYLE that has points, error against time."""
    for series, (colour, style) in SERIES_STYLE.items():
        t, e = _curve(med, series, clock, err)
        if t:
            a.loglog(t, e, style, color=colour, label=series, ms=4)
    a.set_xlabel(xlabel)
    a.set_ylabel(ylabel)
    a.grid(True, which="both", lw=0.3)


def plot_convergence(med: list[dict[str, Any]], eq: list[dict[str, Any]], path: Path) -> Path:
    """Error against time, log-log: (relative MSE, ΔE00) × (wall, CPU)."""
    plt = _plt()
    fig, ax = plt.subplots(2, 2, figsize=(10, 8))
    for i, (err, elabel) in enumerate((("rel_mse", "relative MSE"), ("de00", "mean ΔE00"))):
        for j, (clock, clabel) in enumerate((("wall_s", "wall time (s)"),
                                              ("cpu_s", "CPU time (s)"))):
            a = ax[i, j]
            _series_panel(a, med, clock, err, clabel, elabel)
            for lvl in sorted({r["level"] for r in eq if r["metric"] == err}):
                a.axhline(lvl, color="grey", lw=0.6, ls=":")
    ax[0, 0].legend()
    fig.suptitle("Cornell box, β = 0: error against time (medians; dotted: equal-error levels)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_adaptive(med: list[dict[str, Any]], path: Path) -> Path:
    """Adaptive against plain sampling at equal CPU time, both renderers."""
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(10, 4.2))
    for a, (err, elabel) in zip(ax, (("rel_mse", "relative MSE"), ("de00", "mean ΔE00")),
                                strict=True):
        _series_panel(a, med, "cpu_s", err, "CPU time (s)", elabel)
        for r in (r for r in med if r["series"] == "relray adaptive"):
            a.annotate(f"t={r['x']:g}", (r["cpu_s"], r[err]), fontsize=7,
                       xytext=(3, 3), textcoords="offset points")
    ax[0].legend()
    fig.suptitle("Adaptive sampling: noise_threshold t at a fixed spp cap vs plain spp")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_beta(rows: list[dict[str, Any]], path: Path) -> Path:
    """Time per spp and error at fixed spp against |β|."""
    plt = _plt()
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for d in dict.fromkeys(r["direction"] for r in rows):
        rs = [r for r in rows if r["direction"] == d]
        x = np.arange(len(rs))
        ax[0].plot(x, [r["cpu_per_spp_vs_beta0"] for r in rs], "o-", label=d)
        # an image that is black in the visible has no error to show: leave it out
        ax[1].semilogy(x, [r["rel_mse"] if r["rel_mse"] > 0 else np.nan for r in rs], "o-",
                       label=d)
        for a in ax:
            a.set_xticks(x, [f"{r['beta']:g}" for r in rs])
    ax[0].axhline(GOAL_BETA, color="grey", ls=":", lw=0.8)
    ax[0].set_ylabel("CPU time per spp / β = 0")
    ax[1].set_ylabel(f"relative MSE at {rows[0]['spp']} spp")
    for a in ax:
        a.set_xlabel("|β|")
        a.grid(True, lw=0.3)
    ax[0].legend()
    fig.suptitle("β sweep (camera inside the closed Cornell box)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_profile(rows: list[dict[str, Any]], path: Path) -> Path:
    """Horizontal bars: share of the CPU time per stage."""
    plt = _plt()
    rows = [r for r in rows if r["share"] > 0.0005]
    fig, ax = plt.subplots(figsize=(8, 0.3 * len(rows) + 1))
    y = np.arange(len(rows))[::-1]
    ax.barh(y, [100 * r["share"] for r in rows],
            color=["tab:green" if r["stage"].startswith("Embree") else "tab:blue" for r in rows])
    ax.set_yticks(y, [r["stage"] for r in rows], fontsize=8)
    ax.set_xlabel("% of the render's CPU time (1 thread)")
    ax.grid(True, axis="x", lw=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _curve(med, series, clock, err):
    pts = sorted((r[clock], r[err]) for r in med if r["series"] == series
                 and r[clock] > 0 and r[err] > 0)
    return [p[0] for p in pts], [p[1] for p in pts]


# ----------------------------------------------------------------------------- tables
def table(rows: Sequence[dict[str, Any]], cols: Sequence[tuple[str, Any, str]]) -> str:
    """A markdown table; each column is (header, key or function of the row, format)."""
    head = "| " + " | ".join(c[0] for c in cols) + " |"
    sep = "|" + "|".join("---" for _ in cols) + "|"
    lines = [head, sep]
    for r in rows:
        cells = []
        for _, key, fmt in cols:
            v = key(r) if callable(key) else r.get(key, "")
            cells.append(_f(v, fmt))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _f(v: Any, fmt: str) -> str:
    if v is None or v == "":
        return "–"
    if isinstance(v, float) and math.isnan(v):
        return "–"
    try:
        return format(v, fmt) if fmt else str(v)
    except (TypeError, ValueError):
        return str(v)


def _read(out: Path, name: str) -> list[dict[str, Any]]:
    p = out / f"{name}.csv"
    return cm.read_csv(p) if p.exists() else []


def _rel(md: Path, p: Path) -> str:
    return os.path.relpath(p, md.parent)


def _fit(med: list[dict[str, Any]], series: str, clock: str) -> tuple[float, float]:
    """Least-squares time = overhead + per_spp · spp over a plain series."""
    pts = [(r["x"], r[clock]) for r in med if r["series"] == series]
    if len(pts) < 2:
        return math.nan, math.nan
    x, y = np.array(pts, np.float64).T
    b, a = np.polyfit(x, y, 1)
    return float(a), float(b)


# ----------------------------------------------------------------------------- report
def write(out: Path, md: Path) -> Path:
    """Render the plots and RESULTS.md from the CSVs in ``out``."""
    out, md = Path(out), Path(md)
    meta = json.loads((out / "meta.json").read_text()) if (out / "meta.json").exists() else {}
    d = {name: _read(out, name) for name in (
        "throughput", "profile", "scaling", "heavy", "beta_sweep", "skips",
        "convergence_medians", "equal_error", "converged_compare", "adaptive_gain",
        "shade_breakdown", "adaptive_diagnosis", "embree_floor", "velocity_groups",
        "velocity_group_pairs", "moving_rays",
        "moving_emitter_noise", "environment_nee", "first_render", "viewport_first",
        "first_cli", "profile_scenes", "path_floor",
        "textures", "textures_baseline", "mitsuba_status", "mitsuba_converged",
        "mitsuba_medians", "mitsuba_equal_error", "mitsuba_throughput", "peer_status",
        "peer_converged", "peer_medians", "peer_equal_error", "peer_load",
        "peer_orientation")}
    conv_cfg = meta.get("sections", {}).get("convergence", {}).get("config")
    if d["convergence_medians"] and conv_cfg:
        # derived tables: recomputed from the medians, so they follow this module's rules
        from relray.bench import convergence

        med = d["convergence_medians"]
        d["equal_error"] = convergence.equal_error(med, conv_cfg["spp"])
        d["adaptive_gain"] = (convergence.adaptive_gain(med, "cpu_s")
                              + convergence.adaptive_gain(med, "wall_s"))
        cm.write_csv(out / "equal_error.csv", d["equal_error"])
        cm.write_csv(out / "adaptive_gain.csv", d["adaptive_gain"])
    plots: dict[str, Path] = {}
    if d["convergence_medians"]:
        plots["convergence"] = plot_convergence(d["convergence_medians"], d["equal_error"],
                                                out / "convergence.png")
        plots["adaptive"] = plot_adaptive(d["convergence_medians"], out / "adaptive.png")
    if d["beta_sweep"]:
        plots["beta"] = plot_beta(d["beta_sweep"], out / "beta_sweep.png")
    if d["profile"]:
        plots["profile"] = plot_profile(d["profile"], out / "profile.png")
    if (out / "converged.png").exists():
        plots["converged"] = out / "converged.png"
    if (out / "mitsuba_converged.png").exists() and d["mitsuba_status"]:
        plots["mitsuba_converged"] = out / "mitsuba_converged.png"
    if (out / "peer_converged.png").exists() and d["peer_status"]:
        plots["peer_converged"] = out / "peer_converged.png"
    for name in ("peer_converged_textured", "peer_converged_moving"):
        if (out / f"{name}.png").exists() and d["peer_status"]:
            plots[name] = out / f"{name}.png"
    text = _markdown(meta, d, plots, out, md)
    md.parent.mkdir(parents=True, exist_ok=True)
    md.write_text(text)
    return md


def headline(d: dict[str, list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """The goals of issue 4 against the measured figures (rows for the table and README)."""
    rows = []
    tp = [r for r in d["throughput"] if r.get("mode") == "cie1931"]
    if tp:
        t = tp[0]
        rows.append({"goal": f"Cornell {t['width']}², spectral + NEE, 1 thread: paths per "
                             "CPU-second", "target": "≥ 1.5 M",
                     "measured": f"{t['paths_per_cpu_s'] / 1e6:.2f} M",
                     "met": t["paths_per_cpu_s"] >= GOAL_PATHS})
        # the shadow rays' Embree time inside the shade kernel is estimated (§3's own
        # cost per shadow ray × their count): it cannot be timed apart from the kernel
        share = t["embree_share"] + (shadow_embree_ns(d) or 0.0) * t["paths"] / (
            1e9 * t["cpu_s"])
        how = "shadow rays inside the shade kernel estimated"
        pf = [r for r in d["path_floor"] if r["scene"] == "cornell"]
        if any(r["stage"].startswith("lane-path kernel") and r["seconds"] > 0
               for r in d["profile"]):
            # SIMD lanes: every Embree query is inside the lane kernel; §6 measures Embree
            # alone on the kernel's own packets
            share = pf[0]["lanes_embree_share"] if pf else float("nan")
            how = "SIMD lanes: Embree alone on the lane kernel's packets, §6"
        elif any(r["stage"].startswith("whole-path kernel") and r["seconds"] > 0
                 for r in d["profile"]):
            # whole paths: every Embree query is inside the kernel; §6 measures Embree
            # alone on the kernel's own rays
            share = pf[0]["whole_embree_share"] if pf else float("nan")
            how = "whole paths: Embree alone on the kernel's rays, §6"
        rows.append({"goal": f"Embree's share of the CPU time ({how})", "target": "≥ 50 %",
                     "measured": f"{100 * share:.0f} %", "met": share >= GOAL_EMBREE})
    sc = d["scaling"]
    if len(sc) > 1:
        s2 = sc[-1]
        rows.append({"goal": f"{int(s2['threads'])} threads against 1 (paths per wall-second)",
                     "target": "≥ 1.8× on an idle machine",
                     "measured": f"{s2['speedup_wall']:.2f}× (load {s2['load1']:.1f}, this "
                                 f"process got {100 * s2['cpu_share_before']:.0f} % of "
                                 "the cores)",
                     "met": s2["speedup_wall"] >= GOAL_SCALING})
    eq = d["equal_error"]
    for metric, name in (("rel_mse", "relative MSE"), ("de00", "mean ΔE00")):
        rs = [r for r in eq if r["metric"] == metric and r["a"] == "relray"
              and r["b"] == "cycles" and r["clock"] == "cpu_s"]
        if rs:
            vals = ", ".join(f"{r['ratio_a_over_b']:.2f}" + ("*" if r["extrapolated"] in
                                                              (True, "True") else "")
                             for r in rs)
            rows.append({"goal": f"equal-error time relray / Cycles at β = 0, {name} "
                                 "(CPU time; two levels)", "target": "≤ 0.5",
                         "measured": vals,
                         "met": all(r["ratio_a_over_b"] <= GOAL_RATIO for r in rs
                                if math.isfinite(r["ratio_a_over_b"]))})
            ws = [r for r in eq if r["metric"] == metric and r["a"] == "relray"
                  and r["b"] == "cycles" and r["clock"] == "wall_s"]
            rows.append({"goal": f"… the same in wall time ({name})", "target": "≤ 0.5",
                         "measured": ", ".join(f"{r['ratio_a_over_b']:.2f}" for r in ws),
                         "met": all(r["ratio_a_over_b"] <= GOAL_RATIO for r in ws)})
    bs = [r for r in d["beta_sweep"] if r["beta"] == max(x["beta"] for x in d["beta_sweep"])]
    for r in bs:
        rows.append({"goal": f"CPU time per spp at β = {r['beta']:g} / β = 0 "
                             f"({r['direction']})", "target": "≤ 1.2",
                     "measured": f"{r['cpu_per_spp_vs_beta0']:.2f}",
                     "met": r["cpu_per_spp_vs_beta0"] <= GOAL_BETA})
    return rows


def _pair(vals: Sequence[float]) -> str:
    """Two levels' ratios as "high / low"."""
    return " / ".join(f"{v:.2f}" for v in vals)


def headline_12(d: dict[str, list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """The goals of issue 12 (performance round 2) against the measured figures: goal,
    target, measured, met, and for a goal not met the floor or the cost that stops it
    (the section that measures it)."""
    rows: list[dict[str, Any]] = []
    pf = {r["scene"]: r for r in d["path_floor"]}
    for scene, goal, why in (
            ("cornell", 0.60, "§6: outside Embree the lanes' gathers, Sobol numbers, light "
                              "sample and scalar refill"),
            ("heavy", 0.70, "§6: the hit gathers of 1 M triangles miss the caches")):
        if _num(pf.get(scene, {}).get("lanes_embree_share")):
            share = pf[scene]["lanes_embree_share"]
            rows.append({"goal": f"Embree's share of the CPU time, {scene} (SIMD lanes; "
                                 "Embree alone on their packets, §6)",
                         "target": f"≥ {100 * goal:.0f} %",
                         "measured": f"{100 * share:.1f} %",
                         "met": share >= goal, "stops": why})
    cyc = [r for r in d["equal_error"] if r["metric"] == "rel_mse" and r["a"] == "relray"
           and r["b"] == "cycles" and r["clock"] == "cpu_s"]
    if cyc:
        vals = [r["ratio_a_over_b"] for r in cyc]
        rows.append({"goal": "equal-error CPU time ÷ Cycles, Cornell box (rel. MSE, high / "
                             "low level, §2)", "target": "≤ 0.25", "measured": _pair(vals),
                     "met": all(v <= 0.25 for v in vals),
                     "stops": "the lanes' work outside Embree (§6: the hits, the light "
                              "samples and continuations, the refill) and around the "
                              "kernel the film; not a floor"})
    peer: dict[tuple[str, str], list[float]] = {}
    for scene in ("heavy", "environment", "textured", "moving"):
        for (pe, _level), v in sorted(peer_ratios(d, scene)[0].items()):
            peer.setdefault((scene, pe), []).append(v)
    for r in d["mitsuba_equal_error"]:
        if r["metric"] == "rel_mse":
            peer.setdefault(("cornell", r["peer"]), []).append(
                float(r["ratio_relray_over_peer"]))
    for scene in ("heavy", "environment"):
        vals = peer.get((scene, "cycles"))
        if vals:
            rows.append({"goal": f"equal-error CPU time ÷ Cycles, {scene} scene (§2)",
                         "target": "≤ 0.5", "measured": _pair(vals),
                         "met": all(v <= 0.5 for v in vals), "stops": ""})
    floor = moving_floor_bound(d)
    floor_s = moving_floor_bound(d, "scalar_spectral")
    stops = {
        ("environment", "llvm_ad_spectral"): "the map's lookups in the lanes (§6: sigmoids, "
                                             "searches, escaping rays) and the work around "
                                             "the kernel; not a floor",
        ("environment", "scalar_spectral"): "the same costs as against `llvm_ad_spectral`; "
                                            "the runs scatter by ±10 % (§2)",
        ("heavy", "scalar_spectral"): "at the goal within the runs' ±10 % (§2)",
        ("textured", "llvm_ad_spectral"): "the texture lookups, scalar calls per lane (§6 "
                                          "next steps); not a floor",
        ("moving", "llvm_ad_spectral"): _floor_text(floor, 1.0),
        ("moving", "scalar_spectral"): _floor_text(floor_s, 0.4),
        ("cornell", "llvm_ad_spectral"): "at parity within the runs' ±10 % (§2); what is "
                                         "left is §6's work outside Embree",
    }
    for name, pe, target in (("`llvm_ad_spectral`", "llvm_ad_spectral", 1.0),
                             ("`scalar_spectral`", "scalar_spectral", 0.4)):
        for scene in ("cornell", "heavy", "environment", "textured", "moving"):
            vals = peer.get((scene, pe))
            if not vals:
                continue
            met = all(v <= target for v in vals)
            rows.append({"goal": f"equal-error CPU time ÷ Mitsuba 3 {name}, {scene} (§2)",
                         "target": f"≤ {target:g}", "measured": _pair(vals), "met": met,
                         "stops": "" if met else stops.get((scene, pe), "§2, §6")})
    load = {r["renderer"]: r for r in d["peer_load"]}
    mits = [r for k, r in load.items() if k != "relray"]
    if "relray" in load and mits:
        best = min(float(r["load_s"]) for r in mits)
        rows.append({"goal": "loading a 1 M-triangle mesh and building its BVH (§2)",
                     "target": "no slower than Mitsuba",
                     "measured": f"{load['relray']['load_s']:.2f} s against {best:.2f} s",
                     "met": load["relray"]["load_s"] <= best, "stops": ""})
    sc = d["scaling"]
    if len(sc) > 1:
        s2 = sc[-1]
        rows.append({"goal": "2 threads against 1 (paths per wall-second, §3)",
                     "target": "≥ 1.9×", "measured": f"{s2['speedup_wall']:.2f}×",
                     "met": s2["speedup_wall"] >= 1.9, "stops": ""})
    base = d["textures_baseline"]
    if len(base) == 2:
        r = base[-1]
        rows.append({"goal": "the static, untextured Cornell box against the code "
                             f"{base[0]['code']} (§5e)", "target": "no slower",
                     "measured": f"{r['over_before']:.2f}× its paths per CPU-second",
                     "met": r["over_before"] >= 1.0, "stops": ""})
    warm = [r for r in d["first_cli"] if r["case"] == "warm"]
    if warm:
        w = warm[0]
        cold = [r["wall_s"] for r in d["first_cli"] if r["case"].startswith("cold")]
        f12 = [r["f12_s"] for r in d["first_render"] if r["case"] == "cold, F12 at once"]
        slower = (f" (§5c: the cold command line {cold[0]:.0f} s against 18.3 s at 18:54, "
                  f"Blender's first F12 {f12[0]:.0f} s against 19.2 s, the same kernels)"
                  if cold and f12 else "")
        rows.append({"goal": "first 1-spp Cornell image from `relray render`, warm kernel "
                             "cache (§5c)", "target": "≤ 1 s",
                     "measured": f"{w['wall_s']:.2f} s (imports {w['import_s']:.2f} s)",
                     "met": w["wall_s"] <= 1.0,
                     "stops": "the machine, not a floor: this run's ran everything about "
                              f"twice as slowly as the earlier runs'{slower}; the round's "
                              "garbage-collection change made the warm command line 0.66× "
                              "in alternated pairs (the round's bullets), which would be "
                              "about 0.74 s against the 1.12 s of 18:54: inferred, not "
                              "measured on that machine. Importing numba and loading its "
                              "registries at the first cached kernel take 0.45–1 s of it "
                              "before relray works"})
    return rows


def _markdown(meta: dict[str, Any], d: dict[str, list[dict[str, Any]]],
              plots: dict[str, Path], out: Path, md: Path) -> str:
    mach = meta.get("machine", {})
    secs = meta.get("sections", {})
    quick = meta.get("plan") == "quick"
    make = "make bench-quick" if quick else "make bench"
    L: list[str] = []
    add = L.append
    add(f"# Benchmark results ({meta.get('plan', '?')} run)\n")
    add(f"Produced by `{make}` (`{meta.get('command', 'python -m relray.bench.run')}`) on "
        f"{mach.get('date', '?')}; total {meta.get('total_seconds', math.nan):.0f} s. "
        "Regenerate the text and plots from the CSVs with "
        f"`.venv/bin/python -m relray.bench.report --out "
        f"{os.path.relpath(out.resolve(), cm.REPO)}`.\n")
    la = mach.get("load_average", [math.nan] * 3)
    add("| machine (of the last run; each section's CPU is in the table below) | |\n|---|---|")
    add(f"| CPU | {mach.get('cpu', '?')}, {mach.get('cores', '?')} cores, "
        f"{mach.get('memory', '?')} |")
    add(f"| OS, Python | {mach.get('os', '?')}, Python {mach.get('python', '?')} |")
    add(f"| packages | numpy {mach.get('numpy')}, numba {mach.get('numba')}, embreex "
        f"{mach.get('embreex')}, colour-science {mach.get('colour-science')}, Blender (bpy) "
        f"{secs.get('convergence', {}).get('cycles_version') or '–'} |")
    add(f"| load average at the start (1, 5, 15 min) | {la[0]:.2f}, {la[1]:.2f}, "
        f"{la[2]:.2f} |")
    le = meta.get("load_end", [math.nan] * 3)
    add(f"| load average at the end | {le[0]:.2f}, {le[1]:.2f}, {le[2]:.2f} |")
    add(f"| share of the 2 cores a busy loop got (start, end) | "
        f"{100 * meta.get('cpu_share_start', math.nan):.0f} %, "
        f"{100 * meta.get('cpu_share_end', math.nan):.0f} % |")
    add("")
    add("**The machine is shared** with other engineers' test suites, so wall times and "
        "thread scaling depend on what else runs; every section records the load around "
        "it, runs are interleaved and reduced to medians, and the throughput figures use "
        "CPU time (process CPU clock; stage times from per-thread CPU clocks), which the "
        "other processes disturb much less.\n")
    add(table([{"s": k, **v} for k, v in secs.items()], [
        ("section", "s", ""), ("run at", "date", ""), ("CPU", lambda r: r.get("cpu", "–"), ""),
        ("load before", lambda r: r["load_before"][0], ".2f"),
        ("load after", lambda r: r.get("load_after", [math.nan])[0], ".2f"),
        ("Python loop (ms)", lambda r: 1e3 * r.get("python_loop_s", math.nan), ".0f"),
        ("seconds", "seconds", ".0f")]))
    add("")

    add("## Headline: the goals of issue 4\n")
    hl = headline(d)
    add(table(hl, [("goal", "goal", ""), ("target", "target", ""),
                   ("measured", "measured", ""),
                   ("met", lambda r: "yes" if r["met"] else "**no**", "")]))
    add("\n(* extrapolated beyond the measured curve.)\n")
    h12 = headline_12(d)
    if h12:
        add("## Headline: the goals of issue 12 (performance round 2)\n")
        add("Each goal met, or the floor or the cost that stops it, with the section that "
            "measures it. The equal-error ratios are CPU time at equal relative MSE, at "
            "the two levels of §2 (high / low).\n")
        add(table(h12, [("goal", "goal", ""), ("target", "target", ""),
                        ("measured", "measured", ""),
                        ("met", lambda r: "yes" if r["met"] else "**no**", ""),
                        ("what stops it", lambda r: r["stops"] if not r["met"] else "", "")]))
        add("")

    _section_convergence(add, d, plots, md, meta)
    _section_mitsuba(add, d, plots, md, meta)
    _section_peer_scenes(add, d, plots, md, meta)
    _section_throughput(add, d, plots, md, meta)
    _section_adaptive(add, d, plots, md)
    _section_skips(add, d)
    _section_moving(add, d)
    _section_first(add, d)
    _section_environment(add, d)
    _section_textures(add, d)
    _section_profile(add, d, plots, md, meta)
    _section_recommendations(add, d)
    _section_missing(add, d, meta)
    return "\n".join(L) + "\n"


def _img(add: Callable[[str], None], plots: dict[str, Path], key: str, md: Path,
         alt: str) -> None:
    if key in plots:
        add(f"![{alt}]({_rel(md, plots[key])})\n")


def _section_convergence(add, d, plots, md, meta) -> None:
    add("## 2. Error against time, with Cycles as the anchor\n")
    med = d["convergence_medians"]
    if not med:
        add("Not run.\n")
        return
    cfg = meta.get("sections", {}).get("convergence", {}).get("config", {})
    have_cycles = any(r["series"] == "cycles" for r in med)
    add(f"Cornell box (`presets/cornell.toml`'s geometry and materials), β = 0, "
        f"{cfg.get('width')}×{cfg.get('height')}, max_depth {cfg.get('max_depth')} "
        f"(Cycles: {max(0, cfg.get('max_depth', 8) - 2)} bounces), {cfg.get('threads')} "
        f"threads for both. spp ladder {cfg.get('spp')}, {cfg.get('repeats')} interleaved "
        f"repeats (relray, Cycles, Cycles adaptive per step; seeds 0, 1, …), medians. "
        f"Each renderer against its own reference of {cfg.get('ref_factor')}× the largest "
        f"spp = {cfg.get('ref_factor', 0) * max(cfg.get('spp', [0]))} spp (another seed). "
        "Resolution: the references cost about a minute of CPU each for relray and "
        "two to three for Cycles at 128²; at the largest spp a reference of 16× still "
        "adds 1/16 of the run's variance to its measured error (about 6 %), which is "
        "below the run-to-run spread.\n")
    if not have_cycles:
        add("**Cycles was not run** (`import bpy` failed; `make bench` installs "
            "bpy 5.0.1).\n")
    _img(add, plots, "convergence", md, "error against time")
    add(table(sorted(med, key=lambda r: (r["series"], r["x"])), [
        ("series", "series", ""), ("spp / threshold", "x", "g"), ("mean spp", "spp_mean", ".1f"),
        ("wall s", "wall_s", ".3f"), ("CPU s", "cpu_s", ".3f"),
        ("rel. MSE", "rel_mse", ".4g"), ("mean ΔE00", "de00", ".3f"),
        ("load", "load1", ".1f")]))
    add("")
    c = cfg.get("width", 0) * cfg.get("height", 0)
    lines = []
    for s in ("relray", "cycles"):
        a, b = _fit(med, s, "cpu_s")
        aw, bw = _fit(med, s, "wall_s")
        big = [r for r in med if r["series"] == s]
        if big:
            r = max(big, key=lambda r: r["x"])
            lines.append({"s": s, "oh": aw, "per": bw, "ohc": a, "perc": b,
                          "pps": c * r["x"] / r["cpu_s"]})
    add("Fixed cost and cost per spp (least squares time = overhead + per_spp × spp; the "
        "fitted overheads are small and noisy, one can come out negative), and paths per "
        "CPU-second at the largest spp (2 threads):\n")
    add(table(lines, [("renderer", "s", ""), ("wall overhead s", "oh", ".3f"),
                      ("wall per spp s", "per", ".4f"), ("CPU overhead s", "ohc", ".3f"),
                      ("CPU per spp s", "perc", ".4f"),
                      ("paths per CPU-s", lambda r: r["pps"] / 1e6, ".2f")]))
    add("\n(paths per CPU-s in millions.)\n")
    eq = d["equal_error"]
    if eq:
        add("### Equal-error time ratios\n")
        add("Levels: the error Cycles (without adaptive sampling) reaches at the 2nd spp of "
            "the ladder, and the lowest error that both plain curves reach; each curve is "
            "interpolated in log-log (\\* = extrapolated from its end points; an adaptive "
            "curve flattens at its cap, so a level it does not reach reads –). Ratio < 1: "
            "A reaches the error sooner.\n")
        add(table(eq, [("metric", "metric", ""), ("level", "level", ".4g"),
                       ("clock", "clock", ""), ("A", "a", ""), ("B", "b", ""),
                       ("time A s", "time_a_s", ".3f"), ("time B s", "time_b_s", ".3f"),
                       ("A / B", lambda r: "–" if not math.isfinite(r["ratio_a_over_b"])
                        else f"{r['ratio_a_over_b']:.2f}" + (
                           "*" if r["extrapolated"] in (True, "True") else ""), "")]))
        add("")
    cc = d["converged_compare"]
    if cc:
        add("### The two converged images\n")
        _img(add, plots, "converged", md, "converged images")
        add(table(cc, [("light", "light", ""), ("mean ΔE00", "de00_mean", ".2f"),
                       ("median", "de00_median", ".2f"), ("95th pct", "de00_p95", ".2f"),
                       ("rel. MSE", "rel_mse", ".4f"),
                       ("mean R, G, B relray / Cycles", lambda r:
                        f"{r['mean_ratio_r']:.4f}, {r['mean_ratio_g']:.4f}, "
                        f"{r['mean_ratio_b']:.4f}", ""),
                       ("luminance ratio", "luminance_ratio", ".4f")]))
        add("\nphysics.md expects direct light to agree to the noise (< 0.5 ΔE00) and full "
            "global illumination to differ by about 1–3 ΔE00 (RGB multiplies three "
            "channels per bounce, spectra multiply per wavelength); the residual of the "
            "references' own noise is included in these numbers.")
        full = [r for r in cc if r["light"] == "full GI"]
        if full and full[0]["de00_mean"] < 1.0:
            add(f"Measured: full GI differs by {full[0]['de00_mean']:.2f} on average, less "
                "than physics.md's estimate: ΔE00 is taken on the image as the Standard "
                "view shows it at exposure 0, where this box is fairly dark (mean "
                "luminance ≈ 0.2; ΔE00 shrinks with lightness), and the walls' "
                "reflectances are smooth sigmoid spectra whose products stay close to the "
                "RGB products over 2–3 bounces. The map above shows where the difference "
                "is: where colour bleeds, on the tall block's face lit by the red wall and "
                "on the short block's front face.")
        add("")
    add("### Matching Cycles to relray: conventions and mismatches found\n")
    add("""- **Emission**: Cycles' Emission strength and relray's `emission_strength` are
  both radiance multipliers of the RGB colour (relray's RGB emitter is that RGB under
  a D65-shaped spectrum, whose rendered colour is the RGB). Verified: the mean colour
  of the direct-light images agrees to the figures in the table above.
- **One-sided emission**: Cycles' Emission shader emits from both faces. relray's
  `one_sided_emission` is rebuilt as a Mix shader on Geometry ▸ Backfacing (front:
  Diffuse + Emission, back: Diffuse) with `emission_sampling = 'FRONT'`.
- **Diffuse**: Diffuse BSDF with roughness 0 (Lambert); a Principled BSDF would add a
  specular layer that relray's diffuse material does not have.
- **Bounces**: relray's `max_depth` counts path segments (camera ray = 1), Cycles'
  `max_bounces` counts bounces: `max_bounces = max_depth - 2` (direct light only is
  max_depth 2 = 0 bounces).
- **Cycles defaults that had to be changed** (each one biased or blurred the
  comparison): denoising is on by default in 5.0 (`use_denoising = False`); the render
  result is dithered (`dither_intensity = 0`, the noise is in the float pixels too);
  a new World has a grey 0.05 Background that lights the open box (no World:
  black); the pixel filter is Blackman–Harris 1.5 px (Box 1 px, relray's); the
  indirect light is clamped at 10 (clamping off); `light_sampling_threshold` 0;
  view transform 'Standard' (float pixels are linear anyway).
- **Reading pixels**: in the bpy module the 'Render Result' image has no pixels
  (size 0 × 0), so the result is saved with `Image.save_render` as 32-bit float
  OpenEXR (ZIP, lossless, linear Rec.709) and read back as floats; no PNG involved.
- **Not a mismatch, a difference**: Cycles samples with a tabulated Sobol sequence
  (QMC), relray with hashed random numbers (stratified only in the wavelength
  offsets); at low spp that gives Cycles a lower error per sample. Cycles is an RGB
  renderer, relray a spectral one (4 hero wavelengths per path): its colour noise is
  what the ΔE00 metric sees most.
- **Timing**: Cycles is timed around `bpy.ops.render.render()` inside its own process
  with persistent data on (its BVH is kept, as relray's `prepare` is done once), its
  CPU time includes all its threads; relray is timed around `FrameRenderer.render`.
""")


def plot_mitsuba_converged(refs: dict[str, np.ndarray], path: Path) -> Path | None:
    """relray's converged Cornell box beside each Mitsuba variant's, with ΔE00 maps."""
    peers = [k[:-5] for k in refs if k.endswith("_full") and not k.startswith("relray")]
    if not peers:
        return None
    plt = _plt()
    fig, ax = plt.subplots(2, 1 + len(peers), figsize=(3 * (1 + len(peers)), 6.2),
                           squeeze=False)
    a = refs["relray_full"]
    ax[0, 0].imshow(_display(a))
    ax[0, 0].set_title("relray (full GI)")
    ax[1, 0].imshow(_display(refs["relray_direct"]))
    ax[1, 0].set_title("relray (direct)")
    for j, p in enumerate(peers, start=1):
        ax[0, j].imshow(_display(refs[f"{p}_full"]))
        ax[0, j].set_title(f"Mitsuba {p}", fontsize=9)
        de = cm.delta_e00(a, refs[f"{p}_full"])
        im = ax[1, j].imshow(de, cmap="magma", vmin=0, vmax=5)
        ax[1, j].set_title(f"ΔE00 to relray, full (mean {de.mean():.2f})", fontsize=8)
        fig.colorbar(im, ax=ax[1, j], fraction=0.046)
    for x in ax.ravel():
        x.set_xticks([])
        x.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def plot_peer_converged(refs: dict[str, np.ndarray], path: Path) -> Path | None:
    """Per scene of :mod:`.peer_scenes`: relray's converged image, each peer's, and the
    ΔE00 map of each peer against relray (full GI)."""
    scenes = [k[: -len("_relray_full")] for k in refs if k.endswith("_relray_full")]
    if not scenes:
        return None
    peers = sorted({k[len(s) + 1: -5] for s in scenes for k in refs
                    if k.startswith(s + "_") and k.endswith("_full")} - {"relray"})
    plt = _plt()
    fig, ax = plt.subplots(2 * len(scenes), 1 + len(peers),
                           figsize=(2.6 * (1 + len(peers)), 5.4 * len(scenes)), squeeze=False)
    for i, s in enumerate(scenes):
        a = refs[f"{s}_relray_full"]
        ax[2 * i, 0].imshow(_display(a))
        ax[2 * i, 0].set_title(f"{s}: relray", fontsize=9)
        ax[2 * i + 1, 0].imshow(_display(refs[f"{s}_relray_direct"]))
        ax[2 * i + 1, 0].set_title(f"{s}: relray, direct", fontsize=9)
        for j, p in enumerate(peers, start=1):
            if f"{s}_{p}_full" not in refs:
                ax[2 * i, j].set_axis_off()
                ax[2 * i + 1, j].set_axis_off()
                continue
            b = refs[f"{s}_{p}_full"]
            ax[2 * i, j].imshow(_display(b))
            ax[2 * i, j].set_title(p, fontsize=9)
            de = cm.delta_e00(a, b)
            im = ax[2 * i + 1, j].imshow(de, cmap="magma", vmin=0, vmax=5)
            ax[2 * i + 1, j].set_title(f"ΔE00 (mean {de.mean():.2f})", fontsize=8)
            fig.colorbar(im, ax=ax[2 * i + 1, j], fraction=0.046)
    for x in ax.ravel():
        x.set_xticks([])
        x.set_yticks([])
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def mitsuba_goals(d: dict[str, list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """Issue 12 item 3 against Mitsuba on the Cornell box: equal-error CPU time relray ÷
    peer ≤ 1.0 (``llvm_ad_spectral``) and ≤ 0.4 (``scalar_spectral``), per metric and
    level (all must hold)."""
    targets = {"llvm_ad_spectral": 1.0, "scalar_spectral": 0.4}
    rows = []
    for peer, target in targets.items():
        eq = [r for r in d["mitsuba_equal_error"] if r["peer"] == peer]
        for metric, name in (("rel_mse", "relative MSE"), ("de00", "mean ΔE00")):
            rs = sorted((r for r in eq if r["metric"] == metric),
                        key=lambda r: r["level_index"])
            if not rs:
                continue
            vals = [r["ratio_relray_over_peer"] for r in rs]
            rows.append({"goal": f"equal-error CPU time relray ÷ {peer}, {name} "
                                 f"(two levels)", "target": f"≤ {target:g}",
                         "measured": ", ".join(f"{v:.2f}" + (
                             "*" if r["extrapolated"] in (True, "True") else "")
                                               for v, r in zip(vals, rs, strict=True)),
                         "met": all(math.isfinite(v) and v <= target for v in vals)})
    return rows


def mitsuba_split(med: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per peer: medians over the ladder of relray's relative MSE and CPU time over the
    peer's at the same spp (the noise-per-sample and cost-per-sample factors)."""
    by = {(r["series"], r["x"]): r for r in med}
    rows = []
    for peer in sorted({r["series"] for r in med} - {"relray"}):
        xs = [x for (s, x) in by if s == peer and ("relray", x) in by]
        if not xs:
            continue
        rows.append({"peer": peer,
                     "mse_ratio": statistics.median(by[("relray", x)]["rel_mse"]
                                                    / by[(peer, x)]["rel_mse"] for x in xs),
                     "cpu_ratio": statistics.median(by[("relray", x)]["cpu_s"]
                                                    / by[(peer, x)]["cpu_s"] for x in xs)})
    return rows


def _when(sec: dict[str, Any]) -> str:
    """"<date> on <cpu> (load <before> before, <after> after" of a section's meta."""
    return (f"{sec.get('date', '?')} on {sec.get('cpu', '?')} (load "
            f"{sec.get('load_before', [math.nan])[0]:.2f} before, "
            f"{sec.get('load_after', [math.nan])[0]:.2f} after")


#: The columns of a peer's status table: its version, whether it ran, and why not.
_RAN_COLS = [("version", "version", ""),
             ("ran", lambda r: "yes" if r["ran"] in (True, "True") else "**no**", ""),
             ("why not", "reason", "")]


def _converged_cols(peer: str, digits: int) -> list[tuple[str, Any, str]]:
    """The columns of a converged-image comparison against ``peer``."""
    return [(f"luminance ratio relray / {peer}", "luminance_ratio", ".4f"),
            ("mean R, G, B ratio", lambda r: ", ".join(
                f"{r[f'mean_ratio_{c}']:.{digits}f}" for c in "rgb"), ""),
            ("mean ΔE00", "de00_mean", ".2f"), ("95th pct", "de00_p95", ".2f")]


def _section_mitsuba(add, d, plots, md, meta) -> None:
    add("### Mitsuba 3 as a peer (`scalar_spectral`, `llvm_ad_spectral`)\n")
    st = d["mitsuba_status"]
    sec = meta.get("sections", {}).get("mitsuba", {})
    cfg = sec.get("config", {})
    if not st:
        add("Not run (`python -m relray.bench.run --only mitsuba`).\n")
        return
    add(f"Run at {_when(sec)}). Mitsuba runs in its own venv "
        "(`make mitsuba-venv`: `.cache/mitsuba-venv` from the hashed `bench/mitsuba.lock`; "
        "the LLVM variant with Debian's libLLVM 19 unpacked into `.cache/llvm19` and "
        "handed over by `DRJIT_LIBLLVM_PATH`), as a long-lived worker per variant "
        "(`bench/mitsuba_worker.py`), driven from `bench/mitsuba_peer.py`.\n")
    add(table(st, [("variant", "variant", ""), *_RAN_COLS]))
    add("")
    add("Matched settings (the scene dict is generated from relray's job; "
        "`tests/test_mitsuba_peer.py` checks it): the Cornell box of `presets/cornell.toml`, "
        "β = 0, `path` integrator with NEE + MIS, `max_depth` "
        f"{cfg.get('max_depth', 8)} on both (both count path segments), Russian roulette "
        "from the 4th segment (`rr_depth = 4` = relray's `RR_DEPTH`; Mitsuba caps survival "
        "at 0.95, relray does not), 4 wavelengths per path (fixed in Mitsuba's spectral "
        "variants), `twosided` `diffuse` from the same RGB reflectances **upsampled by "
        "Jakob–Hanika** on both sides (each with its own fit; not shared spectra), the "
        "area light as RGB × strength under D65 (one-sided, front face), `perspective` "
        "camera with relray's vertical fov, position and orientation, `hdrfilm` with a "
        "`box` filter of 1 px, linear Rec.709 out of the CIE 1931 observer. Sampler: "
        "Mitsuba's `ldsampler` (low-discrepancy; it rounds counts up to a power of 4, "
        "so the ladder is in powers of 4 and the counts below are those the sampler "
        "actually took); relray's own sampler.\n")
    cc = d["mitsuba_converged"]
    if cc:
        add(f"**Converged images** ({cfg.get('width')}×{cfg.get('height')}, "
            f"{cfg.get('ref_spp')} spp each, another seed than the ladder):\n")
        _img(add, plots, "mitsuba_converged", md, "relray and Mitsuba, converged")
        add(table(cc, [("Mitsuba variant", "variant", ""), ("light", "light", ""),
                       *_converged_cols("Mitsuba", 4)]))
        add("\n(the references' own noise is in these figures.)\n")
    tp = d["mitsuba_throughput"]
    eq = d["mitsuba_equal_error"]
    by_peer = {(r["peer"], r["metric"], r["level_index"]): r for r in eq}
    rows = []
    for r in tp:
        row = {"renderer": r["renderer"], "mpps": r["mpaths_per_cpu_s"], "ns": r["ns_per_path"]}
        for m in ("rel_mse", "de00"):
            for i in (0, 1):
                e = by_peer.get((r["renderer"], m, i))
                row[f"{m}{i}"] = "—" if e is None else (
                    f"{e['ratio_relray_over_peer']:.2f}"
                    + ("*" if e["extrapolated"] in (True, "True") else ""))
        rows.append(row)
    if rows:
        add(f"**Throughput and equal-error time.** M paths per CPU-second: "
            f"{tp[0]['size']}², {tp[0]['spp']} spp, 1 thread, medians of "
            f"{tp[0]['n']} interleaved renders. Equal-error CPU time relray ÷ peer: "
            f"{cfg.get('width')}×{cfg.get('height')}, ladder {cfg.get('spp')} spp, "
            f"{cfg.get('repeats')} interleaved repeats (relray, then each variant, per "
            "step), 1 thread each, medians; each renderer against its own converged "
            "reference; levels: the largest error any renderer has at the ladder's 2nd "
            "step, and the largest of their lowest errors (so both are inside every "
            "curve; * = extrapolated). < 1: relray reaches the error in less CPU time.\n")
        add(table(rows, [("", "renderer", ""), ("M paths per CPU-s, 1 thread", "mpps", ".2f"),
                         ("ns per path", "ns", ".0f"),
                         ("CPU time to equal rel. MSE, high / low level",
                          lambda r: f"{r['rel_mse0']} / {r['rel_mse1']}", ""),
                         ("… to equal mean ΔE00, high / low level",
                          lambda r: f"{r['de000']} / {r['de001']}", "")]))
        add("")
    med = d["mitsuba_medians"]
    split = mitsuba_split(med)
    if split:
        add("Where the ratio comes from (medians over the ladder's steps at the same spp): "
            "equal-error time ≈ (error per sample ratio) × (CPU per sample ratio), for "
            "relative MSE, whose error falls as 1/spp.\n")
        add(table(split, [("peer", "peer", ""),
                          ("rel. MSE relray ÷ peer at equal spp", "mse_ratio", ".2f"),
                          ("CPU time relray ÷ peer at equal spp", "cpu_ratio", ".2f"),
                          ("product", lambda r: r["mse_ratio"] * r["cpu_ratio"], ".2f")]))
        add("")
    if med:
        add("The ladder (medians):\n")
        add(table(sorted(med, key=lambda r: (r["series"], r["x"])), [
            ("renderer", "series", ""), ("spp asked", "x", "g"),
            ("spp taken", "spp_taken", "g"), ("CPU s", "cpu_s", ".3f"),
            ("wall s", "wall_s", ".3f"), ("rel. MSE", "rel_mse", ".4g"),
            ("mean ΔE00", "de00", ".3f"), ("load", "load1", ".1f")]))
        add("")
    goals = mitsuba_goals(d)
    if goals:
        add("**Issue 12, item 3, against Mitsuba (Cornell box only):**\n")
        add(table(goals, [("goal", "goal", ""), ("target", "target", ""),
                          ("measured", "measured", ""),
                          ("met", lambda r: "yes" if r["met"] else "**no**", "")]))
        add("")
        add(f"A goal counts as met only when it holds at both error levels. The CPU "
            f"has {sec.get('simd', 'an unrecorded vector extension')} (Dr.Jit's LLVM "
            "backend runs 8 float lanes per instruction with AVX2, 16 with AVX-512, so "
            "`llvm_ad_spectral` gains on an AVX-512 machine and these ratios do not carry "
            "over to one). The machine was shared during the run (the load above; CPU "
            "time is what each renderer got, but a crowded core's caches slow every "
            "renderer somewhat, and not necessarily equally).\n")


PEER_TARGETS = {"llvm_ad_spectral": 1.0, "scalar_spectral": 0.4, "cycles": 0.5}


def peer_goals(d: dict[str, list[dict[str, Any]]]) -> list[dict[str, Any]]:
    """Issue 12 item 3 per scene of :mod:`.peer_scenes`: equal-error CPU time relray ÷
    peer ≤ :data:`PEER_TARGETS` (relative MSE, both levels), and loading the heavy mesh
    no slower than Mitsuba."""
    rows = []
    scenes = list(dict.fromkeys(r["scene"] for r in d["peer_equal_error"]))
    for scene in scenes:
        for peer, target in PEER_TARGETS.items():
            rs = sorted((r for r in d["peer_equal_error"] if r["scene"] == scene
                         and r["peer"] == peer and r["metric"] == "rel_mse"),
                        key=lambda r: r["level_index"])
            if not rs:
                continue
            vals = [r["ratio_relray_over_peer"] for r in rs]
            rows.append({"scene": scene, "goal": f"equal-error CPU time relray ÷ {peer}",
                         "target": f"≤ {target:g}",
                         "measured": ", ".join(f"{v:.2f}" + (
                             "*" if r["extrapolated"] in (True, "True") else "")
                             for v, r in zip(vals, rs, strict=True)),
                         "met": all(math.isfinite(v) and v <= target for v in vals)})
    load = {r["renderer"]: r for r in d["peer_load"]}
    for peer in ("scalar_spectral", "llvm_ad_spectral"):
        if "relray" in load and peer in load:
            ratio = load["relray"]["load_s"] / load[peer]["load_s"]
            rows.append({"scene": "heavy", "goal": f"loading the mesh + BVH, relray ÷ {peer}",
                         "target": "≤ 1", "measured": f"{ratio:.2f} "
                         f"({load['relray']['load_s']:.2f} s against "
                         f"{load[peer]['load_s']:.2f} s)", "met": ratio <= 1.0})
    return rows


def _section_peer_scenes(add, d, plots, md, meta) -> None:
    add("### The heavy, environment-lit, textured and moving scenes against Mitsuba 3 and "
        "Cycles\n")
    st = d["peer_status"]
    sec = meta.get("sections", {}).get("peer_scenes", {})
    cfg = sec.get("config", {})
    if not st:
        add("Not run (`python -m relray.bench.run --only peer_scenes`).\n")
        return
    add(f"Run at {_when(sec)}; "
        f"{sec.get('seconds', math.nan):.0f} s) by `python -m relray.bench.run --only "
        "peer_scenes` (`bench/peer_scenes.py`; `tests/test_peer_scenes.py` checks the "
        "export). Scenes, exported from relray's built scene (its triangles, the same "
        "winding): **heavy** = the Cornell box with the displaced-grid floor "
        f"({cfg.get('heavy_triangles', 0):,} triangles asked; `throughput.heavy_job`), "
        "max_depth 8; **environment** = ground, sphere (smooth shading normals) and box, "
        "grey Lambert, lit only by the 256 × 128 sky + sun EXR of `bench/environment.py`, "
        "max_depth 4; **textured** = the Cornell box with base-colour textures (`bench/"
        "textures.py`: a 512² sRGB checker repeated 4× on the white surfaces, colour noise "
        "on the red and green walls), max_depth 8, exported as Mitsuba `bitmap` "
        "reflectances (sRGB-decoded, bilinear, repeat) and Cycles Image Textures "
        "('Linear') on relray's UVs through each texture's UV map (relray filters "
        "trilinearly from its mip pyramid; the blocks' roughness map, which Lambert "
        "ignores, and their flat normal map are left out; any other texture is refused); "
        f"**moving** = the Cornell box with its walls and blocks dealt into "
        f"{cfg.get('moving_groups', 4)} bodies, each moving at β = 10⁻⁴ in its own "
        "direction (`velocity_groups.grouped_scene`), max_depth 8: relray traces it as any "
        "scene with moving bodies (whole paths since 2026-11-26 21:00, SIMD lanes since "
        "2026-11-28 07:50, each body's rays in its rest frame), and at that speed its "
        "picture is the box at rest to 10⁻⁴, so the peers "
        "render the box at rest (they have no relativistic motion) and the converged "
        "images must still agree: the ratios measure what relray's machinery for moving "
        "bodies costs against renderers that have none. "
        "Settings as for the Cornell box above (NEE + MIS, `rr_depth` 4, box "
        "filter 1 px, the same camera, two-sided Lambert from the same RGB), with the "
        "meshes as binary PLY triangle soups (vertex normals where relray has shading "
        "normals). The map: Cycles gets the same EXR as an Environment Texture world "
        "('Closest', relray's nearest texel for lit surfaces); Mitsuba's `envmap` is "
        "always bilinear, so it gets the EXR with each texel repeated "
        f"{cfg.get('env_upsample', 4)} × {cfg.get('env_upsample', 4)} times (the same "
        "piecewise-constant radiance, blurred over a quarter texel), in the frame "
        "`envmap_to_world` (lab (X, Y, Z) = Mitsuba's (z, x, y): Blender's and relray's "
        "equirect orientation).\n")
    tx = sec.get("textured")
    if tx:
        add(f"The textured scene (and the texture-v check below) ran separately right "
            f"after, with the same code and settings (`peer_scenes.run` with scenes = "
            f"(\"textured\",)), at {tx.get('date', '?')} (load "
            f"{tx.get('load_before', [math.nan])[0]:.2f} before, "
            f"{tx.get('load_after', [math.nan])[0]:.2f} after; "
            f"{tx.get('seconds', math.nan):.0f} s); the map-orientation rows come from "
            "`orientation_check` run once after the main section.\n")
    orient = d["peer_orientation"]
    if orient:
        add("Conventions checked on images, not assumed, in direct light: the map's frame "
            "(`peer_scenes.orientation_check`, the environment scene: relray against "
            "Mitsuba with the map in that frame and turned about +Z, and against Cycles) "
            "and, for the textured box, Mitsuba's texture v (`texture_v_check`: v = 0 at "
            "the image's top row in Mitsuba, at its bottom row in relray and Blender). The "
            "export is the setting with the smallest ΔE00:\n")
        add(table(orient, [("check", lambda r: r.get("check", "envmap frame"), ""),
                           ("peer", "peer", ""),
                           ("setting", lambda r: r.get("setting") or
                            f"map turned by {r.get('rotation_deg', 0):g}°", ""),
                           ("size, spp", lambda r: f"{r['size']}², {r['spp']}", ""),
                           ("luminance ratio relray / peer", "luminance_ratio", ".3f"),
                           ("mean ΔE00", "de00_mean", ".2f")]))
        add("")
    add(table(st, [("scene", "scene", ""), ("peer", "peer", ""), *_RAN_COLS]))
    add("")
    cc = d["peer_converged"]
    if cc:
        add(f"**Converged images** ({cfg.get('width')}×{cfg.get('height')}, "
            f"{cfg.get('ref_spp')} spp each at {cfg.get('ref_threads')} threads, another "
            "seed than the ladder; the references' own noise is in the ΔE00):\n")
        _img(add, plots, "peer_converged", md, "heavy and environment scenes, converged")
        _img(add, plots, "peer_converged_textured", md, "textured scene, converged")
        _img(add, plots, "peer_converged_moving", md, "moving scene, converged")
        add(table(cc, [("scene", "scene", ""), ("peer", "variant", ""), ("light", "light", ""),
                       *_converged_cols("peer", 3)]))
        add("")
        add("Where they differ (see the ΔE00 maps): relray looks up the map **bilinearly "
            "for camera rays** (core/render/environment.py) and the peers with the nearest "
            "texel, so the horizon row of the sky differs; the peers draw the tessellated "
            "sphere's shadow terminator as a hard line (shadow rays from the flat "
            "triangles under smooth normals), relray does not; and Mitsuba's light from "
            "the map is about 1.6 % dimmer and 2.6 % less red than relray's, which agrees "
            "with Cycles' to 0.1 % (the ratios above, the same in direct light), which "
            "points at Mitsuba's RGB-to-spectrum conversion of the envmap rather than at "
            "the geometry (the heavy scene's ratios are 1.00). In the textured box, "
            "Cycles comes out 0.6–0.9 % darker than relray and Mitsuba in every channel "
            "alike (not explained yet).\n")
        add("**Caveat for the textured box:** relray filters its textures trilinearly from "
            "a mip pyramid at the ray cone's footprint, the peers bilinearly from the full "
            "image (no mip maps), so each peer sample carries the 512² checker's sub-pixel "
            "variation as noise that relray's samples do not: relray's relative MSE per "
            "sample is a third of theirs (table below), and its converged image is the "
            "prefiltered one (the converged agreement is still within about 0.9 ΔE00 at "
            "96², where a pixel spans several checker cells; the speckle of 3–5 ΔE00 on "
            "the noise-textured side walls is mostly that noise left in the peers' "
            "references, the grid of dots on the back wall the checker's aliasing against "
            "relray's prefiltered checker). The textured equal-error "
            "ratios therefore measure relray's prefiltering as much as its speed; the "
            "CPU-per-sample column is the like-for-like cost.\n")
    eq = d["peer_equal_error"]
    if eq:
        add(f"**Equal-error CPU time**, relray ÷ peer: {cfg.get('width')}×"
            f"{cfg.get('height')}, ladder {cfg.get('spp')} spp, {cfg.get('repeats')} "
            "interleaved repeats (relray, then each peer, per step), **1 thread each** "
            "(Cycles too, unlike §2's 2-thread Cycles series), CPU time of the render call, "
            "medians; each renderer against its own converged reference; the two levels "
            "as for the Cornell box (* = extrapolated). < 1: relray is faster.\n")
        by = {(r["scene"], r["peer"], r["metric"], r["level_index"]): r for r in eq}
        rows = []
        for scene, peer in dict.fromkeys((r["scene"], r["peer"]) for r in eq):
            row = {"scene": scene, "peer": peer}
            for m in ("rel_mse", "de00"):
                cells = []
                for i in (0, 1):
                    e = by.get((scene, peer, m, i))
                    if e is not None:
                        cells.append(f"{e['ratio_relray_over_peer']:.2f}" + (
                            "*" if e["extrapolated"] in (True, "True") else ""))
                row[m] = " / ".join(cells) or "—"
            rows.append(row)
        add(table(rows, [("scene", "scene", ""), ("peer", "peer", ""),
                         ("CPU time to equal rel. MSE, high / low level", "rel_mse", ""),
                         ("… to equal mean ΔE00, high / low level", "de00", "")]))
        add("")
        split = []
        for scene in dict.fromkeys(r["scene"] for r in d["peer_medians"]):
            for r in mitsuba_split([m for m in d["peer_medians"] if m["scene"] == scene]):
                split.append({"scene": scene, **r})
        if split:
            add("Noise per sample and cost per sample (medians over the ladder at equal "
                "spp):\n")
            add(table(split, [("scene", "scene", ""), ("peer", "peer", ""),
                              ("rel. MSE relray ÷ peer", "mse_ratio", ".2f"),
                              ("CPU time relray ÷ peer", "cpu_ratio", ".2f"),
                              ("product", lambda r: r["mse_ratio"] * r["cpu_ratio"],
                               ".2f")]))
            add("")
        add("The ladder (medians):\n")
        add(table(sorted(d["peer_medians"], key=lambda r: (r["scene"], r["series"], r["x"])),
                  [("scene", "scene", ""), ("renderer", "series", ""), ("spp", "x", "g"),
                   ("spp taken", "spp_taken", "g"), ("CPU s", "cpu_s", ".3f"),
                   ("rel. MSE", "rel_mse", ".4g"), ("mean ΔE00", "de00", ".3f"),
                   ("load", "load1", ".1f")]))
        add("")
    load = d["peer_load"]
    if load:
        lsec = meta.get("sections", {}).get("peer_load", {})
        when = (f"section `peer_load`, run at {_when(lsec)})" if lsec else
                "measured with the scenes above")
        add(f"**Loading the heavy mesh and building its BVH** ({when}; medians of "
            f"{load[0]['n']} interleaved runs, wall time): relray's `build_scene` (the box "
            "and the grid's shared-vertex PLY through trimesh) + `prepare` (Embree BVH, "
            "spectral and light tables) against a fresh Mitsuba process loading the same "
            "box and the same PLY file (`mi.load_dict`: reading, BVH; the process's "
            "start-up and `import mitsuba` are not counted).\n")
        add(table(load, [("renderer", "renderer", ""), ("triangles", "triangles", ",d"),
                         ("load + BVH s", "load_s", ".2f"),
                         ("of which build_scene s", "build_scene_s", ".2f"),
                         ("of which prepare s", "prepare_s", ".2f"),
                         ("relray ÷ this", "relray_over_this", ".2f")]))
        add("")
    goals = peer_goals(d)
    if goals:
        add("**Issue 12, item 3, per scene** (relative MSE at both levels must hold):\n")
        add(table(goals, [("scene", "scene", ""), ("goal", "goal", ""),
                          ("target", "target", ""), ("measured", "measured", ""),
                          ("met", lambda r: "yes" if r["met"] else "**no**", "")]))
        add("")
        for scene in dict.fromkeys(g["scene"] for g in goals):
            gs = [g for g in goals if g["scene"] == scene]
            met = [g["goal"] for g in gs if g["met"]]
            unmet = [g["goal"] for g in gs if not g["met"]]
            add(f"- **{scene}**: met {len(met)} of {len(gs)}"
                + (f" ({'; '.join(met)})" if met else "")
                + (f"; not met: {'; '.join(unmet)}" if unmet else "")
                + (" (but see the caveat on texture prefiltering)"
                   if scene == "textured" and met else "") + ".")
        add("")
        add("The load times are wall times on the shared machine (each run's load average "
            "is in `peer_load_raw.csv`), so both sides are slower than on an idle one; "
            "they ran interleaved, so the ratio is the figure to read.\n")


def _embree_share_cell(r: dict[str, Any]) -> str:
    """A throughput row's Embree share in %, "–" where no Embree loop was timed (whole
    paths: their queries are inside the kernel)."""
    return "–" if r["embree_s"] <= 0.0 else f"{100 * r['embree_share']:.1f}"


def _section_throughput(add, d, plots, md, meta) -> None:
    add("## 3. Throughput\n")
    tp = d["throughput"]
    if tp:
        t = tp[0]
        add(f"Cornell box {t['width']}², {t['spp']} spp, 1 thread, median of "
            f"{int(t['repeat'])} (command: `.venv/bin/python bench/throughput.py "
            f"presets/cornell.toml --spp {t['spp']} --threads 1 --profile`):\n")
        add(table(tp, [("mode", "mode", ""),
                       ("paths / CPU-s", lambda r: r["paths_per_cpu_s"] / 1e6, ".3f"),
                       ("rays / CPU-s", lambda r: r["rays_per_cpu_s"] / 1e6, ".2f"),
                       ("paths / wall-s", lambda r: r["paths_per_wall_s"] / 1e6, ".3f"),
                       ("rays per path", "rays_per_path", ".2f"),
                       ("intersect rays / path", lambda r: r["intersect_rays"] / r["paths"],
                        ".2f"),
                       ("shadow rays / path", lambda r: r["occluded_rays"] / r["paths"],
                        ".2f"),
                       ("Embree share of CPU", _embree_share_cell, ""),
                       ("ns per ray (CPU)", "ns_per_ray_cpu", ".0f"),
                       ("load", "load1", ".1f")]))
        add("\n(M = millions; Embree share in %, of the nearest-hit queries: a static "
            "scene's shadow rays are traced inside the shade kernel, §6; –: whole paths, "
            "whose Embree queries are inside their kernel, §6 \"Whole paths\".)\n")
    fl = d["embree_floor"]
    if fl:
        f = fl[0]
        add("### Embree's own cost per ray\n")
        add(f"`bench/embree_floor.py`: {int(f['rays']):,} random rays from inside the box "
            f"({int(f['triangles'])} triangles), one at a time, through embreex's `run` "
            "and through relray's own loops (`core/render/embree.py`: "
            "`rtcIntersect1`/`rtcOccluded1` of the same libembree4, called from compiled "
            "code; the renderer uses these), thread CPU clock, best of 7. The two agree on "
            f"{100 * f.get('agree_t', f['agree_prim']):.1f} % of the hit distances, "
            f"{100 * f['agree_prim']:.1f} % of the hit triangles (where two triangles meet "
            "at the hit either is right) and "
            f"{100 * f['agree_occluded']:.1f} % of the occlusion answers:\n")
        add(table([{"query": "nearest hit", "embreex": f["embreex_intersect_ns"],
                    "embree": f["embree_intersect_ns"]},
                   {"query": "occlusion", "embreex": f["embreex_occluded_ns"],
                    "embree": f["embree_occluded_ns"]}],
                  [("query", "query", ""), ("embreex run, ns per ray", "embreex", ".0f"),
                   ("relray's C-API loop, ns per ray", "embree", ".0f")]))
        add("")
    sc = d["scaling"]
    if sc:
        w = meta.get("sections", {}).get("scaling", {}).get("wait", {})
        add(f"### 1 against {int(sc[-1]['threads'])} threads\n")
        add(table(sc, [("threads", "threads", ".0f"),
                       ("paths / wall-s", lambda r: r["paths_per_wall_s"] / 1e6, ".3f"),
                       ("paths / CPU-s", lambda r: r["paths_per_cpu_s"] / 1e6, ".3f"),
                       ("speed-up (wall)", "speedup_wall", ".2f"),
                       ("CPU / wall", "cpu_per_wall", ".2f"),
                       ("busy-loop core share before", lambda r:
                        100 * r["cpu_share_before"], ".0f"),
                       ("load", "load1", ".2f")]))
        idle = (f" Before this section the harness waited {w.get('waited_s', 0):.0f} s for "
                f"the 1-minute load to drop below 0.6 and "
                f"{'got it' if w.get('idle') else 'gave up'} (load {w.get('load1', 0):.2f})."
                if w else "")
        add(f"\n{sc[-1]['width']:.0f}², {sc[-1]['spp']:.0f} spp, interleaved 1 2 1 2 …, "
            f"medians.{idle} The speed-up only means something when the busy-loop share "
            "is near 100 %: with another process keeping a core busy, 2 threads cannot run "
            "twice as fast. CPU / wall shows how many cores the render actually got.\n")
    hv = d["heavy"]
    if hv:
        add("### Heavy scene\n")
        add("The Cornell box with a generated displaced-grid floor (a binary PLY written "
            "into `bench/results/tmp`, never committed), against the plain box:\n")
        add(table(hv, [("scene", "scene", ""), ("triangles", "triangles", ",.0f"),
                       ("generate + write s", "generate_s", ".2f"),
                       ("build_scene s", "build_scene_s", ".2f"),
                       ("prepare (BVH, tables) s", "prepare_s", ".2f"),
                       ("paths / CPU-s", lambda r: r["paths_per_cpu_s"] / 1e6, ".3f"),
                       ("rays / CPU-s", lambda r: r["rays_per_cpu_s"] / 1e6, ".2f"),
                       ("Embree share", _embree_share_cell, ""),
                       ("ns per ray (CPU)", "ns_per_ray_cpu", ".0f")]))
        add(f"\n{hv[0]['width']:.0f}², {hv[0]['spp']:.0f} spp, 1 thread.\n")
    bs = d["beta_sweep"]
    if bs:
        add("### |β| sweep\n")
        add("The camera inside the Cornell box closed by a white front wall (every camera "
            "ray hits the box at any β, so the paths are of the same kind; in the open box "
            "the aberrated view shrinks the box to a few pixels and most paths end at the "
            "first miss, which would make high β look cheap). Error at the fixed spp "
            "against each β's own reference; ΔE00 at an exposure that puts the reference's "
            "mean luminance at 0.18 (the searchlight effect changes the brightness by "
            "orders of magnitude; sideways at high β the image is black in the visible: "
            "the error reads 0).\n")
        _img(add, plots, "beta", md, "beta sweep")
        add(table(bs, [("direction", "direction", ""), ("|β|", "beta", "g"),
                       ("CPU ms per spp", lambda r: 1e3 * r["cpu_per_spp_s"], ".2f"),
                       ("wall ms per spp", lambda r: 1e3 * r["wall_per_spp_s"], ".2f"),
                       ("CPU per spp / β = 0", "cpu_per_spp_vs_beta0", ".2f"),
                       ("rays per path", "rays_per_path", ".2f"),
                       ("ns per ray", "ns_per_ray_cpu", ".0f"),
                       ("camera share %", lambda r: 100 * r["camera_stage_share"], ".1f"),
                       ("mean Y of ref", "mean_luminance", ".3g"),
                       ("rel. MSE", "rel_mse", ".3g"),
                       ("ΔE00 @0.18", "de00_at_mean_0.18", ".2f")]))
        r0 = bs[0]
        add(f"\n{r0['width']:.0f}², {r0['spp']:.0f} spp, reference {r0['ref_spp']:.0f} spp, "
            f"{r0['threads']:.0f} threads, median of {r0['repeat']:.0f}.\n")


def _section_adaptive(add, d, plots, md) -> None:
    add("## 4. Adaptive sampling (`noise_threshold`)\n")
    g = [r for r in d["adaptive_gain"] if r["clock"] == "cpu_s"]
    if not g:
        add("Not run.\n")
        return
    add("relray's adaptive runs use the largest spp of the ladder as the cap and a ladder "
        "of thresholds t; each is compared with the plain-sampling curve at the same CPU "
        "time (log-log interpolation). Ratio < 1: adaptive sampling lowers the error at "
        "equal time. Cycles' own adaptive sampling (threshold 0.01, spp = cap) for "
        "comparison.\n")
    _img(add, plots, "adaptive", md, "adaptive sampling")
    add(table(g, [("series", "series", ""), ("t / cap", "x", "g"), ("metric", "metric", ""),
                  ("CPU s", "time_s", ".3f"), ("error", "error", ".4g"),
                  ("plain at same time", "plain_error_at_same_time", ".4g"),
                  ("ratio", "ratio", ".2f"),
                  ("inside plain range", "inside_plain_range", "")]))
    rel = [r for r in g if r["series"] == "relray adaptive"]
    for metric, name in (("rel_mse", "relative MSE"), ("de00", "mean ΔE00")):
        rs = [r for r in rel if r["metric"] == metric]
        wins = [r for r in rs if r["ratio"] < 1.0]
        if rs:
            ratios = ", ".join(f"{r['ratio']:.2f}" for r in rs)
            add(f"\n- **{name}**: adaptive sampling lowers the error at equal CPU time for "
                f"{len(wins)} of {len(rs)} thresholds (ratios {ratios}).")
    dg = d["adaptive_diagnosis"]
    if dg:
        add("\n### Why: the stopped pixels\n")
        add("Each threshold again (seed 0) against a plain render of the same mean spp; "
            "relative luminance error per pixel against the reference, split into the "
            "pixels that stopped before the cap and those that reached it. Bias = mean "
            "relative error, RMS = its root mean square.\n")
        add(table(dg, [("t", "threshold", "g"), ("mean spp", "mean_spp", ".0f"),
                       ("stopped", lambda r: 100 * r["stopped_fraction"], ".0f"),
                       ("stopped after the first pass",
                        lambda r: 100 * r.get("stopped_at_first_pass", math.nan), ".0f"),
                       ("CPU per sample adaptive / plain", "cpu_per_sample_ratio", ".2f"),
                       ("rel. MSE adaptive", "rel_mse_adaptive", ".4f"),
                       ("rel. MSE plain", "rel_mse_plain", ".4f"),
                       ("bias stopped: adaptive", "bias_stopped", "+.3f"),
                       ("plain", "bias_stopped_plain", "+.3f"),
                       ("… against the same seed at the cap",
                        lambda r: r.get("bias_stopped_paired", math.nan), "+.4f"),
                       ("RMS stopped: adaptive", "rms_stopped", ".3f"),
                       ("plain", "rms_stopped_plain", ".3f"),
                       ("RMS capped: adaptive", "rms_capped", ".3f"),
                       ("plain", "rms_capped_plain", ".3f")]))
        add("\n(stopped in % of the pixels.)\n")
    add("\n**Reading.** `core/render/frames.py` gives every pixel a first pass of "
        "`ADAPTIVE_FIRST_PASS` = 64 samples, then passes that double the count (aligned "
        "power-of-two blocks of the Owen-scrambled Sobol sequence, so a stopped pixel keeps "
        "a well-stratified prefix). After each pass `Film.converged` stops a pixel when "
        "its noise — the standard error of its mean over the three sensor channels, "
        "divided by √(its brightness × the image's mean brightness) — and the mean of "
        "that noise over its 3×3 neighbourhood are both at most t. The three channels "
        "make spectral colour noise count; the neighbourhood keeps a pixel whose first "
        "samples happened to agree (missed a rare bright path) from stopping while its "
        "neighbours are still noisy, which halves the dark bias of stopped pixels; the "
        "passes run over the whole frame, so the decision does not depend on the thread "
        "count. Cycles' estimate |full − 2·half| was tried offline on the same per-pass "
        "sums and did worse here (it has one degree of freedom per channel). At the "
        "ends of the threshold ladder the curve meets the plain one: a large t stops "
        "nearly every pixel after the first pass, a small t sends nearly every pixel to "
        "the cap.\n")


SKIP_NOTES = {
    "rgb when Doppler is off": (
        "**Skipped when asked: `spectral = \"auto\"`.** A `cie1931` job with `doppler = "
        "false` runs the 4-lane spectral path (hero sampling, 4 table lookups per lane, the "
        "CMF integration). The `rgb` path changes the picture (RGB multiplies channels per "
        "bounce: about 1–3 ΔE00 in indirect light, see §2), so it is a model choice, not a "
        "pure skip: the opt-in `render.spectral = \"auto\"` takes it when nothing shifts "
        "wavelengths (`doppler = false`, or nothing moves in any frame; "
        "`core/scene/spectral_model.py`), and the B / A column is its saving."),
    "β = 0 path (no boost)": (
        "**Skipped.** `camera._primary_rays` branches on b > 0 per ray, so at β = 0 no "
        "aberration or Doppler factor is computed; the difference to the general path is "
        "within the noise, because the camera stage is ~3 % of a path. What still runs at "
        "β = 0: `D**5` and the log(D) shift in `spectrum.grid_coordinates` (`render."
        "FrameRenderer._trace_chunk`), under 1 %."),
    "no glossy/dielectric code": (
        "**Skipped at run time.** `integrator.shade` and `bsdf.principled_eval` branch on "
        "the lobe weights (w_m > 0, w_g > 0) per ray; B forces those branches to run, so "
        "B / A is what the run-time skip saves. There is no compile-time specialisation; "
        "with the branches already skipped it would only save the branch tests "
        "themselves (a few ns per ray)."),
    "NEE only towards existing lights": (
        "**Skipped.** `lights.build_lights` lists only lights that exist (emissive "
        "triangles, lights with power > 0, the sky only when the background is not "
        "black); B adds a sky of 1e-6 to show what a useless light costs: its share of "
        "the NEE samples is wasted and the error at equal spp rises (rel. MSE columns)."),
    "no velocity-group traversal without moving bodies": (
        "**Skipped.** `frames.prepare` traces a scene without moving bodies through its "
        "one static BVH (`accel.Accel`); only a velocity group brings in "
        "`rest_frames.MovingScene` (the rest-frame transform of every ray, one more "
        "traversal per group and the merge of the nearest hits, for camera, continuation "
        "and shadow rays alike). B's group is hit by no ray, so B / A is the traversal "
        "cost alone (§5b measures groups that are hit)."),
    "no texture fetch for untextured materials": (
        "**Skipped.** Without a textured material `frames.scene_textures` gives no "
        "texture table and `integrator.shade` skips the UV interpolation, the mip level "
        "from the ray cone and the texel's spectrum per lane (`t_on` false); B looks up "
        "a 1 × 1 texture on every hit (the per-lane spectrum of the texel's colour from "
        "the Jakob–Hanika table, §5e)."),
    "no environment sampling without a map": (
        "**Skipped.** Without `scene.environment` the map is no light of the NEE table "
        "and a miss reads no texel (`env_on` false); B's map of 1e-6 takes a share of the "
        "light samples, as the useless sky does above."),
    "no star pass without stars": (
        "**Skipped.** `FrameRenderer._add_stars` returns at once without `scene.stars`; "
        "B aberrates, Doppler-shifts, occlusion-tests and splats the ~5,000 stars to "
        "magnitude 6 once per frame. It is a per-frame cost, so per spp it shrinks as "
        "spp grows."),
}


def _section_skips(add, d) -> None:
    add("## 5. Skip what a scene does not need\n")
    sk = d["skips"]
    if not sk:
        add("Not run.\n")
        return
    rend = [r for r in sk if r.get("cpu_per_spp_A_s") not in (None, "")]
    if rend:
        r0 = rend[0]
        add(f"Cornell box {r0['width']:.0f}², {r0['spp']:.0f} spp, {r0['threads']:.0f} "
            f"threads, CPU time per spp, median of {r0['repeat']:.0f} interleaved runs; "
            "relative MSE against a reference of the A variant. A is what relray does, B "
            "the work the skip avoids (for rgb: B is the path A could take).\n")
        add(table(rend, [("skip", "skip", ""),
                         ("A: CPU ms/spp", lambda r: 1e3 * r["cpu_per_spp_A_s"], ".2f"),
                         ("B: CPU ms/spp", lambda r: 1e3 * r["cpu_per_spp_B_s"], ".2f"),
                         ("B / A", "B_over_A", ".2f"),
                         ("rel. MSE A", "rel_mse_A", ".4f"), ("rel. MSE B", "rel_mse_B", ".4f"),
                         ("NEE lights A, B", lambda r: f"{r['lights_A']}, {r['lights_B']}",
                          "")]))
        add("")
        for r in rend:
            note = SKIP_NOTES.get(r["skip"])
            if note:
                add(f"- *{r['skip']}* (B / A = {r['B_over_A']:.2f}): {note}")
        add("")
    anim = [r for r in sk if str(r["skip"]).startswith("BVH once")]
    if anim:
        a = [r for r in anim if r.get("wall_per_frame_A_s") not in (None, "")]
        h = [r for r in anim if r.get("prepare_s") not in (None, "")]
        if a:
            r = a[0]
            add(f"**BVH once per animation: skipped.** A {r['frames']:.0f}-frame fly-by "
                f"(`presets/flyby.toml`, {r['width']:.0f}×{r['height']:.0f}, "
                f"{r['spp']:.0f} spp) in one `relray render` takes "
                f"{r['wall_per_frame_A_s']:.2f} s per frame; one `relray render --frames "
                f"i-i` per frame takes {r['wall_per_frame_B_s']:.2f} s per frame "
                f"({r['B_over_A']:.1f}×; {r['separate_measured']:.0f} separate runs "
                "measured). `render.render_job` builds the scene, BVH and tables once "
                f"(`render.prepare`: {1e3 * r['prepare_in_process_s']:.0f} ms for this "
                "scene in a warm process) and every frame reuses them; most of the cost "
                "of a separate run is the process start: imports (colour-science alone "
                f"{r.get('colour_import_s', math.nan):.1f} s), numba's cache load, the "
                "sensor tables.\n")
        if h:
            r = h[0]
            add(f"For the heavy scene the same skip is worth more: {r['skip']}: "
                f"build_scene {r['build_scene_s']:.2f} s + prepare {r['prepare_s']:.2f} s, "
                f"against a frame of {r['render_wall_s']:.2f} s at the heavy-scene "
                f"resolution: {r['B_over_A']:.1f}× per frame if rebuilt every frame.\n")


def _section_first(add, d) -> None:
    add("## 5c. The first render in Blender\n")
    rows = d["first_render"]
    if not rows:
        add("Not run.\n")
        return
    add("Blender's default scene (320×180, 16 spp, the Relativistic engine), each case a "
        "new Blender session (bpy module) with the extension installed in a fresh user "
        "directory (`bench/first_render.py`). *Cold*: an empty kernel cache. The warm-up "
        "child starts when the add-on is enabled; the time to F12 is the artist's.\n")
    add(table(rows, [("case", "case", ""),
                     ("enable → kernels ready (s)", "warmup_s", ".1f"),
                     ("F12 → frame (s)", "f12_s", ".1f")]))
    add("")
    if d["viewport_first"]:
        add("The Rendered viewport (`relblend.viewport`, kernels loaded): seconds from a "
            "new view to its quarter-size preview (1 spp) and to the first full-size "
            f"sample, median of {d['viewport_first'][0]['repeat']:.0f}.\n")
        add(table(d["viewport_first"], [("view", "view", ""),
                                         ("preview (s)", "preview_s", ".2f"),
                                         ("first full-size sample (s)", "first_sample_s",
                                          ".2f")]))
        add("")
    if d.get("first_cli"):
        add("The command line: `relray render presets/cornell.toml --spp 1` (256², 1 spp, "
            "the EXR and PNG written), from process start to exit; *cold*: an empty kernel "
            "cache, *warm*: the median of "
            f"{d['first_cli'][-1]['repeat']:.0f} runs with the cache filled; every "
            "process has relray's modules byte-compiled (as an installed package has: "
            "`first_render._python_env`; this machine's `PYTHONDONTWRITEBYTECODE=1` had "
            "made every start compile them again, about 0.18 s, before 2026-11-26 12:00). "
            "The goal of issue 12 is 1 s warm.\n")
        add(table(d["first_cli"], [("case", "case", ""), ("wall (s)", "wall_s", ".2f"),
                                   ("CPU (s)", "cpu_s", ".2f"),
                                   ("of it: imports (s)", "import_s", ".2f"),
                                   ("load", "load", ".1f")]))
        add("")
        add(FIRST_CLI_NOTES)


#: What the 2026-11-26 investigation of issue 12 found (not from the CSVs: its figures
#: were measured by hand, named below).
FIRST_CLI_NOTES = (
    "*Cold compile* (measured apart, 2026-11-26, per kernel with numba's compile events): "
    "all but about 15 s of the cold run is `integrator.shade`, compiled once (static and "
    "moving scenes share its one type signature, so `python -m relray.core.warmup` "
    "compiles it once too). numba's own passes, not LLVM, took the time: inlining 38 s, "
    "SSA reconstruction 34 s, lowering 24 s, type inference 16 s, rewrites 14 s, LLVM "
    "14 s (wall, load 3): an `inline=\"always\"` device function is copied, typed and "
    "lowered at every call site, and the five texture-slot lookups, the environment "
    "map's and the moving bodies' helpers had made shade several times larger. Compiled "
    "once as functions of their own (the helpers every hit runs stay inlined), the cold "
    "command line takes 65 CPU s at load 2 (72 at load 3.5; it was 122 at load 3), its "
    "images bit-identical (Cornell; a moving, textured, environment-lit scene); "
    "`python -m relray.core.warmup` 73 CPU s (126 before, both at load 4); throughput "
    "unchanged: Cornell 0.670 against 0.673 M paths/CPU-s (`bench/throughput.py`, 16 spp, "
    "1 thread, medians of 5 alternated runs), the textured box of `bench/textures.py` "
    "0.327 against 0.302. "
    "Compiling `nee_factors` and `lights.sample_light` apart as well gives 48 CPU s but "
    "costs 8 % of Cornell's throughput (medians of 5 alternated runs), so they stay "
    "inlined: the 45 s goal is not met. Since whole paths (`render/whole_paths.py`, "
    "2026-11-26), the Cornell box's command line does not compile `shade` at all (its "
    "scene takes the whole-path kernel): cold 23.7 s, warm 1.73 s at 13:33 (86 s and "
    "2.59 s before, without bytecode). Since the whole-path kernel also takes the "
    "environment map, analytic lights and textures (the session of 15:00), it compiles "
    "their lookups too: cold 53 s, warm 1.90 s at 16:08. Since 2026-11-26 17:55 the "
    "kernel is compiled once per kind of scene (`whole_paths.kernel`: a map or not, "
    "textures or not, as constants of the compiled code, so numba prunes those branches "
    "and never compiles their callees): the Cornell box compiles neither, cold 23.3 s "
    "against 53.2 s in two runs by hand at load 1 (the table above has this run's "
    "figure); `python -m relray.core.warmup` renders each kind and takes 151 s against "
    "113 s (load 1, in the background of Blender). "
    "Blender's default scene with its point light takes whole paths, so its first F12 "
    "no longer compiles `shade` (47 s against 85 s); a scene that needs the wavefront "
    "(moving bodies, glossy or glass lobes) still compiles `shade` at its first "
    "render. "
    "*2026-11-28 (`core/jit.py`)*: cProfile of a SIMD-lane kernel's compile found 78 of "
    "109 s in numba's `inline=\"always\"` pass, nearly all of it `copy.deepcopy` of the "
    "callees' IR (numba copies a callee's whole variable scope once per block, twice "
    "per call site; numba issues #8989, #9204). The inlined helpers are now "
    "`forceinline` (LLVM's `alwaysinline`: typed once, inlined by LLVM): that kernel "
    "compiles in 13 s instead of 44 s, and `python -m relray.core.warmup` from an "
    "empty cache takes 270 s instead of 1106 s (both while a test run shared the "
    "machine; by hand, `numba.core.event` timings); the run time per path, against the "
    "commit before (`bench.ab 49036c3`): Cornell 1.04 (12 pairs, quartiles 0.93-1.07), "
    "heavy 0.91 (6 pairs). On a quiet machine the next session measured Cornell 1.00 "
    "(10 pairs, 0.97-1.11) but the environment-lit scene 1.10 (16 spp, 1.02-1.22) and "
    "1.21 (64 spp, 1.09-1.27): an LLVM-inlined helper is optimised alone first, so its "
    "loops were vectorised (or marked not worth it) without the caller's stack arrays, "
    "and lane loops around the map's and lights' helpers stayed scalar (42 scalar square "
    "roots in that kernel). The lanes' loops and those helpers keep numba's IR inlining "
    "(`INLINE_IR`): the environment-lit scene 0.89x the CPU per path of the all-"
    "`forceinline` code (64 spp, 10 pairs, 0.75-0.97; everything IR-inlined 0.85x), "
    "its kernel's compile about 17 s longer.\n\n"
    "*Warm*: with the kernels cached, numba alone takes about 1 s before relray does any "
    "work (load 1.3, cProfile): importing numba (0.45 s with numpy) and, at the first "
    "cached kernel, numba's typing and lowering registries (0.45-0.57 s, 0.14 s of it "
    "`scipy.linalg`, imported by numba's BLAS check); relray's own share is the job "
    "schema (pydantic, 0.18 s), its modules, a 0.19 s render and 0.10 s of writing. "
    "So the 1 s goal has little margin while the command line loads numba's JIT: it "
    "was missed at 1.07–1.17 s in the runs of 2026-11-27 03:02 and 10:02 and met at "
    "0.87 s (imports 0.40 s) in the quicker phase of 13:05. A second "
    "cProfile (2026-11-26 11:52, load 0.6, 2.1 s in all, 0.18 s of it compiling "
    "relray's modules for want of bytecode): importing numba 0.62 s, its registries at "
    "the first cached kernel 0.43 s and `scipy.linalg` 0.20 s, the job schema 0.21 s, "
    "the render 0.19 s.\n")


def _section_environment(add, d) -> None:
    add("## 5d. Environment maps: next-event estimation against BSDF sampling\n")
    rows = d["environment_nee"]
    if not rows:
        add("Not run.\n")
        return
    from relray.bench import environment

    ref = rows[0]
    add(f"A grey diffuse scene (ground, sphere, box) lit only by a 256 × 128 map: a dim "
        f"sky and ground and a 2.8° sun of radiance 3000 (`bench/environment.py`, "
        f"{ref['width']:.0f} × {ref['height']:.0f}, max_depth 4, {ref['threads']:.0f} "
        f"threads). *nee*: the renderer as shipped (the map sampled in proportion to its "
        f"texels' power, MIS with BSDF sampling); *bsdf only*: the same with "
        f"`prepare(..., env_nee=False)` (an internal switch of `core.render.frames`, not "
        f"a job key). "
        f"Relative MSE against a {ref['spp']:.0f}-spp NEE render of another seed, process "
        f"CPU time, medians over seeds; load average {ref['load']:.2f} at the start.\n")
    add(table(rows[1:], [("series", "series", ""), ("spp", "spp", ".0f"),
                         ("CPU s", "cpu_s", ".3f"), ("rel. MSE", "rel_mse", ".4g"),
                         ("load", "load", ".2f")]))
    add("")
    ups = environment.speedups(rows)
    if ups:
        add("| rel. MSE | NEE+MIS CPU s | BSDF only CPU s at that error | speed-up |")
        add("|---|---|---|---|")
        for e, t, tb, extra in ups:
            add(f"| {e:.4g} | {t:.3f} | {tb:.3f}{' (extrapolated)' if extra else ''} | "
                f"{tb / t:.0f}× |")
        add("")
        ln = [r for r in rows if r["series"] == "nee"][-1]
        lb = [r for r in rows if r["series"] == "bsdf only"][-1]
        if any(extra for *_, extra in ups):
            add("*Extrapolated*: BSDF sampling alone never reaches these errors within its "
                "ladder; its time is the power law through its two nearest points "
                "(relative MSE ∝ 1/spp here, as its table shows), so those ratios are "
                "estimates. Measured directly: its largest step "
                f"({lb['spp']:.0f} spp, {lb['cpu_s']:.2f} CPU s) takes "
                f"{lb['cpu_s'] / ln['cpu_s']:.1f}× the CPU time of NEE's largest "
                f"({ln['spp']:.0f} spp) and has {lb['rel_mse'] / ln['rel_mse']:.0f}× its "
                "relative MSE.\n")
def _section_textures(add, d) -> None:
    add("## 5e. Textures: their cost\n")
    rows = d["textures"]
    if not rows:
        add("Not run.\n")
        return
    r0 = rows[0]
    add(f"Cornell box {r0['size']:.0f}², {r0['spp']:.0f} spp, {r0['threads']:.0f} "
        f"thread(s), paths per CPU-second, median of {r0['rounds']:.0f} alternated renders "
        "(`bench/textures.py`). *Textured*: the white surfaces with a 512² sRGB checker "
        "(repeated 4×), a 256² roughness map and a 256² flat normal map, the red and green "
        "walls with a 256² colour noise: every hit but the light's reads 1 to 3 textures "
        "(trilinear, two mip levels) and turns a texel's colour into its spectrum per "
        "hero wavelength (the 8 table nodes' sigmoids, `rgb_table.cell_reflectance`).\n")
    add(table(rows, [("variant", "variant", ""),
                     ("M paths/CPU-s", lambda r: r["paths_per_cpu_s"] / 1e6, ".3f"),
                     ("÷ untextured", "over_untextured", ".3f")]))
    add("")
    ab = d["textures_baseline"]
    if ab:
        a0 = ab[0]
        add("**Scenes without textures** pay one load and branch per hit (the material's "
            "texture flag) and nothing else (no ray cones: `TextureTable.enabled` is off). "
            f"presets/cornell.toml, {a0['spp']:.0f} spp, 1 thread, `bench/throughput.py` "
            f"with this code and with the code {a0['code']} (`bench/textures.py "
            f"--baseline`), alternated, median of {a0['rounds']:.0f}; the runs scatter by "
            "±10 % on this shared machine:\n")
        add(table(ab, [("code", "code", ""),
                       ("M paths/CPU-s", lambda r: r["paths_per_cpu_s"] / 1e6, ".3f"),
                       ("÷ before", "over_before", ".3f"),
                       ("runs (paths/CPU-s)", "runs", "")]))
        add("")


def _section_moving(add, d) -> None:
    add("## 5b. Moving objects: the cost of velocity groups\n")
    rows = d["velocity_groups"]
    if not rows:
        add("Not run.\n")
        return
    r0 = rows[0]
    add(f"Cornell box {r0['width']:.0f}², {r0['spp']:.0f} spp, {r0['threads']:.0f} threads, "
        f"CPU time per spp, median of {r0['repeat']:.0f} interleaved runs "
        "(`bench/velocity_groups.py`). *N groups*: the room's non-emitting triangles dealt "
        "into N velocity groups moving at 1e-4 c (so the picture and the paths stay the "
        "same and only the tracing in N rest frames costs); *the tall box*: only the "
        "tall block moves, the common case of a moving object in a static scene. "
        "Image difference: mean |Δ| / mean against the static render (noise of the "
        "same seed, not bias).\n")
    add(table(rows, [("variant", "variant", ""), ("groups", "groups", ".0f"),
                     ("moving triangles", "moving_triangles", ".0f"),
                     ("CPU ms/spp", lambda r: 1e3 * r["cpu_per_spp_s"], ".2f"),
                     ("÷ static", "over_static", ".2f"),
                     ("image difference", "mean_abs_diff", ".4f")]))
    add("")
    pairs = d["velocity_group_pairs"]
    if pairs:
        p0 = pairs[0]
        ratios = sorted(r["ratio"] for r in pairs)
        med = statistics.median(ratios)
        q1, q3 = ratios[len(ratios) // 4], ratios[(3 * len(ratios)) // 4]
        add(f"**The goal of issue 10** (≤ 1.35× the static time per spp with one moving "
            f"group), measured as a paired statistic (`velocity_groups.pair_rows`): the "
            f"static box and the box as one group rendered alternately {len(pairs)} times "
            f"({p0['width']:.0f}², {p0['spp']:.0f} spp, {p0['threads']:.0f} threads), each "
            "pair's ratio from two renders a second apart, so both see nearly the same "
            f"load: median **{med:.2f}×** (quartiles {q1:.2f}–{q3:.2f}; load "
            f"{min(r['load1'] for r in pairs):.1f}–{max(r['load1'] for r in pairs):.1f}) — "
            f"{'met' if med <= 1.35 else 'not met'}. The table's ratio of medians above "
            "swings by ±0.15 from run to run on this shared machine. The static path pays "
            "nothing for moving objects (a scene without them never builds a "
            "`MovingScene`, and nothing is pending on its paths).\n")
    add("Like for like, both sides here are traced one path at a time "
        "(`render/whole_paths.py`; the static box with `FrameRenderer.lane_paths` off): "
        "the renderer itself traces the static box in SIMD lanes (`render/lane_paths.py`, "
        "§6), which moving scenes do not take, so against what it really runs for the "
        "static box a moving group costs more (§6's per-scene profile: the moving column "
        "against the Cornell column). **Correction**: from 2026-11-26 14:07 this "
        "benchmark's static box was set to the wavefront integrator, like the moving "
        "scenes were then; when moving scenes took whole paths (21:00) it stayed there, "
        "so the 1.17× (quartiles 1.15–1.19) and 1.40× (four groups) of the run at 21:09 "
        "compared moving whole paths with the static wavefront, not like for like. The "
        "figures above are this run's, both sides as whole paths.\n")
    add("A Lambert scene with moving bodies is traced as whole paths "
        "(`render/whole_paths.py`, since 2026-11-26 21:00; §6); the wavefront integrator "
        "takes the others (glossy or glass lobes, alpha masks, area-light quads, the "
        "denoising features). In both, "
        "each lab ray is carried through the static BVH and every segment in one compiled "
        "loop (`rest_frames.nearest_ray`, called per ray by the whole-path kernel and by "
        "`rest_frames.moving_hits` for a wavefront; shadow rays `rest_frames.blocked_ray`, "
        "called from inside either kernel): the static BVH only when the ray meets its box (with "
        "the whole room moving it holds only the light), then per segment the rest-frame "
        "ray (the boosted origin event and B = k d_u, whose parameter is the lab "
        "distance; the emission window, a bounding-sphere and a bounding-box test: "
        "`rest_frames.rest_ray`, `reaches_box`) and, if it can reach the group, Embree's "
        "query on the group's BVH. No pass, buffer or Python call per group: a group costs its "
        "rest-frame arithmetic and its traversals. A ray that leaves a moving body carries "
        "its form in that body's rest frame (origin, direction, k = D_out, written where the "
        "bounce happened), so the segment it leaves needs no "
        "transform (`rest_frames.nearest_ray`), and when it lands on a body of the same "
        "segment again, the kernel keeps its rest-frame direction and lanes: D_u = 1/D_out "
        "exactly, so the lanes' pending shift cancels and only the D_out⁵ is undone (no "
        "aberration, no logarithm). A hit entering a body from the lab costs an aberration "
        "and a Doppler factor, leaving it another, and next-event estimation from it a "
        "third of each; the lanes' shift as the path leaves a body waits for its next hit, "
        "where one logarithm serves both (`integrator.pending_shift`).\n")
    rays = d["moving_rays"]
    if rays:
        add(f"**One ray's cost** (`python -m relray.bench.moving_rays`, in the `moving` "
            f"section: {rays[0]['rays']:.0f} random rays from inside the box, the box static "
            "and as one slowly moving group, thread CPU ns per ray, medians of 7 "
            "alternated rounds):\n")
        add(table(rays, [("query", "query", ""), ("ns per ray", "ns_per_ray", ".1f")]))
        add("")
        add("Embree costs the same in the group's BVH as in the static one (the whole "
            "difference of the moving scene is the light's box test and BVH, and the "
            "rest-frame arithmetic of about 30 ns per ray); a ray that carries its "
            "rest-frame form saves the arithmetic, about half of the difference here.\n")
    add("What this round changed for moving scenes (issue 10's last goal): "
        "`MovingScene.occluded` (the star pass) paid a reference-count increment and "
        "decrement per array of the segment table for every ray (its inlined helpers "
        "read eleven arrays): `moving_hits` and `moving_blocked` are now compiled "
        "without reference counting (`_nrt=False`, the caller passes the RTCRayHit "
        "buffer), 236 → 124 ns per shadow ray measured by hand; the segment table is "
        "three arrays (one float64 row per segment, with γ and γ²/(γ+1) precomputed), so "
        "`blocked_ray`, which the shade kernel calls per shadow ray, receives three array "
        "descriptors instead of eleven; `aberrate_doppler_ray` normalises with one "
        "division (the unnormalised direction's length is 1 - β·d' itself), no square "
        "root; continuation rays carry their rest-frame form, and a ray back on the body "
        "it left skips the frame change (above). The images are the same (the Penrose–"
        "Terrell preset, frame 11, 8 spp: mean relative difference 5e-12 against the "
        "code before the round).\n")
    add("Next steps, by expected gain: (1) a shadow ray from a moving vertex written in "
        "its rest frame too (its origin needs no boost; the direction towards a finite "
        "light still needs the aberration); (2) a bounding box per group instead of a "
        "sphere (for small moving objects; the whole room meets either); (3) next-event "
        "estimation at a moving vertex looks the light's spectrum up per lane for every "
        "sample (the per-path cache serves only vertices at rest in the lab).\n")
    noise = d["moving_emitter_noise"]
    if noise:
        n0 = noise[0]
        add("**Moving lights.** An emitter moving at a constant velocity is sampled by "
            "next-event estimation in its rest frame (the shading event seen there, the "
            "light-travel time its rest-frame distance; the pdf per lab solid angle "
            "p_rest D_e², its spectrum D_e⁵ L(D_e λ)), with MIS against BSDF sampling; "
            "an emitter on a worldline of several segments is reached by BSDF sampling "
            "only (its MIS weight is 1), as is a moving emitter seen from another moving "
            "body (from a point of its own body both rest in one frame, where it is "
            f"sampled as in a static scene). The noise each costs, Cornell box {n0['width']:.0f}², "
            f"{n0['spp']:.0f} spp, relative MSE against a {n0['ref_spp']:.0f}-spp "
            "reference of the light at rest:\n")
        add(table(noise, [("variant", "variant", ""), ("relative MSE", "rel_mse", ".4f"),
                          ("÷ static", "mse_over_static", ".2f"),
                          ("CPU ms/spp", lambda r: 1e3 * r["cpu_per_spp_s"], ".2f")]))
        add("")


def _section_profile(add, d, plots, md, meta) -> None:
    add("## 6. Profile of a Cornell render\n")
    pr = d["profile"]
    tp = [r for r in d["throughput"] if r.get("mode") == "cie1931"]
    if not pr or not tp:
        add("Not run.\n")
        return
    t = tp[0]
    add(f"Command: `.venv/bin/python bench/throughput.py presets/cornell.toml --spp "
        f"{t['spp']} --threads 1 --profile` (the same numbers are in "
        "`bench/results/profile.csv`). Cornell box "
        f"{t['width']}², spectral (cie1931) with NEE, 1 thread. Each stage is timed with "
        "the thread's CPU clock by wrapping the core's functions "
        "(`relray.bench.throughput.StageMeter`); nested stages are exclusive.\n")
    _img(add, plots, "profile", md, "profile")
    add(table(pr, [("stage", "stage", ""), ("CPU s", "seconds", ".3f"),
                   ("share %", lambda r: 100 * r["share"], ".1f"),
                   ("ns per path", "ns_per_path", ".0f")]))
    add(f"\nTotal {1e9 * t['cpu_s'] / t['paths']:.0f} ns of CPU per path "
        f"({t['paths_per_cpu_s'] / 1e6:.2f} M paths per CPU-second), "
        f"{t['intersect_rays'] / t['paths']:.2f} intersect and "
        f"{t['occluded_rays'] / t['paths']:.2f} shadow rays per path.\n")
    sb = d["shade_breakdown"]
    if sb:
        add("Inside the shade kernel (`integrator.shade` re-run on wavefronts captured from a "
            "render; ns per shaded ray, the best of 5):\n")
        add(table(sb, [("bounce", "depth", ".0f"), ("rays", "rays", ".0f"),
                       ("full", "full_ns", ".0f"), ("without NEE", "no_nee_ns", ".0f"),
                       ("emission only", "emission_only_ns", ".0f"),
                       ("1 lane instead of 4", "one_lane_ns", ".0f"),
                       ("shadow rays left to trace", "shadows_later_ns", ".0f"),
                       ("fastmath recompile", "fastmath_ns", ".0f")]))
        add("\nThe kernel traces its shadow rays itself (`rest_frames.blocked1` calls "
            "Embree's `rtcOccluded1`), so *full* includes their Embree queries; *shadow "
            "rays left to trace* is the kernel as it runs with alpha-masked materials "
            "(the rays written to a buffer and traced after it): the difference is what "
            "the shadow rays cost inside it.\n")
    _section_profile_scenes(add, d)
    _section_path_floor(add, d)


def _section_path_floor(add, d) -> None:
    rows = d["path_floor"]
    if not rows:
        return
    r0 = rows[0]
    add(f"### SIMD lanes, whole paths, and the floor they show\n\n`.venv/bin/python -m "
        f"relray.bench.path_floor --scene S --size {r0['size']:.0f} --spp {r0['spp']:.0f}` "
        "(`bench/results/path_floor.csv`; the `profiles` section of `make bench`). The "
        "Cornell box, the heavy scene and the environment-lit scene are static and "
        "Lambert, so whole paths apply (`render/whole_paths.py`: each "
        "path to its end in one loop, Embree called from it, its state in registers); the "
        "renderer traces all three sixteen at a time in SIMD lanes (the environment-lit "
        "scene since 2026-11-27 06:00) "
        "(`render/lane_paths.py`: the same estimator, the lanes' state as structure of "
        "arrays on the kernel's stack, their shading compiled to 16-lane vector code, "
        "their rays in Embree's 16-ray packets). On the same camera rays, keys and hero "
        f"lanes, one thread, thread CPU ns per path, the fastest of {r0['reps']:.0f} "
        "alternated runs: the wavefront integrator (`integrator.trace`, which the renderer "
        "runs where whole paths do not apply: glossy or glass lobes, alpha masks, "
        "area-light quads, denoising features), the whole-path kernel, the lane kernel, "
        "Embree alone on each kernel's own rays (recorded, then traced again in the same "
        "order: one ray at a time for the whole paths, the same packets for the lanes), "
        "and the random numbers alone that those paths draw. *moving* is the peers' moving "
        "scene (§2: the box dealt into four bodies at β = 10⁻⁴), which the renderer traces "
        "in SIMD lanes since 2026-11-28 (the lanes trace its rays one at a time through the "
        "bodies' rest frames, as whole paths do); its *Embree alone* is the rest-frame "
        "traversal of the whole-path kernel's recorded rays (the lanes' own Embree column) "
        "(their lab times, and the rest-frame form "
        "a ray leaving a body carries, recorded too): per ray the static BVH where its box "
        "is met and, per body its rest-frame ray can reach, the boost and that body's "
        "BVH. The integrators compute the "
        "same estimator with the same random numbers: the share of paths whose radiance "
        "differs by more than 1e-4 relative, and the largest difference of a lane's mean "
        "in standard errors, are in the last rows.\n")
    by = {r["scene"]: r for r in rows}
    names = [n for n in ("cornell", "heavy", "environment", "moving") if n in by]

    def ratio(a: str, b: str):
        return lambda r: r.get(a, float("nan")) / r[b] if r.get(a) not in (None, "") \
            else float("nan")

    lines = [("wavefront integrator", "wavefront_ns", ".0f"),
             ("whole-path kernel", "whole_ns", ".0f"),
             ("**lane kernel (16 paths in SIMD lanes)**", "lanes_ns", ".0f"),
             ("whole paths ÷ wavefront", ratio("whole_ns", "wavefront_ns"), ".2f"),
             ("lanes ÷ whole paths", "lanes_over_whole", ".2f"),
             ("Embree alone, on the whole-path kernel's rays (1 ray a query)", "embree_ns",
              ".0f"),
             ("Embree alone, on the lane kernel's packets (as the lanes trace them here)",
              "embree_lanes_ns", ".0f"),
             ("… of it, the packets ray by ray (`rtcIntersect1`)", "embree1_ns", ".0f"),
             ("… of it, the packets as 16-ray queries (`rtcIntersect16`)", "embree16_ns",
              ".0f"),
             ("whole-path kernel outside Embree", "whole_other_ns", ".0f"),
             ("**lane kernel outside Embree**", "lanes_other_ns", ".0f"),
             ("… the random numbers alone, one path at a time", "numbers_ns", ".0f"),
             ("wavefront integrator outside Embree", "wavefront_other_ns", ".0f"),
             ("Embree share of the wavefront integrator %",
              lambda r: 100 * r["wavefront_embree_share"], ".0f"),
             ("Embree share of the whole-path kernel %",
              lambda r: 100 * r["whole_embree_share"], ".0f"),
             ("**Embree share of the lane kernel %** (goal ≥ 60 / 70)",
              lambda r: 100 * r["lanes_embree_share"], ".0f"),
             ("outside Embree ÷ Embree, lanes (goal ≤ 0.67 / 0.43)",
              ratio("lanes_other_ns", "embree_lanes_ns"), ".2f"),
             ("rays per packet of the lanes (of 16)", "lanes_per_packet", ".2f"),
             ("nearest-hit / shadow rays per path",
              lambda r: f"{r['rays_per_path']:.2f} / {r['shadow_rays_per_path']:.2f}", ""),
             ("paths whose radiance differs, whole paths against the wavefront",
              "paths_differing", ".4f"),
             ("paths whose radiance differs, lanes against whole paths",
              "lanes_paths_differing", ".4f"),
             ("largest lane-mean difference (standard errors)", "agreement_z", ".1e"),
             ("load average", "load", ".2f")]
    add("| ns of CPU per path | " + " | ".join(names) + " |\n|---|" + "---|" * len(names))
    for label, key, fmt in lines:
        cells = [_f(key(by[n]) if callable(key) else by[n].get(key), fmt) for n in names]
        add(f"| {label} | " + " | ".join(cells) + " |")
    c = by.get("cornell", r0)
    if _num(c.get("lanes_ns")):
        h = by.get("heavy", {})
        e = by.get("environment", {})
        add(f"\nIn SIMD lanes a Cornell path costs {c['lanes_ns']:.0f} ns against "
            f"{c['whole_ns']:.0f} one path at a time ({c['lanes_over_whole']:.2f}×): Embree "
            f"on the lanes' packets {_f(c.get('embree1_ns'), '.0f')} ns ray by ray and "
            f"{c['embree16_ns']:.0f} as Embree's 16-ray packet queries, against "
            f"{c['embree_ns']:.0f} on the whole paths' rays, the shading "
            f"{c['lanes_other_ns']:.0f} ns against "
            f"{c['whole_other_ns']:.0f}. Embree's share of the lane kernel is "
            f"{100 * c['lanes_embree_share']:.0f} % on the box"
            + (f" and {100 * h['lanes_embree_share']:.0f} % on the heavy scene"
               if _num(h.get("lanes_embree_share")) else "")
            + " (goals 60 % and 70 %). What stays outside Embree is gathers: each hit "
            "reads its triangle (vertex, edges, normal, area, light pmf, material: one "
            "64-byte record since 2026-11-27 09:10, `integrator.triangle_records`, seven "
            "tables before) and eight columns of the reflectance and emission tables per "
            "lane, scattered over memory on the heavy scene (its 1 M triangles miss the "
            "caches: outside Embree a heavy path costs "
            + (f"{h['lanes_other_ns']:.0f} ns against the box's {c['lanes_other_ns']:.0f}"
               f", and {h['whole_other_ns']:.0f} ns one path at a time: there the lanes "
               f"gain in Embree alone, their packets {_f(h.get('embree_lanes_ns'), '.0f')}"
               f" ns against {h['embree_ns']:.0f}, so Embree's share falls"
               if _num(h.get("lanes_other_ns")) else "more than the box's")
            + "); the lanes' refill from the queue and the radiance written back are "
            "scalar. The packed record took the heavy scene's lanes outside Embree from "
            "396 ns per path and an Embree share of 64 % (06:39) to 297 ns and 70 % in a "
            "run by hand (09:10; this run's figures are in the table); the renderer's CPU "
            "per path on the heavy scene 0.95× "
            "(`bench.ab e542f82 --scene heavy`, 6 pairs, quartiles 0.88–1.05), the Cornell "
            "box 0.99× (8 pairs, 0.95–1.02). On the "
            "environment-lit scene the lanes cost "
            + (f"{e['lanes_ns']:.0f} ns against {e['whole_ns']:.0f} one path at a time "
               f"({e['lanes_over_whole']:.2f}×); Embree on their packets "
               f"{_f(e.get('embree_lanes_ns'), '.0f')} ns "
               f"against {e['embree_ns']:.0f}, the rest {e['lanes_other_ns']:.0f} ns against "
               f"{e['whole_other_ns']:.0f}"
               if _num(e.get("lanes_ns")) else "less than its whole paths")
            + ". Its map's lookups are vector code (the escaping rays' (u, v) by polynomial "
            "`acos`/`atan2`, `render/arcs.py`; the texels' spectra from their coefficient "
            "rows gathered into the stack first), the light samples' texels a short scalar "
            "loop of guided searches. What it still costs, by hand (each part removed from "
            "the kernel, or run twice, 2026-11-27 05:50–06:15, ns per path): the two CDF "
            "searches run twice add about 43 (90 as bisections in every lane: nine and ten "
            "dependent gathers from the 263 KB conditional CDF), the texels' sigmoids about 50, "
            "the escaping rays' (u, v), pdf and blend about 30 (the bilinear lookup of camera "
            "rays 23 more), the four `exp` of λ at a path's start about 20. Embree's share "
            "of this scene's lanes is small: its simple geometry takes about 42 ns a ray "
            "(2.45 rays a path), while every escaping ray and every light sample does the "
            "map's work.\n")
    text = moving_floor(d)
    if text:
        add(text + "\n")


def _floor_text(bound: list[float], target: float) -> str:
    """The moving scene's "what stops it" from its floor at the two levels."""
    if not bound:
        return "the rest-frame traversal of each body (§5b, §6)"
    above = [b > target for b in bound]
    if not any(above):
        return (f"not a floor: the rest-frame traversal of each body alone bounds it at "
                f"{_pair(bound)}, under the goal; the rest is the lanes' work outside the "
                "traversal and the renderer's around the kernel (§6, the moving scene's "
                "floor)")
    where = ("" if all(above) else " (above the goal at the "
             + ("high" if above[0] else "low") + " level only)")
    return ("**floor**: "
            + f"the rest-frame traversal of each body alone bounds it at {_pair(bound)}"
            + where + " (§6, the moving scene's floor)")


def moving_floor_bound(d, peer: str = "llvm_ad_spectral") -> list[float]:
    """The moving scene's lower bound of its equal-error ratio to Mitsuba's ``peer`` at
    the two levels (:func:`moving_floor`), empty without the measurements."""
    parts = _moving_floor_parts(d, peer)
    if not parts:
        return []
    _, _, eq, _, bound = parts
    return [bound * eq[0], bound * eq[1]]


def _moving_floor_parts(d, peer: str = "llvm_ad_spectral"):
    """(the moving and the Cornell path floors, Cornell's ratios to Mitsuba's ``peer`` by
    level, the renderer's ns per path outside the kernel scaled to the floor's run, the
    least a moving path costs against a static one), or None without the
    measurements."""
    pf = {r["scene"]: r for r in d["path_floor"]}
    m, c = pf.get("moving", {}), pf.get("cornell", {})
    eq = {int(r["level_index"]): float(r["ratio_relray_over_peer"])
          for r in d["mitsuba_equal_error"]
          if r["peer"] == peer and r["metric"] == "rel_mse"}
    prof = {r["stage"]: r["ns_per_path"] for r in d["profile_scenes"]
            if r["scene"] == "cornell"}
    kern = prof.get("lane-path kernel (16 paths in SIMD lanes, with its Embree packets)", 0.0)
    if not (_num(m.get("embree_ns")) and _num(c.get("lanes_ns")) and 0 in eq and 1 in eq
            and kern > 0):
        return None
    # the profile's own run may be slower or faster than the floor's: its work outside the
    # kernel scaled to the floor's run by the lane kernel's two figures
    out = (prof["total"] - kern) * c["lanes_ns"] / kern
    return m, c, eq, out, (m["embree_ns"] + out) / (c["lanes_ns"] + out)


def moving_floor(d) -> str:
    """The floor of the moving scene against `llvm_ad_spectral` (§6's path floor, §2's
    Cornell ratios, the per-scene profile's work outside the kernels), as a paragraph;
    empty without the measurements."""
    parts = _moving_floor_parts(d)
    if not parts:
        return ""
    m, c, eq, out, bound = parts
    return (
        f"**The moving scene's floor.** Its rest-frame traversal alone costs "
        f"{m['embree_ns']:.0f} ns per path ({m['rays_per_path']:.2f} nearest-hit and "
        f"{m['shadow_rays_per_path']:.2f} shadow rays, four bodies): "
        f"{m['embree_ns'] / c['embree_ns']:.2f}× Embree alone on the static box's rays "
        f"({c['embree_ns']:.0f} ns) and {m['embree_ns'] / c['lanes_ns']:.2f}× the static box's "
        f"whole lane kernel ({c['lanes_ns']:.0f} ns, its shading included). The moving scene "
        "shows the static box's picture with the static box's estimator (the same noise per "
        "sample), and Mitsuba renders both as the box at rest. So even if all of a moving "
        "path's work but its traversal were free, and the renderer's work around the kernel "
        f"(camera, hero wavelengths, film: {out:.0f} ns per path, §6's per-scene profile "
        "scaled to this run) stayed the box's, a moving path would cost "
        f"{bound:.2f}× a static one, and its equal-error CPU time against "
        f"`llvm_ad_spectral` would be at least {bound:.2f} × the box's "
        f"({eq[0]:.2f} / {eq[1]:.2f}, §2) = **{bound * eq[0]:.2f} / {bound * eq[1]:.2f}**. "
        + ("The goal of 1.0 is out of reach while each body is traced in a BVH of its own, "
           "which it must be: a body's BVH is static only in its rest frame, and Embree's "
           "instances apply affine maps to space, not a boost to events (rest_frames.py). "
           if bound * eq[0] > 1.0 else
           "Under the goal: each body must be traced in a BVH of its own (its BVH is static "
           "only in its rest frame, and Embree's instances apply affine maps to space, not a "
           "boost to events, rest_frames.py), but that alone does not stop it. ")
        + f"Whole paths on this scene cost {m['whole_ns']:.0f} ns per path, "
        f"{m['whole_ns'] - m['embree_ns']:.0f} of them outside the traversal"
        + (f"; the SIMD lanes, which the renderer runs here, {m['lanes_ns']:.0f} ns, "
           f"{m['lanes_other_ns']:.0f} outside it." if _num(m.get("lanes_ns")) else "."))


def _num(v: Any) -> bool:
    """Whether ``v`` is a finite number (a CSV cell that was measured)."""
    return isinstance(v, (int, float)) and math.isfinite(v)


def _section_profile_scenes(add, d) -> None:
    rows = d["profile_scenes"]
    if not rows:
        return
    from relray.bench.profile_scenes import SCENES

    scenes = [s for s in SCENES if any(r["scene"] == s for r in rows)]
    totals = {r["scene"]: r for r in rows if r["stage"] == "total"}
    t0 = totals[scenes[0]]
    add(f"### Per scene\n\n`.venv/bin/python -m relray.bench.profile_scenes --size "
        f"{t0['size']:.0f} --spp {t0['spp']:.0f}` (`bench/results/profile_scenes.csv`): "
        f"ns of CPU per path in each stage, {t0['size']:.0f}², {t0['spp']:.0f} spp, 1 "
        "thread, one render each. *cornell*: the box; *heavy*: its displaced-grid floor "
        "(§3); *environment*: ground, sphere and box lit by a map with a small sun (§5d); "
        "*textured*: the textured box (§5e); *moving*: the whole room as one velocity "
        "group (§5b).\n")
    stages = [r["stage"] for r in rows if r["scene"] == scenes[0] and r["stage"] != "total"]
    by = {(r["scene"], r["stage"]): r for r in rows}
    cols = [("stage", "stage", "")] + [
        (s, (lambda r, s=s: by.get((s, r["stage"]), {}).get("ns_per_path", 0.0)), ".0f")
        for s in scenes]
    body = [{"stage": st} for st in stages
            if any(by.get((s, st), {}).get("ns_per_path", 0.0) > 0.5 for s in scenes)]
    body.append({"stage": "**total**"})
    for s in scenes:
        by[(s, "**total**")] = totals[s]
    add(table(body, cols))
    add("\n| | " + " | ".join(scenes) + " |\n|---|" + "---|" * len(scenes))
    add("| M paths per CPU-second | " + " | ".join(
        f"{totals[s]['paths_per_cpu_s'] / 1e6:.2f}" for s in scenes) + " |")
    kernels = ("whole-path kernel (with all its Embree queries)",
               "lane-path kernel (16 paths in SIMD lanes, with its Embree packets)")
    whole = {s for s in scenes
             if any(by.get((s, k), {}).get("ns_per_path", 0.0) > 0 for k in kernels)}
    add("| Embree share % (nearest-hit queries; the shadow rays are traced inside the "
        "shade kernel; –: SIMD lanes or whole paths, Embree inside their kernel, next "
        "table) | "
        + " | ".join("–" if s in whole else f"{100 * totals[s]['embree_share']:.0f}"
                     for s in scenes) + " |")
    add("| rays per path | " + " | ".join(
        f"{totals[s]['rays_per_path']:.2f}" for s in scenes) + " |")
    add("")


def _ns(d, *stages: str) -> float:
    """ns per path of profile stages (by name prefix), from profile.csv."""
    return sum(r["ns_per_path"] for r in d["profile"] if r["stage"].startswith(stages))


def _scene_ns(d, scene: str, *stages: str) -> float:
    """ns per path of one scene's profile stages (by name prefix), from §6's per-scene
    profile (profile_scenes.csv); §1's profile (:func:`_ns`) where that scene has none."""
    rows = [r for r in d["profile_scenes"] if r["scene"] == scene]
    if not rows:
        return _ns(d, *stages)
    return sum(r["ns_per_path"] for r in rows if r["stage"].startswith(stages))


def shadow_embree_ns(d) -> float | None:
    """Estimated ns per path of the shadow rays' Embree queries inside the shade kernel
    (occluded rays per path × Embree's own ns per shadow ray, §3), or None."""
    tp = [r for r in d["throughput"] if r.get("mode") == "cie1931"]
    if not tp or not d["embree_floor"]:
        return None
    t = tp[0]
    return d["embree_floor"][0]["embree_occluded_ns"] * t["occluded_rays"] / t["paths"]



def peer_ratios(d, scene: str) -> tuple[dict, str]:
    """A peer scene's equal-error ratios at equal relative MSE, {(peer, level): ratio},
    and as text: "`llvm_ad_spectral` high / low; `scalar_spectral` …; Cycles …"."""
    ratio = {(r["peer"], int(r["level_index"])): float(r["ratio_relray_over_peer"])
             for r in d["peer_equal_error"]
             if r["scene"] == scene and r["metric"] == "rel_mse"}
    text = "; ".join(
        f"{name} {ratio[(peer, 0)]:.2f} / {ratio[(peer, 1)]:.2f}"
        for peer, name in (("llvm_ad_spectral", "`llvm_ad_spectral`"),
                           ("scalar_spectral", "`scalar_spectral`"), ("cycles", "Cycles"))
        if (peer, 0) in ratio and (peer, 1) in ratio)
    return ratio, text


def _moving_lanes_bullet(add, d) -> None:
    """The 2026-11-28 round: moving bodies in the SIMD lanes (last round's next step 2)."""
    m = {r["scene"]: r for r in d["path_floor"]}.get("moving", {})
    run = ""
    if _num(m.get("lanes_ns")) and _num(m.get("whole_ns")):
        run = (f" In §6's run: the lanes {m['lanes_ns']:.0f} against whole paths' "
               f"{m['whole_ns']:.0f} ns per path ({m['lanes_ns'] / m['whole_ns']:.2f}×), "
               f"{m['lanes_other_ns']:.0f} against {m['whole_other_ns']:.0f} ns outside the "
               f"traversal ({m['embree_ns']:.0f} ns, now "
               f"{100 * m['lanes_embree_share']:.0f} % of a moving path in the lanes).")
    add("- **Moving bodies in the SIMD lanes** (`render/lane_paths.py`, 2026-11-28 06:15–07:45, "
        "AVX2; last round's next step 2): a scene of Lambert bodies that move, glowing or not, "
        "lit by emissive triangles alone (no sky or delta light, no map, no textures: those stay "
        "with whole paths) is traced sixteen paths at a time. Each lane carries its ray's "
        "origin lab time, the segment it leaves, its rest-frame form there and the pending "
        "D_out; its rays are traced one at a time through the bodies' rest frames "
        "(`rest_frames.nearest_one`, `blocked_ray`, as whole paths trace them); the frame "
        "changes are lane arithmetic with selects; a light that moves with a body is sampled "
        "as whole paths sample it (in its rest frame from a static vertex, in the common frame "
        "from its own body, the MIS weights per rest-frame solid angle); a lane whose ray "
        "escapes ends its path and takes the next camera ray before the packet is shaded "
        "(`lane_paths.finish_misses`: without it the lanes cost 1.6× the whole paths on the "
        "train preset, 2.3× on the Terrell preset, where most rays escape; with it 1.15× and "
        "1.04×, and a moving room under a sky and delta lights 1.09×, so moving bodies under a "
        "sky or delta lights stay with whole paths: each lane evaluates every kind of light's "
        "sample there; lit by triangles, a moving room 1.00×, a moving room with its light "
        "0.91×, in one process on the same paths). What it "
        "took: the aberration as a call left the lane loops scalar (the first version cost "
        "1.04–1.09× the whole paths), and inlining the usual form under the lanes' "
        "reassociation could turn (1 − b) − |c|²/2 into 1 − (b + |c|²/2), which loses "
        "1 − cos θ' as b → 1: `relativity.aberrate_doppler_lane` takes 1 − b from the segment "
        "table (`rest_frames.OMB`, exact), and `tests/test_relativity.py` checks it compiled "
        "with the lanes' flags against the per-ray form up to b = 1 − 1e-12; the lanes' shift by "
        "ln D is straight-line code (`rgb_table.doppler_columns`: the exponent by selects, "
        "atanh's series; within 3 ulp of libm's `log`, `tests/test_rgb_table.py`). "
        "`tests/test_lane_paths.py` checks the lanes path by path against whole paths and the "
        "wavefront (two bodies, the room as one body whose rays land on the body they left, "
        "without the Doppler shift or the searchlight factor, a static smooth ball in a moving "
        "room, the light moving alone, with the blocks, or with the room as one body; "
        "spectral, rgb and seed-gaussian; β 0–0.6). On the "
        "peers' moving scene (`bench/path_floor.py --scene moving`, by hand at 06:36): 1747 "
        "against 2176 ns per path (0.80×), 565 against 995 ns outside the traversal. The renderer "
        "(`python -m relray.bench.ab d743b75 --scene peer_moving --pairs 8`, 128², 16 spp, 1 "
        "thread): **0.86×** (quartiles 0.77–0.97; 2507 → 2068 ns)." + run)


def _camera_block_bullet(add, d) -> None:
    """The 2026-11-28 round: the camera stage's loop made vector code again on AVX2."""
    add("- **The camera rays on AVX2** (`render/camera.py`, 2026-11-28 02:25–02:35): §6's "
        "per-scene profile of 2026-11-27 22:36 gave the camera stage 66–81 ns per path on this "
        "AVX2 machine (the ray kernel alone about 60); this run's gives 25–42. Two things kept "
        "`_primary_rays`' loop of 16 rays from LLVM's vector code here: the pixel's column and "
        "row by `divmod` (a 64-bit integer division per ray, which no SIMD unit has; now "
        "`camera.pixel_column_row`: ⌊(p + ½)·(1/w)⌋ in float64, exact up to the job's limits of "
        "2³¹ pixels and 2¹⁵ columns, `tests/test_camera.py` checks it against `divmod` at every "
        "row boundary) and the camera's two tests (β > 0, outside the bounding sphere), the same "
        "for every ray but branches inside the loop (now constants of one of four copies of the "
        "block loop, `camera.camera_ray_as`). The rays are bit-identical; the camera stage alone "
        "(in one process against the code before, 15 alternated pairs, 262 144 rays): **0.41×** "
        "at rest (63 → 26 ns per ray) and 0.41× for a moving camera outside the sphere (85 → 34 "
        "ns). The renderer's CPU per path (`python -m relray.bench.ab ef9d92a --scene S`, 8 "
        "alternated pairs, 128², 16 spp, 1 thread, with a clean-clone CI run beside it): Cornell "
        "**0.93×** (quartiles 0.86–1.04; 1156 → 1088 ns), environment-lit **0.94×** (0.78–1.15; "
        "945 → 886 ns). Looked at and left: the Sobol points' hashing (about 8 ns per `sobol2` on "
        "AVX2 in vector code; its 32-bit multiplies written as 32-bit gained nothing, LLVM had "
        "narrowed them already) and the hero wavelengths' lanes (37–40 ns per path; an int32 cell "
        "index, or blocks of 16 in stack memory, gained nothing measurable).")


def _body_bounds_bullet(add, d) -> None:
    """The 2026-11-28 round: the moving bodies' rest-frame traversal (a box per body, the
    lab-distance parameterisation), what its cost is made of, and what was dropped."""
    add("- **The bodies' rest-frame traversal** (`render/rest_frames.py`, 2026-11-28 01:40–02:20, "
        "AVX2; last round's next step 4): a body was traced wherever its rest-frame ray reached "
        "its bounding sphere; now also only where it meets its bounding box in its rest frame "
        "(`rest_frames.reaches_box`; the sphere stays as the first, cheaper test). On the peers' "
        "moving scene (the box as four bodies, §2) the kernel's nearest-hit rays reached 2.71 "
        "bodies' spheres each and reach 2.25 bodies' boxes, its shadow rays 2.91 and 2.57 (the "
        "wall bodies' boxes are the room, the blocks' much smaller than their spheres). The "
        "rest-frame ray is now parameterised by the lab distance: the lab point o + s d at lab "
        "time t − s is the rest-frame point x_u(0) + s B with B = C⁻¹(d + u) = k d_u (C the "
        "contraction along u), so Embree's distance along B is the lab distance and neither d_u "
        "nor k = γ(1 + u·d) needs a division (`rest_frames.rest_ray`, in the aberration's "
        "cancellation-free chord form; the hits agree with the old form's to float32 rounding: "
        "the same triangles and bodies on every recorded ray, the distances within 8e-6 relative, "
        "2e-7 at the 99th percentile). Embree alone on the kernel's recorded rays (`path_floor`'s "
        "replay, in one process against the previous code, 15 alternated pairs, 128², 8 spp): "
        "**0.96×** (quartiles 0.95–0.97; 1064 → 1026 ns per path), of which the box test alone "
        "0.94× (0.91–0.98, the same code with the box set to infinity). The renderer on that "
        "scene (`python -m relray.bench.ab 0a8e080 --scene peer_moving --pairs 10`, 128², 16 spp, "
        "1 thread, with a clean-clone CI run beside it): **0.97×** (quartiles 0.93–0.98; 2255 → "
        "2244 ns per path in medians, 6 pairs before gave 0.86×, quartiles 0.78–1.19). "
        "`tests/test_rest_frames.py` checks that the sphere and the box change no hit and no "
        "occlusion (a thin tilted group, rays from inside and outside, grazing and ending short, "
        "β 0–0.99), and that each bound does leave rays out (a smaller box or sphere fails it). "
        "**What the traversal is made of**: of the 1145 ns per path that Embree alone costs on "
        "this scene, 391 remain with the bodies' Embree queries taken out (the boosts, the "
        "bounds, the static BVH's box test, the calls' set-up): the queries themselves cost about "
        "750 ns, 14.6 per path (8.9 nearest-hit, 5.6 shadow) at about 52 ns each on BVHs of 8–9 "
        "triangles, where a query's fixed cost dominates. The static BVH (the light) is met by "
        "0.7 % of the nearest-hit rays and none of the shadow rays. Tried and dropped: the "
        "segments' rest-frame rays computed first, side by side in stack memory, then traced (so "
        "the out-of-order core overlaps the segments' arithmetic): 1.04× the one-pass loop, "
        "slower. perf on the whole-path kernel (its JIT code mapped by hand) finds no hot spot in "
        "its own code: the hottest window of 32 instructions holds 5.7 % of its samples (a "
        "normalisation's square root and division).")


def _lane_rays_bullet(add, d) -> None:
    """The 2026-11-27 late round: the lanes' rays traced one at a time, the first image's
    garbage collection, and what was measured and dropped."""
    pf = {r["scene"]: r for r in d["path_floor"]}
    c = pf.get("cornell", {})
    replay = (f" (§6's run: {c['embree_lanes_ns']:.0f} against {c['embree16_ns']:.0f})"
              if _num(c.get("embree_lanes_ns")) and _num(c.get("embree16_ns")) else "")
    add("- **The lanes' rays one at a time** (`render/embree.py`, `render/lane_paths.py`, "
        "2026-11-27 21:45–23:25): the lanes traced each bounce's sixteen rays by "
        "`rtcIntersect16`/`rtcOccluded16`; on AVX2, Embree now traces them one at a time by "
        "`rtcIntersect1`/`rtcOccluded1` (`embree.intersect_lanes`, `occluded_lanes`: each "
        "valid lane's ray copied into one `RTCRayHit` on the kernel's stack and its hit "
        "copied back), with the packet layout and the vector shading unchanged. Embree "
        "alone on the Cornell lanes' recorded packets costs 591 ns per path ray by ray "
        f"against 617 as 16-ray packets (by hand, 22:05){replay}. The lane kernel against "
        "the code before, in three alternated `path_floor --scene cornell` pairs "
        "(22:10–22:18), took 769 against 938, 761 against 790 and 787 against 789 ns per "
        "path. The renderer's CPU per path (`bench.ab 3c18d92 --scene S`, 6–8 alternated "
        "pairs) was 0.85× and 0.96× on the Cornell box in two runs (quartiles 0.78–0.95 "
        "and 0.91–1.09), 0.88× on the environment-lit scene (0.80–1.13), 0.94× on the "
        "heavy scene (0.88–1.14) and 1.01× on the textured box (0.97–1.06). That is a few "
        "per cent on scenes with few triangles, on a machine about twice as slow as in "
        "the earlier runs today, and noisy, and one without AVX-512: Embree emulates "
        "its 16-ray packets there. Where it runs them natively (AVX-512) they measured "
        "cheaper than single rays (312 ns per Cornell path against 363 for the whole "
        "paths' rays, the heavy scene's 639 against 750, at 19:01), so the lanes keep "
        "them there: `lane_paths.PACKETS` "
        "(`embree.native_packets`, LLVM's host features) is a compile-time constant of "
        "the lane kernel, and §6 replays the lanes' packets both ways on every run. "
        "Ray by ray the lanes' hits are bit for bit those of the whole paths "
        "(`tests/test_embree.py`: lane by lane equals `intersect1`; the packets agree "
        "within a tolerance), and `tests/test_lane_paths.py` traces the same paths both "
        "ways on any machine.")
    add("- **The first image's garbage collection** (`relray/__init__.py`, 21:25–21:40): "
        "a warm `relray render presets/cornell.toml --spp 1` spent about a quarter of its "
        "time walking numba's ~180 000 objects. Part of it was collections during the "
        "imports and the first kernel load (0.195 s of CPU, by `gc.callbacks`). Most "
        "was the interpreter's last collection as it exits, after the files are written: "
        "the process ended 0.56–0.60 s after the command returned. `relray.cli_main` now "
        "keeps the collector off during the imports, freezes their objects "
        "(`gc.freeze`), and freezes everything again when the command is done. After the "
        "change, collections during the run take 0.017 s and the exit 0.03 s. Warm, from "
        "process start to exit, new ÷ old in 9 alternated pairs (the old `cli_main` "
        "from the commit before, 21:39): **0.66×** (quartiles 0.60–0.71; medians 1.77 "
        "against 2.74 s). This session's machine ran the old code in 2.3–2.7 s, where "
        "the run of 18:54 measured 1.12 s, so §5c's figure of this run cannot be set "
        "against the earlier ones. Each section now records the interpreter's speed "
        "(the sections' table: the CPU time of a fixed Python loop), so that runs on "
        "different machines can be told apart. `tests/test_cli.py` checks both freezes, "
        "that no collection runs during the imports, and that the collector is on during "
        "the command.")
    add("- Tried and dropped this round, by hand on 262 144 paths: the sensor values "
        "folded into the film's accumulation (next step 6). One fused loop cost 32–35 ns "
        "per path against 44–45 ns for the two passes: about 1 % of a Cornell path, for "
        "a second accumulate beside `Film.add_samples`. The hero wavelengths' table rows "
        "packed into one 64-byte record per cell: 65–73 against 53–70 ns, no gain. The "
        "hero pass in blocks of 16 on the stack, for vector code: 60–80 against 44–73 "
        "ns, slower. pydantic's deferred schema build for the job's tables: 0.29–0.32 s "
        "against 0.31–0.33 s for the import and the parse, nothing.")


def _map_light_bullet(add, d) -> None:
    """The 2026-11-27 night round: the environment-lit scene's lanes (the map's λ in
    vector code, a kernel for the map as the only light, searches only where a light
    sample is made), and the alias table tried for the map's texels."""
    pf = {r["scene"]: r for r in d["path_floor"]}
    env = pf.get("environment", {})
    lanes = (f" (§6's run: {env['lanes_ns']:.0f} ns per path in the lanes, "
             f"{env['whole_ns']:.0f} as whole paths)"
             if _num(env.get("lanes_ns")) and _num(env.get("whole_ns")) else "")
    add("- **The environment-lit scene's lanes** (`render/lane_paths.py`, "
        "`physics/rgb_table.py`, 2026-11-27 18:05–18:50; the lane kernel's cycle counts, "
        "by stage, found each cost): (1) the lanes that take a new path got the map's "
        "λ and E(λ) from libm's `exp` and two compiled-apart lerps per lane in the scalar "
        "refill; they now come from one loop over the 16 lanes (`env_refill`), λ by "
        "`rgb_table.lambda_of_grid_column` — 2ⁿ by selects over n's bits and e^r by its "
        "Taylor series through r¹³, within 4e-16 of libm's `exp` over the whole grid and "
        "packed code without a call (`tests/test_rgb_table.py`): the refill 51 → 35 ns "
        "per path; (2) a lane kernel per kind of lights (`lane_paths.light_kind`: "
        "`TRIANGLE_LIGHTS`, `ANY_LIGHTS`, `MAP_LIGHT`, a compile-time constant like the "
        "other flags): with the map as the only light and no material emitting (an "
        "HDRI-lit scene) no other light's sample is made (the light samples and "
        "continuations 62 → 28 ns) and the hits look up no emission (50 → 31 ns); a "
        "material that glows only outside the visible keeps the lookup "
        "(`tests/test_lane_paths.py`: a ground glowing at 0.9–1.3 µm under the map, "
        "seen at β = 0.6, where 60 % of the paths differ without it), and the warm-up "
        "renders the map-lit kinds; (3) the map's two CDF searches only for the lanes "
        "whose path goes on (an escaped ray or a last bounce makes no light sample): "
        "54 → 35 ns with the texels' sigmoids. The renderer's CPU per path on that scene "
        "against the code before (`python -m relray.bench.ab 6adeacd --scene "
        "environment`, 6 alternated pairs, 128², 16 spp, 1 thread): (1) and (2) **0.89×** "
        "(quartiles 0.88–0.92; 482 → 430 ns), with (3) **0.85×** (0.82–0.89; 484 → 410), "
        "with the emission left out **0.79×** (0.73–0.82; 493 → 393, 18:51); the Cornell "
        f"box unchanged (1.00×, quartiles 1.00–1.01){lanes}. "
        "Tried and dropped: the map's texel drawn from an alias table over all texels "
        "(Walker/Vose: one cell read, vector code; the searches 50 → 22 ns), because it "
        "throws away what the two-dimensional inversion keeps, the stratification of the "
        "Sobol points over the map: on `tests/test_environment.py`'s bright patch under "
        "a dim sky (NEE + MIS, 24², the quadrature as truth) its relative RMS error per "
        "pixel was 0.052 / 0.051 against 0.024 / 0.021 at 32 spp and 0.026 / 0.024 "
        "against 0.0069 / 0.0069 at 128 spp (two seeds): 5–14× the MSE for 4 % of the "
        "time; the CDF searches as branch-free steps over the lanes again (53–56 against "
        "58 ns with the counters: noise).")


def _hero_table_bullet(add, d) -> None:
    """The 2026-11-27 evening round: the hero wavelengths from a table, the light pick
    as a count, and a cycle-counter profile of the lane kernel."""
    pf = {r["scene"]: r for r in d["path_floor"]}
    c = pf.get("cornell", {})
    box = (f"in §6's run the box's lanes spend {c['lanes_other_ns']:.0f} ns per path "
           f"outside Embree, Embree's share {100 * c['lanes_embree_share']:.1f} %"
           if _num(c.get("lanes_other_ns")) else "")
    add("- **The hero wavelengths from an inverse-CDF table** (`physics/spectrum.py`, "
        "2026-11-27 15:00–15:40; last round's next step 8): `WavelengthSampler` now "
        "tabulates the bins' inverse CDF at u = g/8192 (`inv_nm`), and u in cell g maps "
        "linearly to λ in [λ_g, λ_(g+1)): two gathers and no search, where the guided "
        "search walked up to six dependent steps. The sampled pdf is the cell's, "
        "(1/G)/(λ_(g+1) − λ_g) (`pdf_at`, exact for every λ drawn): the bins' pdf "
        "(physics.md: ∝ |r̄|+|ḡ|+|b̄|, an inverse-CDF table) inside a bin, between the "
        "covered bins' values across an edge; `tests/test_spectrum.py` checks both, and "
        "the histograms against the table's own CDF (1 nm and 0.1 nm bins). Compiled "
        "with fused multiply-adds and unsigned cell indices, the camera stage's spectral "
        "pass costs 23 ns per path in the renderer (42 before; Cornell 128², 16 spp, "
        "65 536-path wavefronts, by hand). Vectorising it gains nothing more: the stores "
        "of λ, pdf and table coordinates (88 bytes per path) bound it. "
        "**The light pick as a count** (`render/lane_paths.py`): `pick_lights` bisected "
        "the light CDF in every lane; on the Cornell box (a CDF of three entries, the "
        "light's two triangles at 0.5) each step is a branch that the lanes' random "
        "numbers make unpredictable, 42 ns per path by a cycle counter in the kernel "
        "(`llvm.readcyclecounter` around each stage, a throw-away copy of the kernel). A "
        "CDF of up to 64 entries is now counted, #{k: cdf[k] ≤ u}, one broadcast compare "
        "and add per entry over the sixteen lanes (vector code, no branch): 4 ns; "
        "`path_floor --scene cornell` 510 → 476 ns per path (two alternated pairs, by "
        "hand at 15:40); `tests/test_lane_paths.py` checks the count and the bisection "
        f"against `searchsorted` (a `<` for `≤` was caught){'; ' + box if box else ''}. "
        "The renderer's CPU per path against the code before this round "
        "(`python -m relray.bench.ab 7faced5 --scene S`, 6 alternated pairs, 128², "
        "16 spp, 1 thread, 15:56–15:59): Cornell **0.92×** (quartiles 0.92–0.93; "
        "631 → 581 ns), environment-lit 0.95× (0.88–0.99; 500 → 476), heavy 0.96× "
        "(0.92–0.98; 979 → 922), textured 0.96× (0.95–0.98; 1149 → 1115). "
        "Where the environment-lit scene's lane kernel spends its time, by the same "
        "cycle counter (380 ns per path with the counters): the refill of new paths 51, "
        "`rtcIntersect16` with the prefetch and the numbers 84, the hits 50, the "
        "escaping rays' map lookups 37, the light samples' texels (searches and "
        "sigmoids) 55, the light samples and continuations 62, `rtcOccluded16` 26. "
        "Tried there and dropped (`path_floor --scene environment`, alternated by "
        "hand): the light samples' two CDF searches as vector code (a gather and a "
        "select per step, the rare longer walks scalar: 371 against 373 ns); the texels' "
        "sigmoids in single precision (354–375 against 367–374: noise); the refill and "
        "the write-back without a branch on which lanes ended (a branch-free queue walk, "
        "the new paths' rays as gathers and selects, every lane's radiance written each "
        "packet: 476 against 480 on the box, 388–392 against 381–382 on the map).")


def _lane_numbers_bullet(add, d) -> None:
    """The 2026-11-27 afternoon round: the lanes' numbers, indices and prefetches, the
    camera rays in blocks."""
    pf = {r["scene"]: r for r in d["path_floor"]}
    shares = "; ".join(
        f"{name} {pf[k]['lanes_other_ns']:.0f} ns outside Embree, Embree's share "
        f"{100 * pf[k]['lanes_embree_share']:.1f} %"
        for k, name in (("cornell", "the box"), ("heavy", "the heavy scene"))
        if _num(pf.get(k, {}).get("lanes_other_ns")))
    add("- **The lanes' work outside Embree** (`render/lane_paths.py`, `render/sampling.py`, "
        "`render/prefetch.py`, 2026-11-27 12:10–12:45; found by taking each part out of "
        "the Cornell lane kernel in turn, `path_floor --scene cornell`): (a) Sobol's "
        "dimension 1 came from a byte table, four 64-bit gathers per point in every lane "
        "(about 17 ns per path); it is now the superset transform its direction numbers "
        "are (Pascal's triangle mod 2: digit j of x_i is the xor of i's bits k ⊇ j, five "
        "shift-and-xor steps, `sampling.sobol1_reversed`; the same numbers bit for bit, "
        "`tests/test_sampling.py` checks it against the direction numbers at every bit "
        "and at 2000 random indices); (b) numba turns a negative signed index into one "
        "from the end, a sign test, a mask and an add per gather in vector code; the "
        "lanes' table rows and columns, triangle and light indices now index as "
        "unsigned (`lane_paths.lane_lerp`; about 14 ns); (c) the hit triangles' records "
        "are prefetched (`llvm.prefetch` from numba, `prefetch.prefetch_row`) right "
        "after `rtcIntersect16` returns, and the bounce's numbers are drawn before the "
        "records are gathered (`lane_paths.bounce_numbers`), so the heavy scene's cache "
        "misses overlap the hashing (about 250 → 220 ns outside Embree by hand; the "
        "prefetch alone or the new order alone gained nothing). By hand at 12:40 the "
        "box's lanes spend 190 ns per path outside Embree (223 before), Embree's share "
        f"62 %; in §6's run: {shares}. "
        "**The camera rays in blocks** (`render/camera.py`): `_primary_rays` computes 16 "
        "rays at a time into the kernel's stack memory, where LLVM vectorises the loop "
        "(written straight into the output arrays it stayed scalar), then copies them "
        "out: 25 → 13 ns per path at rest, 54 → 16 ns for a moving camera outside the "
        "bounding sphere (65 536 rays, bit-identical, `tests/test_camera.py` checks every "
        "path of a partial last block against `camera.camera_ray` alone); the keys, rays "
        "and hero offsets go into the chunk's kept buffers (fresh multi-MB arrays cost a "
        "page fault per 4 KiB on every wavefront). The renderer's CPU per path against "
        "the code before this round (`python -m relray.bench.ab 8097bb5 --scene S`, 6 "
        "alternated pairs, 128², 16 spp, 1 thread, 12:59–13:01): Cornell **0.93×** "
        "(quartiles 0.92–0.95; 664 → 621 ns), heavy **0.91×** (0.88–0.92; 1027 → 923 ns); "
        "the camera stage's part alone (against f9e57e1) 0.97× (0.94–1.01). Tried and "
        "dropped: the lanes' reflectance table in float32 (the mixed precision cost more, "
        "223 ns); the emission's gathers only where a lane sees an emitter (masked gathers: "
        "no gain); Embree's high build quality (no change on either scene); the hero "
        "wavelengths' inverse CDF in blocks of 16 (37 against 40 ns per path: its guided "
        "search and the per-path Doppler work stay scalar, and the stack memory it needs "
        "lives in the render layer, below which the sampler sits); the sensor values in "
        "blocks (slower: 20 against 13 ns).")


def _floors_bullet(add, d) -> None:
    """The 2026-11-27 late-morning round: the goals table, the moving scene's floor, the
    packed triangle record, the inlined texture lookups."""
    pf = {r["scene"]: r for r in d["path_floor"]}
    h = pf.get("heavy", {})
    heavy = (f"in §6's run the heavy scene's lanes spend {h['lanes_other_ns']:.0f} ns per "
             f"path outside Embree and Embree's share is {100 * h['lanes_embree_share']:.1f} %"
             " (396 ns and 64 % at 06:39" if _num(h.get("lanes_other_ns"))
             else "the heavy scene's lanes outside Embree 396 → 297 ns per path (")
    bound = moving_floor_bound(d)
    floor = (f"it bounds that scene's ratio to `llvm_ad_spectral` at {_pair(bound)}, above "
             "the goal of 1 whatever the shading costs" if bound
             else "the bound needs §2's Mitsuba run")
    text = (
        "- **The goals of issue 12 in one table** (the headline above), each met or with "
        "the floor or the cost that stops it. **The moving scene's floor** (§6): whole "
        "paths now record each ray's lab time, the segment it leaves and its rest-frame "
        "form (`whole_paths.ray_log`; `tests/test_whole_paths.py` traces the log again "
        "and finds the kernel's own hits), so `bench/path_floor.py` replays the moving "
        f"scene's rays through the rest-frame traversal alone: {floor}. **A packed record "
        "per triangle** for the SIMD lanes' hits (`integrator.triangle_records`: v0, "
        "edges, normal, area, light pmf, material in one 64-byte row; "
        f"`tests/test_integrator.py`): {heavy}; 297 ns and 70.3 % in a run by hand at "
        "09:10); the renderer's CPU per path 0.95× on the heavy scene (`bench.ab e542f82 "
        "--scene heavy`, 6 pairs, quartiles 0.88–1.05), 0.99× on the box (8 pairs, "
        "0.95–1.02), for 64 bytes more per triangle. **The texture lookups inlined** into "
        "the Lambert kernels (`textures.*_of`, at one call site for the four slots; "
        "`integrator.shade` keeps the compiled-apart wrappers): the textured box 0.89× "
        "(`bench.ab 7a57ca7 --scene textured`, 6 pairs, quartiles 0.86–0.92); its lane "
        "kernel's first compile 33 s against 23 s (78 s with a call site per slot, 0.87×), "
        "`python -m relray.core.warmup` with an empty cache 247 s against 195 s (by hand, "
        "10:25–10:32; "
        "a session before tried them inlined per call site by hand and dropped them for "
        "that compile time, 0.96× then).")
    _, tex_peers = peer_ratios(d, "textured")
    if tex_peers:
        text += (" Equal-error CPU time on the textured box at the high / low level (§2, "
                 f"relative MSE): {tex_peers} (06:33: 1.03 / 0.67, 0.27 / 0.18, 0.15 / 0.11).")
    add(text)


def _env_lanes_bullet(add, d) -> None:
    """The 2026-11-27 morning round: colour environment maps in the SIMD lanes."""
    peers = bool(peer_ratios(d, "environment")[1])
    env_ns = ("554 ns per path in the per-scene profile at 06:07, before the guided "
              "searches (676 at 02:51, whole paths; the profile of this run came in a slow "
              "phase of the machine, every scene about 1.3× its 06:07 figure)")
    add("- **Environment maps in the SIMD lanes** (`render/lane_paths.py`, 2026-11-27 "
        "05:40; last round's next step 1, the map's part): a static scene under a colour "
        "map (RGB-emitter texels; a spectral map's bands stay with whole paths) is now "
        "traced sixteen paths at a time, with textures or without. The map's lookups are "
        "vector code: `acos`/`atan2` as branch-free polynomials "
        "(`render/arcs.py`, within 1e-15 of libm's, `tests/test_arcs.py`, which also "
        "checks that a loop of them compiles to packed code without libm calls), the "
        "sampler's sin/cos by `sampling.sincos_2pi` (its series now through θ¹⁶, 4e-16: "
        "near the poles sin θ comes back as √(1 − cos²θ), where the old 2e-9 moved the "
        "pdf there by up to 5e-5 relative), the escaping rays' texels, MIS "
        "weights and bilinear weights (`env_misses`), and the texels' spectra from their "
        "(c0, c1, c2, k) rows gathered into the kernel's stack first (`texel_rows`, "
        "`texel_values`; the four bilinear texels only when a camera ray of the packet "
        "sees the map): one loop that gathered the rows and evaluated the sigmoids "
        "together was left scalar by LLVM and cost 130–185 ns per path against 56 now. "
        "The light samples' texels: the map sampler now searches each CDF from a guide "
        "table (`spectrum.guide_table`, `guided_bin`, the hero wavelengths' own: "
        "Devroye's indexed search, about "
        "one step instead of a bisection's nine or ten dependent loads; the same texel, "
        "`tests/test_environment.py` checks it against a binary search on CDFs with empty "
        "steps and at the buckets' edges, where a guide without its margin failed), for "
        "whole paths, the wavefront and the lanes (`pick_texels`, a short scalar loop: a "
        "bisection in every lane as vector code cost twice as much). "
        "A fourth compile flag (`lane_paths.kernel(smooth, general, textured, env_on)`); "
        "the warm-up's two map scenes now compile lane kernels. "
        "`tests/test_lane_paths.py` checks path by path against whole paths and the "
        "wavefront (spectral, rgb and seed-gaussian; β 0, 0.3 and 0.6; depth 2 and 5; a "
        "transparent film; point, spot and sun lights beside the map in the light CDF; "
        "checker and normal textures under the map) and the renderer's image against "
        "whole paths; five mutations were caught (the MIS weight dropped, the map never "
        "the light, the column search in the wrong row, the bilinear lookup's other "
        "three texels skipped, one of its texels read in place of another). "
        "The renderer's CPU per path on the environment-lit scene "
        "(`python -m relray.bench.ab 055e6e0 --scene environment`, 6 alternated pairs, "
        "128², 16 spp, 1 thread, 05:48) **0.91×** (quartiles 0.89–0.93; 605 → 548 ns); "
        "the kernel alone 0.81–0.85× its whole paths (§6); the Cornell box unchanged "
        "(0.99, quartiles 0.93–1.03, 05:57); the guided searches a further 0.94× "
        "(`bench.ab b86eab8`, quartiles 0.92–1.10, 06:15), all of it against 055e6e0 "
        "**0.86×** (quartiles 0.79–1.01, 06:25). The polynomial arcs alone do not speed up "
        "whole paths (466c7fa against 055e6e0: 0.99, 6 pairs)"
        + (f"; {env_ns}" if env_ns else "")
        + (". Equal-error CPU time on the environment-lit scene at the high / low level "
           "(§2, relative MSE, the run of 06:33 in a slow phase of the machine): "
           "`llvm_ad_spectral` 1.44 / 1.21; `scalar_spectral` 0.37 / 0.30; Cycles 0.22 / "
           "0.19; at 06:02, the lanes without the guided "
           "searches and the machine quicker: 1.29 / 1.14, 0.38 / 0.32, 0.24 / 0.21; before "
           "the lanes (02:52): 1.24 / 1.44, 0.42 / 0.35, 0.21 / 0.23. The `scalar_spectral` "
           "goal was met in that run (0.41 at the high level at 10:16), the "
           "`llvm_ad_spectral` one not: relray's CPU per sample is still 1.3–1.45× the "
           "LLVM variant's there, its noise per sample 0.79×"
           if peers else "")
        + ".")


def _textured_lanes_bullet(add, d) -> None:
    """The 2026-11-27 round: image textures in the SIMD lanes, the texel spectrum as one
    vector loop, and the first image's BLAS probe."""
    peers = ("`llvm_ad_spectral` 1.03 / 0.67; `scalar_spectral` 0.27 / 0.18; Cycles 0.15 / "
             "0.11 (06:33)" if peer_ratios(d, "textured")[1] else "")
    llvm_met = ("the `llvm_ad_spectral` goal met at the low level, not at the high one in "
                "that run (0.92 / 0.65 at 02:52, 0.85 / 0.65 at 06:02, the textured code the "
                "same; met at both since the lookups were inlined, this round's first bullet)")
    tex_ns = "1326 ns per path in the per-scene profile of 02:51 (1730 before)"
    add("- **Image textures in the SIMD lanes** (`render/lane_paths.py`, 2026-11-27 "
        "02:20; last round's next step 1, in part): a static textured scene without a "
        "map (the textured box, the default fly-by) is now traced sixteen paths at a "
        "time. The base colour, roughness, normal and emission lookups are a lane loop of "
        "their own (`texture_lanes`, after the vectorised shading of the hits: scalar "
        "calls per lane, so the other loops stay 16-lane code), each lane carries its ray "
        "cone; a third compile flag (`lane_paths.kernel(smooth, general, textured)`), "
        "and the warm-up renders the fly-by's kind. `tests/test_lane_paths.py` checks "
        "path by path against whole paths and the wavefront (base, roughness, normal and "
        "emission textures; smooth shading under a normal map; spectral and rgb; β 0 and "
        "0.6; depth 2 and 8); four mutations were caught. With it, a texel's spectrum at "
        "the four lanes is one vector loop (`textures.cell_reflectance4`: the 8 table "
        "nodes' 32 sigmoids in zmm registers, bit for bit `rgb_table.cell_reflectance`'s "
        "values, `tests/test_textures.py`; the stack memory of the lanes moved to "
        "`render/stack.py`), a lookup on a mip level reads that level alone, and a "
        "repeated power-of-two texture wraps by a mask instead of two divisions. The "
        "renderer's CPU per path on the textured box, each step against the one before "
        "(`python -m relray.bench.ab REV --scene textured`, 6 alternated pairs, 128², 16 "
        "spp, 1 thread): the lanes **0.92×** (quartiles 0.89–0.94; 1628 → 1481 ns, "
        "02:22), the vector spectrum and the level read **0.90×** (0.87–0.93, 02:27), the "
        "mask **0.95×** (0.92–1.01, 02:40); all three against the code before them "
        "(`bench.ab b16c5c2 --scene textured`, 03:05) **0.81×** (0.80–0.83; 1630 → 1326 "
        "ns)"
        + (f"; {tex_ns}" if tex_ns else "")
        + (". Equal-error CPU time on the textured box at the high / low level (§2, "
           f"relative MSE): {peers}: {llvm_met} (1.08 / 0.75 before the lanes)"
           if peers else "")
        + ". Tried and dropped: prefetching every lane's texels before the lookups (a "
        "first pass over the lanes): **1.20×**, slower (02:34): the lookups are bound by "
        "their arithmetic more than by memory; the environment map's CDF searched by a "
        "branch-free bisection: 1.02× (02:45; the benchmark map's searches are "
        "predictable, its sun holds most of the power); Embree's high-quality BVH build "
        "(`rtcSetSceneBuildQuality` HIGH, spatial splits) for the heavy scene: its lanes "
        "1058–1074 against 983–1017 ns per path and the build 0.85–0.90 against 0.35–0.39 "
        "s (by hand, 03:09); the texture lookups inlined into the kernels instead of "
        "called: the lanes 0.96× on the textured box, the whole paths unchanged, for a "
        "much longer compile (by hand, 03:20); the map sampler's libm `sin`/`cos` "
        "(`environment.uv_to_direction`) as `sampling.sincos_2pi` (to 2e-9): the "
        "environment-lit scene 1.04 (quartiles 0.93–1.13, `bench.ab HEAD --scene "
        "environment`, 03:50), no gain (next step 4's libm cost is the escaping rays' "
        "`atan2`/`acos` and the texel loads, not the sampler's trigonometry). The cold "
        "command line (empty kernel cache) is unchanged by the textured lanes: 14.5 s "
        "against 14.5 s for the code before "
        "them (two alternated rounds, 03:22; §5c's 18 s was a busy moment). And the first "
        "image: numba "
        "probes for BLAS at its first load by importing scipy.linalg (0.13 s); no "
        "kernel calls BLAS, so relray answers the probe \"none\" without the import "
        "(`core/__init__.py`, `tests/test_core.py`): numba.np.arraymath's import 0.145 → "
        "0.009 s (cProfile of a warm `relray render`).")

def _section_recommendations(add, d) -> None:
    add("## What changed in this round, and what stands in the way\n")
    if not d["profile"]:
        add("Needs the profile.\n")
        return
    tp = [r for r in d["throughput"] if r.get("mode") == "cie1931"][0]
    total = 1e9 * tp["cpu_s"] / tp["paths"]
    emb_i = _ns(d, "Embree intersect")
    emb_o = shadow_embree_ns(d) or 0.0
    shade = _ns(d, "shade kernel")
    pfc = {r["scene"]: r for r in d["path_floor"]}
    lane_rows = {n: r for n, r in pfc.items() if _num(r.get("lanes_ns"))}
    _moving_lanes_bullet(add, d)
    _camera_block_bullet(add, d)
    _body_bounds_bullet(add, d)
    _lane_rays_bullet(add, d)
    _map_light_bullet(add, d)
    _hero_table_bullet(add, d)
    _lane_numbers_bullet(add, d)
    _floors_bullet(add, d)
    _env_lanes_bullet(add, d)
    _textured_lanes_bullet(add, d)
    if lane_rows:
        c = lane_rows.get("cornell", next(iter(lane_rows.values())))
        per = "; ".join(
            f"{n} {r['lanes_ns']:.0f} against {r['whole_ns']:.0f} ns "
            f"({r['lanes_over_whole']:.2f}×), Embree's share "
            f"{100 * r['lanes_embree_share']:.0f} % (whole paths "
            f"{100 * r['whole_embree_share']:.0f} %)" for n, r in lane_rows.items())
        add("- **Paths in SIMD lanes** (`render/lane_paths.py`, 2026-11-26 23:30; last "
            "round's next step 1): a static Lambert scene without an environment map or "
            "image textures, with a light to sample (emissive triangles, point, spot, sun "
            "lights, a constant sky; flat or smooth-shaded) is traced sixteen paths at a "
            "time. Each lane holds a path's state in structure-of-arrays rows on the "
            "kernel's own stack; every bounce of the sixteen is one `rtcIntersect16` "
            "packet, their shading a few loops over the lanes that LLVM compiles to 16-lane "
            "AVX-512 code (gathers from the scene's tables, the Sobol hashing in 64-bit "
            "integer vectors, the light sample and the cosine warp as selects), their "
            "shadow rays one `rtcOccluded16` packet; a lane whose path ends takes the next "
            "camera ray, so the packets stay full "
            f"({c['lanes_per_packet']:.2f} rays of 16 on the box). What it took: numba "
            "vectorised nothing while the lanes' arrays were on the heap (LLVM could not "
            "rule out that the loops' stores alias the scene's tables they gather from: "
            "\"unsafe dependent memory operations\"), so the lanes' arrays are stack "
            "memory made by a numba intrinsic (now `stack.stack_array`: no owner, no reference "
            "counting, so the kernel compiles with `_nrt=False`); the loops are inlined "
            "functions of fewer than 30 arguments (Python 3.11 passes more as `*args`, "
            "which numba's inliner refuses); `sincos_2pi`'s quadrant and the triangle "
            "light's sample became selects (images bit-identical). The estimator is the "
            "whole-path kernel's, sample for sample: `tests/test_lane_paths.py` checks path "
            "by path against it and the wavefront (flat and smooth, triangle, delta and "
            "sky lights, a transparent film, depth 1–8, spectral and rgb, β 0–0.6), and "
            "`tests/test_embree.py` the packets against single rays. The compiled kernel "
            "comes in four kinds (flat or smooth, triangle lights or any), each compiled "
            "once (about 10 s; the warm-up renders each). §6, on the same paths, one "
            f"thread: {per}. The renderer's CPU per path against the code before it "
            "(`python -m relray.bench.ab 93e0ad9 --scene S`, 6 alternated pairs, 128², 16 "
            "spp, 1 thread, 2026-11-26 23:36–23:40): Cornell **0.80×** (quartiles "
            "0.79–0.81; 836 → 668 ns), heavy (1 M triangles) **0.89×** (0.86–0.92; 1258 → "
            "1134 ns). Tried and dropped: the environment-lit scene in lanes (its map's "
            "lookups are libm and searches that stay scalar: 1.00× its whole paths, by "
            "hand); a packed 64-byte record per triangle for the hit's gathers (one cache "
            "line instead of seven tables): the heavy scene (200 k triangles) 0.84× its "
            "whole paths against 0.91× (by hand, 23:41), for 64 bytes more per triangle "
            "(83 MB on the 1.3 M-triangle mesh); the refill of finished lanes as one loop "
            "of selects over the lanes instead of a scalar loop over the finished ones: "
            "1.02× (`bench.ab HEAD --scene cornell`, 6 pairs, quartiles 1.02–1.03, "
            "2026-11-27 00:30). Fixed before it landed: a lane that never got a path "
            "(fewer paths than lanes: the stress suite's 1-pixel render) ran the lane "
            "loops on uninitialised stack memory and read the tables out of bounds; every "
            "lane's state is now defined first (`tests/test_lane_paths.py`, 1, 5, 15 and "
            "17 paths).")
    if pfc:
        ratios = ", ".join(f"{n} {r['whole_ns'] / r['wavefront_ns']:.2f}"
                           for n, r in pfc.items())
        add("- **Whole paths in one kernel call** (`render/whole_paths.py`): a static scene "
            "whose materials are all Lambert, with no alpha mask, no area-light quad and no "
            "denoising features, is traced path by path, each to its end in one compiled "
            "loop that calls Embree itself, with the wavefront integrator's estimator and "
            "random numbers: the two give the same radiance path by path "
            "(`tests/test_whole_paths.py`, thirteen scenes and modes; §6). First for the "
            "Cornell "
            "box and the heavy scene (emissive triangles only); since the session of "
            "2026-11-26 15:00 also smooth shading (vertex normals), point, spot and sun "
            "lights, a constant sky, the environment map (its miss lookups MIS-weighted, "
            "NEE towards it; the lanes' λ and the map's E(λ) looked up once per path) and "
            "base-colour, roughness, normal and emission textures (the wavefront's ray "
            "cones), so all four benchmark scenes take it. CPU per path, whole paths ÷ "
            f"wavefront on the same paths (§6): {ratios}; the renderer's CPU per path "
            "against the code before each step (`python -m relray.bench.ab REV --scene S`, "
            "6 alternated pairs, 128², 16 spp, 1 thread): environment-lit **0.84** "
            "(quartiles 0.81–0.93), textured **0.90** (0.84–0.94), Cornell 0.98–1.04 "
            "(unchanged within the noise). Equal-error CPU time at equal relative MSE, high / "
            "low level, against `llvm_ad_spectral`, `scalar_spectral` and Cycles, in the §2 "
            "run of 18:15 (load 1–2; in brackets the run of 15:56, and the wavefront's of "
            "12:26): the environment-lit scene **0.96 / 0.84**, 0.42 / **0.39**, **0.26 / "
            "0.22** (0.99 / 0.90, 0.47 / 0.39; 1.05 / 0.92, 0.52 / 0.42); the textured scene "
            "**0.64 / 0.46**, **0.30 / 0.20**, **0.14 / 0.13** (0.62 / 0.56, 0.27 / 0.20; "
            "0.84 / 0.63, 0.39 / 0.26); the heavy scene, whose code did not change, **0.88 / "
            "0.68**, 0.50 / **0.38**, **0.22 / 0.16** (0.71 / 0.72, 0.44 / 0.42). The Cornell "
            "box (18:30–18:42, load 0.4–1.9; in brackets 12:10–12:36, then before whole "
            "paths): `llvm_ad_spectral` **0.60 / 0.61** (0.69 / 0.61; 0.98 / 0.78), "
            "`scalar_spectral` **0.37 / 0.29** (0.39 / 0.30; 0.48 / 0.41), M paths per "
            "CPU-second relray 0.79, `llvm_ad_spectral` 0.56, `scalar_spectral` 0.30 (0.90, "
            "0.67, 0.36 at a lower load); Cycles (2 threads, CPU time) 0.37 / **0.25** (0.31 "
            "/ 0.25; 0.38 / 0.38).")
    add("- **Whole paths for moving bodies** (`render/whole_paths.py`, 2026-11-26 21:00): "
        "a Lambert scene with moving bodies is now traced as whole paths too: every ray "
        "carries its origin's lab time and goes through the static BVH and each body's "
        "segments in their rest frames from inside the kernel (`rest_frames.nearest_one`, "
        "`rest_frames.blocked_ray`), and a hit on a body is shaded in its rest frame as "
        "`integrator.shade` does it (aberration, D⁵, the lanes' shift with the one pending "
        "from the last body, lights sampled in the lab from the hit's lab event, a light "
        "of the same body in its rest frame, a moving light from a static vertex in its "
        "rest frame, the continuation turned back into the lab with its rest-frame form "
        "kept), with textures and under an environment map (its lane lookups made again "
        "when the lanes shift). The two integrators give the same radiance path by path "
        "(`tests/test_whole_paths.py`: moving blocks, a moving room, a moving light, a "
        "room moving with its light, moving textured blocks, moving bodies under the map; "
        "β of the camera 0–0.6, spectral and rgb). The moving presets (train, ships, "
        "Penrose–Terrell) take it; their images agree with the wavefront's to 2e-8 (mean "
        "relative difference). CPU per path against the wavefront (`python -m "
        "relray.bench.ab 5868059 --scene moving`, the room as one body, 6 alternated "
        "pairs, 128², 16 spp, 1 thread): **0.89×** (quartiles 0.86–0.90); the room as "
        "four bodies (the peer scene), alternated by hand: 0.88× and 0.91×. §5b's paired "
        "statistic, one group against the static box, was given as 1.17× (quartiles "
        "1.15–1.19; four groups 1.40×), but that run's static box was on the wavefront "
        "(§5b's correction); like for like, both as whole paths, it is **1.41×** "
        "(1.40–1.43, 41 pairs, 2026-11-26 23:43; four groups 1.85× in the table) — issue "
        "10's ≤ 1.35× is not met. The static scenes are unchanged "
        "(`bench/ab.py` against 5868059, 6–8 pairs: Cornell 1.00, quartiles 0.99–1.03; "
        "environment-lit 1.03, 0.99–1.12; textured 1.02, 0.98–1.08), and so is their "
        "kernel's compile time (the moving blocks are pruned by the compile-time flag: "
        "8.5 s against 8.3 s for the Cornell box's first render with an empty cache). "
        "What a moving body still costs is its rest-frame traversal: with the room as "
        "four bodies, every ray is traced in four BVHs after its own boost (perf: the "
        "kernel 55 %, Embree 28 % of the samples). Tried and dropped: the bodies' BVHs "
        "as one Embree scene with a ray mask per body, traced as one `rtcIntersect8` "
        "packet (one lane per body): 272 ns per ray against 166 ns for the four "
        "`rtcIntersect1` calls (91 ns for one BVH of the whole box; /tmp experiment, "
        "200 000 random rays in the box, 2026-11-26 21:00).")
    add("- **One whole-path kernel per kind of scene** (`whole_paths.kernel`, 2026-11-26 "
        "17:55): whether the scene has an environment map or image textures (and whether "
        "the benchmarks record the rays) are constants of the compiled code, a closure's "
        "values, so numba prunes the branches they close and never compiles their callees "
        "(numba keys each variant's on-disk cache by the closure's values). The Cornell "
        "box's first image from the command line with an empty kernel cache takes 23 s "
        "(53 s when the one kernel compiled the map's and textures' lookups for every "
        "scene), Blender's first F12 of its default scene 17 s (47 s); the warm-up renders "
        "each kind (151 s against 113 s, in the background). CPU per path unchanged "
        "(`bench/ab.py`, 6 pairs: Cornell 0.99, quartiles 0.96–1.05; environment-lit "
        "0.97, 0.89–1.09).")
    add("- **The moving scene against the peers** (issue 12 item 1's scene with several "
        "moving objects; §2, 18:15): the Cornell box as four bodies at β = 10⁻⁴, which the "
        "peers render at rest. The converged images agree (luminance ratios 0.999–1.002, "
        "mean ΔE00 0.61–0.71 in full GI with the references' noise, no structure in the "
        "maps). Equal-error CPU time at equal relative MSE, high / low level, on the "
        "AVX2 machine at 18:15 (the wavefront): `llvm_ad_spectral` 1.48 / 1.75, "
        "`scalar_spectral` 0.72 / 0.89, Cycles 0.37 / 0.36; on this session's AVX-512 "
        "machine at 21:09 (whole paths): 2.22 / 2.21, 0.74 / **0.67**, **0.33 / 0.31** "
        "(next bullet for why the LLVM ratios rose on every scene). Not met against "
        "either Mitsuba variant: the rest-frame traversal of each body (§5b, like for like: one "
        "group 1.41× the static box, four groups 1.85×), on top of the static box's own "
        "gap.")
    add("- **The CPU changed under the benchmarks** (2026-11-26 21:00): this session's "
        "machine (AMD EPYC, 2 cores) has AVX-512, the earlier sessions' had AVX2. "
        "Mitsuba's `llvm_ad_spectral` JIT-compiles its kernels for the machine it runs "
        "on, 16 lanes wide with AVX-512 against 8 with AVX2; relray's scalar kernels gain "
        "little from it. In the 21:09 run relray's CPU per sample is 1.24× (heavy), "
        "1.67× (environment-lit), 2.30× (textured) and 2.48× (moving) "
        "`llvm_ad_spectral`'s at equal spp, and the equal-error ratios against it are "
        "1.11 / 1.12, 1.64 / 1.43, 1.07 / 0.82 and 2.22 / 2.21 (at 18:15 on the AVX2 "
        "machine 0.88 / 0.68, 0.96 / 0.84, 0.64 / 0.46, 1.48 / 1.75), while those "
        "against `scalar_spectral` and Cycles, which do not widen, stayed within the "
        "runs' noise: heavy 0.49 / 0.42 and 0.20 / 0.21, environment-lit 0.46 / 0.38 and "
        "0.29 / 0.23, textured 0.29 / 0.21 and 0.19 / 0.14. Paths in SIMD lanes (the "
        "first bullet) follow the LLVM variant there for the box and the heavy scene: in "
        "the runs of 23:47–00:05, at equal relative MSE, high / low level, the Cornell "
        "box 1.00 / 0.88 against `llvm_ad_spectral` and the heavy scene 0.98 / 0.93 (§2); "
        "the environment-lit, textured and moving scenes, which the lanes do not take "
        "yet, stay above 1.")
    add("- **The environment-lit scene's ΔE00 against Mitsuba, explained**: at equal "
        "relative MSE, relray needed more time than Mitsuba's LLVM variant to reach equal "
        "mean ΔE00 on that scene (1.21 / 1.59 in the 15:56 run), that is more colour "
        "noise per unit of luminance noise. It is the hero wavelengths' pdf: "
        "`python -m relray.bench.wavelength_pdf --scene environment` renders the scene "
        "with relray's pdf (∝ |r̄|+|ḡ|+|b̄|, physics.md) and with Mitsuba's (∝ sech²(0.0072 "
        "(λ − 538 nm))), all else equal (96², 6 seeds, each against its own 1024-spp "
        "reference, 2026-11-26 18:12): mean ΔE00 at 4 / 16 / 64 spp 11.95 / 3.13 / 1.20 "
        "against 14.92 / 2.00 / 0.83, relative MSE 0.067 / 0.0077 / 0.00127 against 0.143 / "
        "0.0065 / 0.00135, Mitsuba's own figures there (15.0 / 2.35 / 0.91, 0.147 / 0.0081 / "
        "0.00162) being those of the sech² pdf. On the Cornell box the sech² pdf is the "
        "worse one (`--scene cornell`: ΔE00 9.36 / 3.69 / 1.81 against 10.04 / 3.74 / 1.97, "
        "relative MSE 0.253 / 0.047 / 0.0100 against 0.318 / 0.050 / 0.0113), and the "
        "CMF-sum pdf physics.md also allows is worse on the environment-lit scene (ΔE00 "
        "15.1 / 3.42 / 1.25, by hand with the same harness). Neither pdf wins everywhere; "
        "relray keeps the one physics.md prescribes.")
    add("- **Reference counting off the per-hit calls** (perf on the JIT code, "
        "2026-11-26): numba counts the references of the arrays a compiled function "
        "receives, with atomic instructions, unless it is compiled with `_nrt=False`. "
        "The texture functions `shade` calls per textured hit (`triangle_uv`, "
        "`normal_mapped`, `texel_reflectance`, `texel_emission`), `lerp_at` and the "
        "whole-path kernel's sky/map lookup now are (they allocate nothing): 6 % of the "
        "textured scene's samples had been `NRT_MemInfo_incref`/`decref`; its CPU per "
        "path 0.92× (6 alternated pairs, quartiles 0.85–1.03). `shade`'s `shadow_done` "
        "(which traces a shadow ray at once) had been inlined with branches, so every "
        "shadow ray counted references to fourteen arrays (found with gdb on numba's "
        "reference-count function: one call site, 6 % of the moving scene's samples); "
        "compiled apart without counting, the moving scene's CPU per path is 0.91× "
        "(quartiles 0.88–0.96).")
    add("- **Environment maps** (`render/environment.py`; the environment-lit scene, §2 "
        "and §6): a lookup evaluates the four hero lanes of a texel in one call (before: "
        "one compiled call per lane and per texel, 16 for the bilinear lookup of a map "
        "seen directly, each computing its lane's λ with an `exp`), next-event estimation "
        "takes the texel it drew from the sampler (no second `acos`/`atan2` for its "
        "radiance), a miss's texel and MIS pdf come from one (u, v), and the map's device "
        "functions are compiled without reference counting (they allocate nothing). "
        "Images bit-identical. CPU per path on that scene, this code ÷ the previous "
        "round's (`python -m relray.bench.ab 2e97a3e --scene environment`: alternated "
        "processes, 128², 16 spp, 1 thread): median of 8 pairs 0.82 (quartiles "
        "0.72–0.90); two runs by hand before that command existed gave 0.71 and 0.76 (8 and "
        "9 pairs). In §6's per-scene profile the shade kernel went from 1344 to 817 ns per "
        "path on that scene (Cornell box 1378 → 1335: unchanged). Against Mitsuba's LLVM "
        "variant that is still 1.29× its CPU per sample in the first of this round's two "
        "§2 runs and 1.07× in the second "
        "(1.36× before), whose Dr.Jit kernel evaluates the same lookups 8 lanes at a time. "
        "The equal-error ratios of that scene, high / low level, in the two runs (09:29 "
        "and 09:44, load 0.6–2.2) against the last round's: `llvm_ad_spectral` 1.07 / "
        "1.06 and 0.93 / 0.88 (1.35 / 1.03), `scalar_spectral` 0.53 / 0.45 and 0.45 / "
        "0.45 (0.65 / 0.45), Cycles 0.28 / 0.29 and 0.25 / 0.23 (0.71 / 0.54). How much "
        "these ratios move from run to run shows on the heavy scene, whose code did not "
        "change: against `llvm_ad_spectral` 0.87 / 0.93 in the last round, 1.09 / 1.04 "
        "and 1.19 / 1.29 in this round's runs (about ±20 %: the peers and relray share "
        "the two cores with other work, not always alike).")
    add("- **Loading a mesh** (`scene/geometry.py`, issue 12's load goal): the transform "
        "of a mesh is one BLAS product over its vertices (not a 3×3 product per "
        "triangle), a single part is not copied, missing UVs are float32 zeros written "
        "in place, the bounds come from one compiled pass, and the coordinates are "
        "checked on the vertex table (on the faces' vertices only when that finds a "
        "problem): `build_scene` of the heavy scene takes about a third of its time "
        "(0.71 → 0.22–0.33 s by hand, quiet machine), so loading the mesh and building "
        "the BVH is now faster than Mitsuba 3 (the `peer_load` section, §2).")
    add("- **Moving scenes** (issue 10's last goal, §5b): no reference counting in the "
        "moving loops, a three-array segment table, an aberration without a square root, "
        "continuation rays that carry their rest-frame form, and a ray back on the body "
        "it left keeping its frame: one moving group now costs about "
        "1.3× the static box (paired median, §5b).")
    add("- **Benchmark**: `bench/ab.py` measures a change against any earlier revision "
        "(paired, alternated processes on one benchmark scene); the heavy mesh's load "
        "time is a section of its own (`--only peer_load`, a minute, without the peer "
        "renders); "
        "`bench/moving_rays.py` measures one ray's cost in a moving scene; the stage "
        "meter counts a moving scene's rays again (an argument index had gone stale).\n")
    pf = {r["scene"]: r for r in d["path_floor"]}
    if "cornell" in pf and _num(pf["cornell"].get("lanes_ns")):
        c = pf["cornell"]
        add(f"**Where a Cornell path's {c['lanes_ns']:.0f} ns go** (the lane kernel, §6): "
            f"Embree alone on its packets {_f(c.get('embree_lanes_ns'), '.0f')} ns "
            f"({100 * c['lanes_embree_share']:.0f} %); outside Embree "
            f"{c['lanes_other_ns']:.0f} ns for the sixteen lanes' gathers of the hit's "
            "triangle and of the spectral tables, the numbers, the light sample, the "
            "packets' set-up and the scalar refill and write-back. Around the kernel the "
            f"camera rays cost {_scene_ns(d, 'cornell', 'camera:'):.0f} ns, the hero "
            f"wavelengths {_scene_ns(d, 'cornell', 'hero:'):.0f} ns and the film "
            f"{_scene_ns(d, 'cornell', 'film:'):.0f} ns per path (§6's per-scene profile). "
            "One path at a time "
            f"the same paths cost {c['whole_ns']:.0f} ns ({c['whole_other_ns']:.0f} outside "
            f"Embree), in the wavefront integrator {c['wavefront_ns']:.0f} ns.\n")
    elif "cornell" in pf:
        c = pf["cornell"]
        add(f"**Where a Cornell path's {c['whole_ns']:.0f} ns go** (the whole-path kernel, "
            "§6): Embree alone on its rays "
            f"{c['embree_ns']:.0f} ns ({100 * c['whole_embree_share']:.0f} %); outside "
            f"Embree {c['whole_other_ns']:.0f} ns, of which {c['numbers_ns']:.0f} ns draw "
            "the random numbers and the rest is the four lanes' table lookups, the light "
            "sample, the shadow ray's and the continuation's set-up and the ray offsets. "
            "Around the kernel the camera rays and hero wavelengths cost "
            f"{_ns(d, 'camera:', 'hero:'):.0f} ns and the film "
            f"{_ns(d, 'film:'):.0f} ns per path (§6's profile). The wavefront integrator "
            f"spends {c['wavefront_other_ns']:.0f} ns outside Embree on the same paths.\n")
    else:
        add(f"**Where a Cornell path's {total:.0f} ns go**: the nearest-hit queries "
            f"{emb_i:.0f} ns; the shade kernel {shade:.0f} ns, of which about {emb_o:.0f} "
            "ns are its shadow rays' Embree queries (§3); the camera rays and hero "
            f"wavelengths {_ns(d, 'camera:', 'hero:'):.0f} ns; the film "
            f"{_ns(d, 'film:'):.0f} ns.\n")
    add("Next steps, by expected gain:\n")
    add("1. **The texture lookups as gathers in the lanes** (the textured box): its "
        "lookups are scalar code per lane, inlined since 2026-11-27 09:50 (0.89×, "
        "`bench.ab 7a57ca7 --scene textured`, 6 pairs, quartiles 0.86–0.92), and still "
        "about 40 % of its CPU per path (1181 against the plain box's ~690 ns); the "
        "atlas descriptors, the mip level and the texels of sixteen lanes as vector code "
        "would be the next step.")
    pfm = pfc.get("moving", {})
    ratio, _ = peer_ratios(d, "moving")
    eqm = [ratio[("llvm_ad_spectral", k)] for k in (0, 1) if ("llvm_ad_spectral", k) in ratio]
    now = ""
    if _num(pfm.get("lanes_ns")) and len(eqm) == 2:
        now = (f" In this run the moving scene's lanes cost {pfm['lanes_ns']:.0f} ns per "
               f"path, {100 * pfm['lanes_embree_share']:.0f} % of it the rest-frame "
               f"traversal (next step 4), and its ratio to `llvm_ad_spectral` is "
               f"{_pair(eqm)} (§2).")
    add("2. ~~**SIMD lanes for moving bodies**~~: done for scenes lit by emissive "
        "triangles (2026-11-28, above)." + now + " What is left: moving bodies under a sky "
        "or delta lights (the train, Terrell and ships presets: there the lanes cost "
        "1.04–1.15× the whole paths; finishing escaped rays before the packet is shaded "
        "for the static lanes too, and a light sample per kind of light instead of every "
        "kind's as selects, would be the next steps), and maps and textures with moving "
        "bodies.")
    add("3. ~~**The environment-lit scene's lanes**~~: done (2026-11-27 18:50, above: "
        "the map's λ as vector code, a kernel for the map as the only light, the "
        "searches only where a light sample is made; 0.79× its CPU per path). What is "
        "left there, by the kernel's cycle counter (about 300 ns per path): Embree about "
        "105, the hits 31, the escaping rays' lookups 37, the light samples' searches "
        "and texels 35, the light samples and continuations 28, the refill 35; around "
        "the kernel (§6's profile) the hero wavelengths "
        f"{_scene_ns(d, 'environment', 'hero:'):.0f}, the sensor values and the film "
        f"{_scene_ns(d, 'environment', 'film:'):.0f}, the camera rays "
        f"{_scene_ns(d, 'environment', 'camera:'):.0f} (the next step 6 would take part "
        "of the film's).")
    add("4. **The bodies' rest-frame traversal** (the moving scene): ~~a box per body "
        "in its rest frame~~ done (2026-11-28, above: 0.96× of the traversal). What is "
        "left: two thirds of the traversal are the bodies' Embree queries at about 52 ns "
        "each on BVHs of 8–9 triangles (above), one per body a ray can reach (an "
        "`rtcIntersect8` packet over one masked scene was slower, 2026-11-26); a shadow "
        "ray from a moving vertex could use its rest-frame form for its own body (one "
        "boost less, about 2 % of a path).")
    add("5. **Whole paths for glossy and glass materials**: the principled material's "
        "other lobes as branches of the whole-path kernel (the wavefront stays for alpha "
        "masks, area-light quads and the denoising features).")
    add("6. ~~**Sensor values in the film's accumulation**~~: measured and dropped "
        "(2026-11-27 21:37, above): `integrator.sensor_values` + `Film.add_samples` "
        f"cost {_scene_ns(d, 'cornell', 'film:'):.0f} ns per path in §6's profile, one "
        "fused loop would save about 10 (32–35 against 44–45 ns by hand): about 1 % of a "
        "Cornell path.")
    add("7. ~~**Cheaper random numbers**: `sobol2`'s bit reversals as LLVM's `bitreverse` "
        "intrinsic~~: nothing to gain (2026-11-27 03:08): LLVM already recognises "
        "`reverse32`'s mask steps as a bit reversal and compiles the lanes' to GFNI's "
        "`vgf2p8affineqb` (10 in the Cornell lane kernel); the kernel written with "
        "`llvm.bitreverse.i32` compiled to the same instructions (4515, the same mix), "
        "and `bench.ab HEAD --scene cornell` measured 1.03 (quartiles 1.01–1.09: noise).")
    add("8. ~~**The hero wavelengths' inverse CDF**~~: done (2026-11-27 15:40, above): "
        "an inverse-CDF table on a uniform grid, "
        f"{_scene_ns(d, 'cornell', 'hero:'):.0f} ns per path in §6's profile (39 before), "
        "bounded by its stores.")
    add("")


def _section_missing(add, d, meta) -> None:
    add("## What is missing\n")
    miss = [name for name, key in (("throughput/profile", "throughput"),
                                   ("thread scaling", "scaling"), ("heavy scene", "heavy"),
                                   ("β sweep", "beta_sweep"), ("skip table", "skips"),
                                   ("error against time", "convergence_medians"))
            if not d[key]]
    if miss:
        add(f"- Sections not in this run: {', '.join(miss)}.")
    if d["convergence_medians"] and not any(r["series"] == "cycles"
                                            for r in d["convergence_medians"]):
        add("- Cycles: bpy was not importable, so there is no Cycles anchor in this run.")
    sc = d["scaling"]
    if sc and sc[-1].get("cpu_share_before", 1.0) < 0.9:
        add("- Thread scaling on an *idle* machine: the machine was busy during the scaling "
            "section (see its busy-loop share), so the ≥ 1.8× goal could not be checked; "
            "rerun `python -m relray.bench.run --only scaling` when `uptime` shows a load "
            "below 0.5.")
    add("- Cycles and Mitsuba 3 get Lambert + RGB emitters, an equirectangular map and "
        "base-colour textures (`bench/cycles_anchor.py`, `bench/mitsuba_peer.py`, "
        "`bench/peer_scenes.py`); glossy, glass, analytic lights, a constant sky and "
        "other textures are not exported yet (the exports raise for them).")
    st = d["mitsuba_status"]
    if st:
        for r in st:
            if r["ran"] not in (True, "True"):
                add(f"- Mitsuba `{r['variant']}` did not run: {r['reason']}.")
        add("- Mitsuba 3 and Cycles are compared on the Cornell box, the heavy, the "
            "environment-lit, the textured and the moving scenes; the moving scene's bodies "
            "move at β = 10⁻⁴, where the peers' box at rest gives the same picture: neither "
            "peer has relativistic motion, so a moving scene at a speed that changes the "
            "picture has no peer to compare with.")
    add("- Error against time at β ≠ 0 (where the peers have no counterpart) is not "
        "measured.")
    add("")


def main(argv: list[str] | None = None) -> None:
    """Rewrite the plots and RESULTS.md from the CSVs in ``--out``."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=cm.RESULTS, help="folder with the CSVs")
    ap.add_argument("--md", type=Path, help="RESULTS.md to write (default: next to bench/ "
                    "for bench/results, else OUT/RESULTS.md)")
    a = ap.parse_args(argv)
    md = a.md or (cm.REPO / "bench" / "RESULTS.md" if a.out.resolve() == cm.RESULTS.resolve()
                  else a.out / "RESULTS.md")
    print(write(a.out, md))


if __name__ == "__main__":
    main()
