"""Environment maps in the spectral modes: how long a map's spectral tables take to prepare.

    .venv/bin/python bench/env_prepare.py [--size 2048x1024] [--reference 16384] [--seed 0]

The map: every texel's three channels drawn independently, log-normal (σ = 1.5), as
float32 (as read from an EXR), so every texel is a distinct colour (2 M at 2048 × 1024).
"after": :func:`..core.render.environment.texel_table` in the default ``cie1931`` mode
(the per-texel sigmoid coefficients, :func:`..core.physics.rgb_table.coefficients`:
distinct colours, table start, compiled polish on the usable cores), wall and process CPU
time, after a small call that compiles the kernels. "before": the code this replaced
(``np.unique(axis=0)``, then :func:`..core.physics.sigmoid.fit` in numpy batches of 4096
from the table start), the fit timed on ``--reference`` distinct colours of the same map
and extrapolated linearly to all of them (the whole map takes minutes), the unique
measured on the whole map. Prints a markdown table.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import numpy as np

from relray.core.physics import rgb_table as rt
from relray.core.physics import sigmoid as sg
from relray.core.physics.spectrum import reflectance_fit_model
from relray.core.render.environment import texel_table
from relray.core.resources import usable_cores


def hdr_map(width: int, height: int, seed: int = 0) -> np.ndarray:
    """The random HDR map (module docstring), float32 (height, width, 3)."""
    rng = np.random.default_rng(seed)
    return rng.lognormal(0.0, 1.5, (height, width, 3)).astype(np.float32)


def normalised(rgb: np.ndarray) -> np.ndarray:
    """The texels as :func:`texel_table` hands them to ``coefficients``: rgb / (2 max)."""
    px = rgb.reshape(-1, 3).astype(np.float64)
    k = 2.0 * px.max(axis=1)
    return px / np.where(k > 0.0, k, 1.0)[:, None]


def prepare_seconds(rgb: np.ndarray) -> tuple[float, float]:
    """(wall s, process CPU s) of ``texel_table(rgb, "cie1931")`` (kernels compiled
    beforehand on an 8 × 4 map)."""
    texel_table(hdr_map(8, 4, seed=99).astype(np.float64), "cie1931")
    w0, c0 = time.perf_counter(), time.process_time()
    texel_table(rgb.astype(np.float64), "cie1931")
    return time.perf_counter() - w0, time.process_time() - c0


def reference_polish(distinct: np.ndarray, batch: int = 4096) -> np.ndarray:
    """The replaced polish: the table start, then :func:`sigmoid.fit` on the non-grey
    colours, ``batch`` at a time (POLISH_TOL, POLISH_ITER; μ0 = 1e-3)."""
    table = rt.coefficient_table()
    model = reflectance_fit_model()
    out = np.empty(distinct.shape)
    rt._coefficients_kernel(table.scale, table.data, np.ascontiguousarray(distinct), out)
    todo = np.flatnonzero(np.ptp(distinct, axis=1) > 0.0)
    for k in range(0, len(todo), batch):
        rows = todo[k:k + batch]
        none = np.full(len(rows), np.nan)
        out[rows], _ = sg.fit(distinct[rows], model.t_band, model.B_band, model.b_uv,
                              model.b_ir, none, none, out[rows], tol=rt.POLISH_TOL,
                              max_iter=rt.POLISH_ITER)
    return out


def reference_seconds(rgb: np.ndarray, sample: int) -> dict[str, float]:
    """The replaced code's cost on this map: ``np.unique(axis=0)`` (measured, wall s),
    the fit per distinct colour (µs, on ``sample`` of them) and its extrapolation to all
    distinct colours (s)."""
    flat = np.clip(normalised(rgb), 0.0, 1.0)
    w0 = time.perf_counter()
    distinct = np.unique(flat, axis=0)
    unique_s = time.perf_counter() - w0
    pick = np.random.default_rng(1).choice(len(distinct), min(sample, len(distinct)),
                                           replace=False)
    w0 = time.perf_counter()
    reference_polish(distinct[pick])
    per = (time.perf_counter() - w0) / len(pick)
    return {"distinct": float(len(distinct)), "unique_s": unique_s, "fit_us": per * 1e6,
            "fit_s": per * len(distinct)}


def rows(width: int, height: int, sample: int, seed: int) -> list[dict[str, Any]]:
    """One row per measurement (see :func:`main`)."""
    rgb = hdr_map(width, height, seed)
    wall, cpu = prepare_seconds(rgb)
    ref = reference_seconds(rgb, sample)
    n = ref["distinct"]
    return [
        {"what": "after: texel_table (cie1931), whole map", "wall_s": wall, "cpu_s": cpu,
         "us_per_colour": wall / n * 1e6},
        {"what": "before: np.unique(axis=0), whole map", "wall_s": ref["unique_s"],
         "cpu_s": float("nan"), "us_per_colour": ref["unique_s"] / n * 1e6},
        {"what": f"before: numpy LM polish, {min(sample, int(n))} colours, extrapolated",
         "wall_s": ref["fit_s"], "cpu_s": float("nan"), "us_per_colour": ref["fit_us"]},
    ]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", default="2048x1024")
    ap.add_argument("--reference", type=int, default=16384)
    ap.add_argument("--seed", type=int, default=0)
    a = ap.parse_args(argv)
    w, h = (int(x) for x in a.size.split("x"))
    table = rows(w, h, a.reference, a.seed)
    print(f"# environment map prepare, {w}x{h} random HDR map ({w * h} texels, "
          f"{usable_cores()} usable cores)\n")
    print("| what | wall s | CPU s | µs per distinct colour |")
    print("|---|---:|---:|---:|")
    for r in table:
        print(f"| {r['what']} | {r['wall_s']:.2f} | {r['cpu_s']:.2f} | "
              f"{r['us_per_colour']:.2f} |")


if __name__ == "__main__":
    main()
