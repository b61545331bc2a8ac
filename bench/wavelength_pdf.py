"""Colour noise against the hero wavelengths' pdf: relray's own pdf against Mitsuba 3's.

    .venv/bin/python -m relray.bench.wavelength_pdf [--scene environment] [--size 96]
                                                    [--seeds 6] [--ref-spp 1024]

relray samples its hero wavelengths with a pdf ∝ |r̄|+|ḡ|+|b̄| (the linear-Rec.709
matching functions; physics.md, "Spectral model"). Mitsuba 3's spectral variants use
pdf(λ) ∝ sech²(0.0072 (λ - 538 nm)) (``sample_rgb_spectrum``). This renders one benchmark
scene with each pdf, everything else equal (each against its own ``ref_spp`` reference,
as §2 measures every renderer), and prints mean ΔE00 and relative MSE at 4, 16 and 64 spp
(means over ``seeds`` renders), to tell the share of a difference in colour noise that
is the wavelength pdf's. The second pdf is swapped in for the run only
(:func:`mitsuba_pdf`); the renderer keeps the pdf physics.md prescribes.
"""

from __future__ import annotations

import argparse
import contextlib
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from relray.bench import common as cm
from relray.bench import peer_scenes
from relray.core.physics import spectrum


def sech2_sampler(base: spectrum.WavelengthSampler) -> spectrum.WavelengthSampler:
    """``base``'s bins with pdf ∝ sech²(0.0072 (λ - 538)) at their centres (0 where
    ``base`` has none)."""
    edges = base.edges_nm
    mid = 0.5 * (edges[:-1] + edges[1:])
    f = np.where(base.pdf > 0.0, 1.0 / np.cosh(0.0072 * (mid - 538.0)) ** 2, 0.0)
    widths = np.diff(edges)
    p = f / np.sum(f * widths)
    cdf = np.concatenate([[0.0], np.cumsum(p * widths)])
    cdf /= cdf[-1]
    cdf[-1] = 1.0
    return spectrum.WavelengthSampler(edges_nm=edges, cdf=cdf, pdf=p)


@contextlib.contextmanager
def mitsuba_pdf() -> Iterator[None]:
    """Within the block, renderers built for the cie1931 model sample Mitsuba's pdf."""
    orig = spectrum.make_sampler

    def make(mode, *a, **k):
        s = orig(mode, *a, **k)
        return sech2_sampler(s) if mode == "cie1931" else s

    spectrum.make_sampler = make
    try:
        yield
    finally:
        spectrum.make_sampler = orig


def scene(name: str, tmp: Path, size: int) -> cm.RelrayBench:
    """The Cornell box or one of §2's peer scenes at ``size``²."""
    if name == "cornell":
        return cm.RelrayBench(cm.make_job(cm.job_dict(), width=size, height=size))
    return peer_scenes.scene_bench(name, tmp, size, size)


def errors(bench: cm.RelrayBench, ref_spp: int, seeds: int) -> list[dict]:
    """Mean ΔE00 and relative MSE at 4, 16 and 64 spp against a ``ref_spp`` reference."""
    ref = bench.render(spp=ref_spp, threads=2, seed=1000).rgb
    rows = []
    for spp in (4, 16, 64):
        imgs = [bench.render(spp=spp, threads=2, seed=s).rgb for s in range(seeds)]
        rows.append({"spp": spp,
                     "de00": float(np.mean([cm.mean_de00(i, ref) for i in imgs])),
                     "rel_mse": float(np.mean([cm.rel_mse(i, ref) for i in imgs]))})
    return rows


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scene", default="environment",
                    choices=("cornell", *peer_scenes.SCENES))
    ap.add_argument("--size", type=int, default=96)
    ap.add_argument("--seeds", type=int, default=6)
    ap.add_argument("--ref-spp", type=int, default=1024)
    a = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        own = errors(scene(a.scene, Path(tmp) / "own", a.size), a.ref_spp, a.seeds)
        with mitsuba_pdf():
            sech = errors(scene(a.scene, Path(tmp) / "sech", a.size), a.ref_spp, a.seeds)
    print(f"{a.scene}, {a.size}², {a.seeds} seeds, references {a.ref_spp} spp; "
          f"load {cm.load_average()[0]:.2f}")
    print("spp  ΔE00 relray's pdf  ΔE00 Mitsuba's  rel. MSE relray's pdf  rel. MSE Mitsuba's")
    for o, s in zip(own, sech, strict=True):
        print(f"{o['spp']:>3}  {o['de00']:>16.3f}  {s['de00']:>14.3f}  {o['rel_mse']:>20.5f}"
              f"  {s['rel_mse']:>18.5f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
