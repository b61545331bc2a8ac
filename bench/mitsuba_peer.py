"""Mitsuba 3 as a benchmark peer: the Cornell box in ``scalar_spectral`` and ``llvm_ad_spectral``.

    files = scene_files(job, scene, 128, 128, tmp / "mitsuba")
    with MitsubaWorker("llvm_ad_spectral", files) as mw:
        img, wall, cpu, spp = mw.render(spp=64, threads=1, out=tmp / "a.npy")

Mitsuba runs in its own venv (``make mitsuba-venv``: ``.cache/mitsuba-venv`` from
``bench/mitsuba.lock``) as a long-lived worker (:mod:`.mitsuba_worker`), one per variant,
so runs of relray and both variants interleave (A B C A B C) without paying for start-up
and for Dr.Jit's kernel compilation each time.  The LLVM variant needs libLLVM ≥ 17
(with 15 or 16 its JIT aborts with "Cannot select … fminimum"): ``make mitsuba-venv``
unpacks Debian's libllvm19 into ``.cache/llvm19`` and the worker gets it through
``DRJIT_LIBLLVM_PATH``.  A variant that cannot start is reported with its reason.

Settings matched to relray's (:func:`scene_dict`; relray's in parentheses):

- path integrator ``path`` with NEE + MIS (relray's unidirectional path tracer with NEE
  and the power heuristic), ``max_depth`` = relray's ``max_depth`` (both count path
  segments: 2 is direct light only), ``rr_depth = 4`` (``integrator.RR_DEPTH = 4``:
  relray decides on roulette after the 4th hit; Mitsuba's depth counter is 4 there);
  Mitsuba caps the survival probability at 0.95, relray does not;
- 4 wavelengths per path: Mitsuba's spectral variants always carry 4 (not configurable;
  relray's 4 hero wavelengths);
- materials: ``twosided`` ``diffuse`` with the RGB reflectance (Mitsuba upsamples it with
  Jakob–Hanika 2019 through its own ``srgb.coeff`` table; relray fits the same sigmoid
  polynomial per colour) — both renderers start from the same RGB, not from shared
  spectra; the emitter is an ``area`` light with radiance RGB × strength (Mitsuba:
  upsampled RGB × D65, relray: ``s(λ) · D65`` scaled, physics.md), one-sided on the front
  face like relray's ``one_sided_emission`` (Mitsuba's area lights are one-sided);
- geometry: relray's triangles as OBJ files, one per material, with face normals (flat
  shading, the same winding and so the same front faces);
- camera: ``perspective`` with relray's vertical ``fov`` (``fov_axis = "y"``), position
  and orientation; film ``hdrfilm`` with a ``box`` filter of radius 0.5 px (relray's
  box of one pixel), linear Rec.709 RGB output (the CIE 1931 observer, as relray's
  ``spectral = "cie1931"``);
- sampler ``ldsampler`` (low-discrepancy, as relray's stratified samples): it rounds
  counts up to a power of 4, so the ladders are powers of 4 and the worker reports the
  count the sampler actually took.
"""

from __future__ import annotations

import json
import os
import statistics
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from relray.bench import common as cm
from relray.core.render import integrator
from relray.core.scene import motion
from relray.core.scene.description import Job
from relray.core.scene.geometry import Scene

WORKER = Path(__file__).with_name("mitsuba_worker.py")
MARK = "@@MITSUBA@@"
VARIANTS = ("scalar_spectral", "llvm_ad_spectral")
VENV_PYTHON = cm.REPO / ".cache" / "mitsuba-venv" / "bin" / "python"
LIBLLVM = cm.REPO / ".cache" / "llvm19" / "root" / "usr" / "lib" / "x86_64-linux-gnu" / \
    "libLLVM.so.19.1"
SAMPLER = "ldsampler"


def python() -> Path:
    """The interpreter of Mitsuba's venv (``RELRAY_MITSUBA_PYTHON`` overrides it)."""
    return Path(os.environ.get("RELRAY_MITSUBA_PYTHON", VENV_PYTHON))


def libllvm() -> Path | None:
    """The libLLVM handed to Dr.Jit (``DRJIT_LIBLLVM_PATH`` if set, else .cache/llvm19)."""
    if os.environ.get("DRJIT_LIBLLVM_PATH"):
        return Path(os.environ["DRJIT_LIBLLVM_PATH"])
    return LIBLLVM if LIBLLVM.exists() else None


def unavailable(variant: str) -> str | None:
    """Why ``variant`` cannot run here (None when it can be tried)."""
    if not python().exists():
        return f"no Mitsuba venv at {python()} (make mitsuba-venv)"
    if variant.startswith("llvm") and libllvm() is None:
        return ("no libLLVM >= 17: `apt-get download libllvm19` failed in make mitsuba-venv "
                "(the system's LLVM 15/16 abort with 'Cannot select ... fminimum')")
    return None


def simd() -> str:
    """The widest x86 vector extension of this CPU (what Dr.Jit's LLVM backend targets:
    AVX-512 runs 16 float lanes per instruction, AVX2 8)."""
    try:
        text = Path("/proc/cpuinfo").read_text()
    except OSError:
        return "unknown"
    flags = next((ln.split(":", 1)[1].split() for ln in text.splitlines()
                  if ln.startswith("flags")), [])
    for flag, name in (("avx512f", "AVX-512"), ("avx2", "AVX2"), ("avx", "AVX"),
                       ("sse4_2", "SSE4.2")):
        if flag in flags:
            return name
    return "none found"


# ----------------------------------------------------------------------------- the scene
def scene_dict(job: Job, scene: Scene, width: int, height: int, max_depth: int,
               meshes: list[str]) -> dict[str, Any]:
    """Mitsuba's scene dict (JSON-able) for relray's scene (settings: module docstring).

    ``meshes[i]`` is the OBJ file name of material ``i``'s triangles (``""``: none).  The
    camera transform is given as ``look_at`` (origin, target, up); the worker turns it
    into ``to_world``.  Only Lambert + RGB emission materials, no analytic lights and a
    black sky are supported (the Cornell box); anything else raises ValueError.
    """
    if scene.lights or np.any(scene.background):
        raise ValueError("analytic lights and a sky are not exported to Mitsuba")
    cam = motion.resolve_camera(job, scene)
    rot = np.asarray(cam.rotation, np.float64)  # columns: right, up, backward
    pos = np.asarray(cam.position, np.float64)
    d: dict[str, Any] = {
        "type": "scene",
        "integrator": {"type": "path", "max_depth": int(max_depth),
                       "rr_depth": integrator.RR_DEPTH, "hide_emitters": False},
        "sensor": {
            "type": "perspective", "fov": float(cam.fov), "fov_axis": "y",
            "near_clip": 1e-3, "far_clip": 1e6,
            "look_at": {"origin": pos.tolist(), "target": (pos - rot[:, 2]).tolist(),
                        "up": rot[:, 1].tolist()},
            "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                     "rfilter": {"type": "box"}, "pixel_format": "rgb",
                     "component_format": "float32"},
            "sampler": {"type": SAMPLER, "sample_count": 4},
        },
    }
    for i, m in enumerate(scene.materials):
        if m.metallic or m.transmission or m.emission_blackbody or m.emission_line or \
                m.emission_spectrum is not None:
            raise ValueError(f"material {m.name!r}: only Lambert + RGB emission for Mitsuba")
        if not meshes[i]:
            continue
        shape: dict[str, Any] = {
            "type": "obj", "filename": meshes[i], "face_normals": True,
            "bsdf": {"type": "twosided", "bsdf": {
                "type": "diffuse",
                "reflectance": {"type": "rgb", "value": [float(c) for c in m.base_color]}}}}
        radiance = [float(c) * float(m.emission_strength) for c in m.emission]
        if any(v > 0.0 for v in radiance):
            if not m.one_sided_emission:
                raise ValueError(f"material {m.name!r}: Mitsuba's area lights are one-sided")
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": radiance}}
        d[f"shape_{i}_{m.name}"] = shape
    return d


def write_obj(triangles: np.ndarray, path: Path) -> Path:
    """Triangles (n, 3, 3) as an OBJ file, three vertices per face, winding kept."""
    v = np.asarray(triangles, np.float64).reshape(-1, 3)
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in v.tolist()]
    lines += [f"f {3 * i + 1} {3 * i + 2} {3 * i + 3}" for i in range(len(triangles))]
    path.write_text("\n".join(lines) + "\n")
    return path


def scene_files(job: Job, scene: Scene, width: int, height: int, folder: Path,
                max_depth: int | None = None) -> Path:
    """Write the OBJ files and ``scene.json`` (the dict of :func:`scene_dict`) to
    ``folder``; returns the JSON's path."""
    folder.mkdir(parents=True, exist_ok=True)
    ids = np.asarray(scene.material_ids)
    meshes = []
    for i in range(len(scene.materials)):
        tris = np.asarray(scene.triangles)[ids == i]
        meshes.append(write_obj(tris, folder / f"mesh_{i}.obj").name if len(tris) else "")
    depth = job.render.max_depth if max_depth is None else max_depth
    d = scene_dict(job, scene, width, height, depth, meshes)
    path = folder / "scene.json"
    path.write_text(json.dumps(d, indent=1))
    return path


# ----------------------------------------------------------------------------- the worker
class MitsubaWorker(cm.WorkerProcess):
    """A Mitsuba subprocess (one variant) that loads one scene and renders it on demand."""

    def __init__(self, variant: str, scene_file: Path, log: Path | None = None):
        super().__init__(MARK, f"Mitsuba worker ({variant})", log)
        self.variant = variant
        self.scene_file = Path(scene_file)
        self.load_s = float("nan")  # seconds the worker took to load the scene (setup)

    def start(self) -> None:
        """Start the worker and load the scene; RuntimeError says why it cannot."""
        env = dict(os.environ)
        llvm = libllvm()
        if llvm is not None:
            env["DRJIT_LIBLLVM_PATH"] = str(llvm)
        hello = self._spawn([str(python()), str(WORKER), self.variant], env)
        if "error" in hello:
            self.close()
            raise RuntimeError(hello["error"])
        self.version = hello.get("version", "?")
        self.load_s = float(self._call({"cmd": "setup", "scene": str(self.scene_file)})
                            .get("load_s", "nan"))

    def render(self, spp: int, out: Path, threads: int = 1, max_depth: int | None = None,
               seed: int = 0) -> tuple[np.ndarray, float, float, int]:
        """Render; returns (linear RGB float64 (h, w, 3), wall s, CPU s, spp taken)."""
        cmd: dict[str, Any] = {"cmd": "render", "spp": int(spp), "seed": int(seed),
                               "threads": int(threads), "out": str(out)}
        if max_depth is not None:
            cmd["max_depth"] = int(max_depth)
        r = self._call(cmd)
        img = np.load(out).astype(np.float64)
        Path(out).unlink(missing_ok=True)
        return img, float(r["wall"]), float(r["cpu"]), int(r["spp"])


# ----------------------------------------------------------------------------- the runs
@dataclass
class MitsubaConfig:
    """Sizes of the Mitsuba comparison (ladders in powers of 4: the ldsampler's counts)."""

    width: int = 128
    height: int = 128
    spp: list[int] = field(default_factory=lambda: [4, 16, 64, 256])
    repeats: int = 3
    ref_spp: int = 4096
    ref_threads: int = 2
    max_depth: int = 8
    tp_size: int = 256
    tp_spp: int = 16
    tp_repeats: int = 3
    variants: tuple[str, ...] = VARIANTS


def run(cfg: MitsubaConfig, tmp: Path, log=print) -> dict[str, Any]:
    """Converged agreement, the interleaved error ladder (1 thread) and the throughput
    (1 thread, ``tp_size``²) of relray and each Mitsuba variant that starts.

    Returns rows for ``mitsuba_status.csv``, ``mitsuba_converged.csv``,
    ``mitsuba_raw.csv``, ``mitsuba_medians.csv``, ``mitsuba_equal_error.csv`` and
    ``mitsuba_throughput.csv``.
    """
    folder = tmp / "mitsuba"
    bench = cm.RelrayBench(cm.make_job(cm.job_dict(), width=cfg.width, height=cfg.height,
                                       max_depth=cfg.max_depth))
    files = scene_files(bench.job, bench.scene, cfg.width, cfg.height, folder)
    tp_bench = cm.RelrayBench(cm.make_job(cm.job_dict(), width=cfg.tp_size,
                                          height=cfg.tp_size, max_depth=cfg.max_depth))
    tp_files = scene_files(tp_bench.job, tp_bench.scene, cfg.tp_size, cfg.tp_size,
                           folder / "tp")
    status, workers, tp_workers = [], {}, {}
    for v in cfg.variants:
        why = unavailable(v)
        if why is None:
            try:
                w = MitsubaWorker(v, files, log=tmp / f"mitsuba_{v}.log")
                w.start()
                workers[v] = w
                # a first render: the LLVM JIT aborts here when libLLVM is too old
                w.render(cfg.spp[0], tmp / "mitsuba_first.npy", threads=1)
                tp_workers[v] = MitsubaWorker(v, tp_files, log=tmp / f"mitsuba_{v}.log")
                tp_workers[v].start()
            except (RuntimeError, OSError) as e:
                why = f"{e}; {_last_line(tmp / f'mitsuba_{v}.log')}"
                for ws in (workers, tp_workers):
                    if v in ws:
                        ws.pop(v).close()
        status.append({"variant": v, "ran": why is None, "reason": why or "",
                       "version": workers[v].version if v in workers else ""})

        log(f"  mitsuba {v}: {'ready' if why is None else 'not run: ' + why}")
    try:
        return _measure(cfg, tmp, bench, tp_bench, workers, tp_workers, status, log)
    finally:
        for w in (*workers.values(), *tp_workers.values()):
            w.close()


def _last_line(log: Path) -> str:
    """Why a worker stopped, from its log: the last ``LLVM ERROR`` line (the JIT's abort,
    e.g. "Cannot select ... fminimum" with libLLVM 15/16), else the last line, or ''."""
    try:
        lines = [x for x in log.read_text(errors="replace").splitlines() if x.strip()]
    except OSError:
        return ""
    errors = [x for x in lines if "LLVM ERROR" in x]
    return (errors or lines or [""])[-1][:300]


def _measure(cfg, tmp, bench, tp_bench, workers, tp_workers, status, log) -> dict[str, Any]:
    out_npy = tmp / "mitsuba_img.npy"
    # warm-up: kernels compiled (numba, Dr.Jit) at every ladder size, outside any timing
    for spp in sorted({*cfg.spp, cfg.tp_spp}):
        for v, w in workers.items():
            w.render(spp, out_npy, threads=1)
            if spp == cfg.tp_spp:
                tp_workers[v].render(spp, out_npy, threads=1)
    bench.render(spp=4, threads=1)
    log(f"  mitsuba references: {cfg.ref_spp} spp at {cfg.width}x{cfg.height}")
    refs: dict[str, np.ndarray] = {}
    for label, depth in (("full", cfg.max_depth), ("direct", 2)):
        refs[f"relray_{label}"] = bench.render(spp=cfg.ref_spp, threads=cfg.ref_threads,
                                               max_depth=depth, seed=1000).rgb
        for v, w in workers.items():
            refs[f"{v}_{label}"] = w.render(cfg.ref_spp, out_npy, threads=cfg.ref_threads,
                                            max_depth=depth, seed=1000)[0]
    converged = compare(refs, list(workers))
    raw: list[dict[str, Any]] = []
    for seed in range(cfg.repeats):
        log(f"  mitsuba ladder, repeat {seed + 1}/{cfg.repeats}")
        for spp in cfg.spp:
            r = bench.render(spp=spp, threads=1, seed=seed)
            raw.append(_row("relray", spp, seed, r.rgb, refs["relray_full"], r.wall, r.cpu,
                            r.spp_mean))
            for v, w in workers.items():
                img, wall, cpu, taken = w.render(spp, out_npy, threads=1, seed=seed)
                raw.append(_row(v, spp, seed, img, refs[f"{v}_full"], wall, cpu, taken))
    med = medians(raw)
    tp_raw: list[dict[str, Any]] = []
    for rep in range(cfg.tp_repeats):
        r = tp_bench.render(spp=cfg.tp_spp, threads=1, seed=rep)
        tp_raw.append({"renderer": "relray", "repeat": rep, "spp": cfg.tp_spp,
                       "paths": r.paths, "cpu_s": r.cpu, "wall_s": r.wall,
                       "load1": cm.load_average()[0]})
        for v, w in tp_workers.items():
            _, wall, cpu, taken = w.render(cfg.tp_spp, out_npy, threads=1, seed=rep)
            tp_raw.append({"renderer": v, "repeat": rep, "spp": taken,
                           "paths": cfg.tp_size * cfg.tp_size * taken, "cpu_s": cpu,
                           "wall_s": wall, "load1": cm.load_average()[0]})
    tp = []
    for name in ("relray", *workers):
        rs = [r for r in tp_raw if r["renderer"] == name]
        cpu = statistics.median(r["cpu_s"] for r in rs)
        tp.append({"renderer": name, "size": cfg.tp_size, "spp": rs[0]["spp"],
                   "paths": rs[0]["paths"], "cpu_s": cpu,
                   "wall_s": statistics.median(r["wall_s"] for r in rs),
                   "mpaths_per_cpu_s": rs[0]["paths"] / cpu / 1e6,
                   "ns_per_path": 1e9 * cpu / rs[0]["paths"], "n": len(rs)})
    return {"status": status, "converged": converged, "raw": raw, "medians": med,
            "equal_error": equal_error(med, list(workers)), "throughput": tp,
            "throughput_raw": tp_raw, "refs": refs, "config": asdict(cfg)}


def _row(series: str, spp: int, seed: int, img: np.ndarray, ref: np.ndarray, wall: float,
         cpu: float, taken: float) -> dict[str, Any]:
    return {"series": series, "x": spp, "seed": seed, "spp_taken": taken, "wall_s": wall,
            "cpu_s": cpu, "rel_mse": cm.rel_mse(img, ref), "de00": cm.mean_de00(img, ref),
            "load1": cm.load_average()[0]}


def compare(refs: dict[str, np.ndarray], variants: list[str]) -> list[dict[str, Any]]:
    """Converged relray against each converged Mitsuba variant: luminance ratio
    (relray / Mitsuba), mean and 95th-percentile ΔE00, full GI and direct light only."""
    rows = []
    for v in variants:
        for label in ("direct", "full"):
            a, b = refs[f"relray_{label}"], refs[f"{v}_{label}"]
            de = cm.delta_e00(a, b)
            ma, mb = a.mean(axis=(0, 1)), b.mean(axis=(0, 1))
            rows.append({"variant": v, "light": "direct only" if label == "direct"
                         else "full GI", "luminance_ratio":
                         cm.mean_luminance(a) / cm.mean_luminance(b),
                         "mean_ratio_r": ma[0] / mb[0], "mean_ratio_g": ma[1] / mb[1],
                         "mean_ratio_b": ma[2] / mb[2], "de00_mean": float(de.mean()),
                         "de00_p95": float(np.percentile(de, 95)),
                         "rel_mse": cm.rel_mse(a, b)})
    return rows


def medians(raw: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per (series, spp): medians over the repeats."""
    groups: dict[tuple[str, int], list[dict[str, Any]]] = {}
    for r in raw:
        groups.setdefault((r["series"], r["x"]), []).append(r)
    out = []
    for (series, x), rs in groups.items():
        row: dict[str, Any] = {"series": series, "x": x, "n": len(rs)}
        for k in ("spp_taken", "wall_s", "cpu_s", "rel_mse", "de00", "load1"):
            row[k] = statistics.median(r[k] for r in rs)
        out.append(row)
    return out


def equal_error(med: list[dict[str, Any]], variants: list[str]) -> list[dict[str, Any]]:
    """CPU time relray ÷ each Mitsuba variant at equal error, two levels per metric.

    The high level is the largest error any series has at the ladder's 2nd step, the
    low one the largest of the series' lowest errors: every curve reaches both, so the
    times are interpolated (log-log), not extrapolated, unless flagged.
    """
    rows = []
    series = ["relray", *variants]
    xs = sorted({r["x"] for r in med})
    for err in ("rel_mse", "de00"):
        curves = {s: sorted((r["cpu_s"], r[err]) for r in med if r["series"] == s)
                  for s in series}
        if any(len(c) < 2 for c in curves.values()) or len(xs) < 2:
            continue
        by = {(r["series"], r["x"]): r[err] for r in med}
        high = max(by[(s, xs[1])] for s in series)
        low = max(min(e for _, e in curves[s]) for s in series)
        for i, level in enumerate([high, low] if low < high else [high]):
            ta, xa = cm.time_at_error([c[0] for c in curves["relray"]],
                                      [c[1] for c in curves["relray"]], level)
            for v in variants:
                tb, xb = cm.time_at_error([c[0] for c in curves[v]],
                                          [c[1] for c in curves[v]], level)
                rows.append({"metric": err, "level_index": i, "level": level,
                             "peer": v, "relray_cpu_s": ta, "peer_cpu_s": tb,
                             "ratio_relray_over_peer": ta / tb,
                             "extrapolated": bool(xa or xb)})
    return rows
