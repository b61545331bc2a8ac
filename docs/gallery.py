"""Render the README's gallery: the seed report's figures, the moving objects and the
fly-by contact sheet.

    .venv/bin/python docs/gallery.py [--spp N] [--only seed,moving]

Renders every job in presets/seed_figures/ (into out/seed_figures/) and writes
docs/gallery/seed_figures.png, a captioned contact sheet.  Then it renders the Doppler
figures 2-3 ... 2-18 again with relray's physics (CIE 1931 sensor, Jakob-Hanika spectra,
Doppler and the D^5 searchlight) into docs/gallery/seed_figures_physical.png, and writes
docs/gallery/flyby.png from out/flyby/ when `make demo` has rendered it. The moving
objects' presets (presets/moving/) give one chosen frame each to
docs/gallery/moving.png. The starfield presets (presets/stars/: ahead, sideways and back,
β = 0 ... 0.999 as frames 1-5) go to docs/gallery/stars.png, one row per view.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
from pathlib import Path

from relray.core.output.contact import write_contact_sheet
from relray.core.runner import render_job
from relray.core.scene import job as jobmod

ROOT = Path(__file__).resolve().parents[1]


def figure_key(path: Path) -> tuple[int, int]:
    """fig2-13.toml -> (2, 13), for the seed's order."""
    a, b = re.match(r"fig(\d+)-(\d+)", path.stem).groups()
    return int(a), int(b)


def caption(job: jobmod.Job) -> str:
    b = job.motion.beta
    beta = ",".join(f"{x:g}" for x in b)
    return f"{job.path.stem}  ct={job.motion.ct:g}  b=({beta})  {job.render.spectral}"


def physical_job(job: jobmod.Job) -> jobmod.Job:
    """The same figure with relray's spectral model, Doppler and searchlight."""
    render = dataclasses.replace(job.render, spectral="cie1931", doppler=True,
                                 searchlight=True)
    output = dataclasses.replace(job.output, dir=ROOT / "out" / "seed_figures_physical")
    return dataclasses.replace(job, render=render, output=output)


def sheet(jobs: list[Path], spp: int | None, name: str, physical: bool) -> None:
    """Render ``jobs`` and tile their PNGs into docs/gallery/NAME.png."""
    pngs, captions = [], []
    for path in jobs:
        job = jobmod.with_overrides(jobmod.load_job(path), spp=spp)
        if physical:
            job = physical_job(job)
        render_job(job, overwrite=True, show_progress=False)
        pngs.append(job.output.dir / f"{job.output.name.format(frame=1)}.png")
        captions.append(caption(job))
        print(pngs[-1])
    print(write_contact_sheet(pngs, ROOT / "docs" / "gallery" / f"{name}.png", columns=6,
                              captions=captions))


#: The frame of each moving preset that the gallery shows, and its caption.
MOVING = (("terrell", 7, "0.9 c past a camera at rest: the sphere stays round"),
          ("ships", 7, "ship B closing at 0.9 c, seen from ship A"),
          ("mirror", 8, "mirrors at rest (left) and receding at 0.1 c"),
          ("train", 12, "a train at 0.8 c: colour changes along it"))


def moving_sheet(spp: int | None) -> None:
    """One frame of each moving preset, tiled into docs/gallery/moving.png."""
    pngs, captions = [], []
    for name, frame, text in MOVING:
        job = jobmod.with_overrides(jobmod.load_job(ROOT / "presets" / "moving" /
                                                    f"{name}.toml"), spp=spp)
        first = job.motion.frames[0]
        motion = dataclasses.replace(job.motion, frames=(frame, frame),
                                     ct=job.motion.ct + (frame - first) * job.motion.ct_per_frame)
        job = dataclasses.replace(job, motion=motion)
        render_job(job, overwrite=True, show_progress=False)
        pngs.append(job.output.dir / f"{job.output.name.format(frame=frame)}.png")
        captions.append(text)
        print(pngs[-1])
    print(write_contact_sheet(pngs, ROOT / "docs" / "gallery" / "moving.png", columns=2,
                              captions=captions))


STAR_VIEWS = (("ahead", "ahead"), ("side", "sideways"), ("back", "back"))
STAR_BETAS = ("0", "0.5", "0.9", "0.99", "0.999")


def stars_sheet() -> None:
    """presets/stars/*.toml (5 frames each) tiled into docs/gallery/stars.png."""
    pngs, captions = [], []
    for name, text in STAR_VIEWS:
        job = jobmod.load_job(ROOT / "presets" / "stars" / f"{name}.toml")
        render_job(job, overwrite=True, show_progress=False)
        for frame, beta in enumerate(STAR_BETAS, start=1):
            pngs.append(job.output.dir / f"{job.output.name.format(frame=frame)}.png")
            captions.append(f"{text}, b = {beta}")
    print(write_contact_sheet(pngs, ROOT / "docs" / "gallery" / "stars.png",
                              columns=len(STAR_BETAS), captions=captions))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spp", type=int, default=None)
    ap.add_argument("--only", default="seed,moving,stars",
                    help="a comma-separated choice of seed, moving, stars")
    args = ap.parse_args()
    parts = set(args.only.split(","))
    if "seed" in parts:
        jobs = sorted((ROOT / "presets" / "seed_figures").glob("fig*.toml"), key=figure_key)
        sheet(jobs, args.spp, "seed_figures", physical=False)
        doppler = [p for p in jobs if figure_key(p)[0] == 2 and figure_key(p)[1] >= 3]
        sheet(doppler, args.spp, "seed_figures_physical", physical=True)
    if "moving" in parts:
        moving_sheet(args.spp)
    if "stars" in parts:
        stars_sheet()
    flyby = sorted((ROOT / "out" / "flyby").glob("frame_*.png"))
    if flyby:
        print(write_contact_sheet(flyby[::3], ROOT / "docs" / "gallery" / "flyby.png",
                                  columns=4, captions=[p.stem for p in flyby[::3]]))


if __name__ == "__main__":
    main()
