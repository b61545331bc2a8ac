"""The command line: ``relray render``, ``relray info``, ``relray contact-sheet``.

Every user error (a malformed job, a missing file, |β| ≥ 1, ...) ends with one line on
stderr naming the key and the file, exit code 2, and no file written.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from .errors import UserError

EXIT_USER_ERROR = 2


def parse_frames(text: str) -> tuple[int, int]:
    """'A-B' or 'A' -> (A, B)."""
    try:
        a, _, b = text.partition("-")
        first, last = int(a), int(b or a)
    except ValueError:
        raise UserError(f"expected A-B or A, got {text!r}", key="--frames") from None
    if last < first:
        raise UserError(f"last frame {last} is before first frame {first}", key="--frames")
    return first, last


def parse_vector(text: str, key: str) -> np.ndarray:
    """'x,y,z' -> a float64 3-vector."""
    try:
        v = np.array([float(x) for x in text.split(",")], np.float64)
    except ValueError:
        raise UserError(f"expected x,y,z numbers, got {text!r}", key=key) from None
    if v.shape != (3,):
        raise UserError(f"expected three numbers x,y,z, got {text!r}", key=key)
    return v


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="relray", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a job's frames")
    r.add_argument("job", type=Path)
    r.add_argument("--frames", help="A-B: render only these frames")
    r.add_argument("--spp", type=int, help="samples per pixel")
    r.add_argument("--beta", help="camera velocity x,y,z (lab frame, |beta| < 1)")
    r.add_argument("--ct", type=float, help="camera proper time of the first frame")
    r.add_argument("--out", type=Path, help="output folder")
    r.add_argument("--threads", type=int, help="worker threads (0 = all cores)")
    r.add_argument("--overwrite", action="store_true", help="render finished frames again")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    i = sub.add_parser("info", help="print the parsed job, gamma and the D range")
    i.add_argument("job", type=Path)
    c = sub.add_parser("contact-sheet", help="tile a folder's PNG frames into one image")
    c.add_argument("folder", type=Path)
    c.add_argument("--out", type=Path, required=True)
    c.add_argument("--columns", type=int, default=8)
    return p


def load_with_overrides(args: argparse.Namespace):
    from . import job as jobmod

    job = jobmod.load_job(args.job)
    return jobmod.with_overrides(
        job,
        spp=getattr(args, "spp", None),
        beta=parse_vector(args.beta, "--beta") if getattr(args, "beta", None) else None,
        ct=getattr(args, "ct", None),
        frames=parse_frames(args.frames) if getattr(args, "frames", None) else None,
        out=getattr(args, "out", None),
        threads=getattr(args, "threads", None),
    )


def cmd_render(args: argparse.Namespace) -> int:
    from .render import render_job

    job = load_with_overrides(args)
    written = render_job(job, overwrite=args.overwrite, show_progress=not args.quiet)
    for path in written:
        print(path)
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    from . import job as jobmod
    from . import relativity
    from .camera import PinholeCamera, lab_rays
    from .render import camera_settings, frame_events

    job = load_with_overrides(args)
    print(jobmod.job_summary(job))
    cam = camera_settings(job)
    if cam is None:
        from .scene import build_scene

        cam = build_scene(job).camera
    pin = PinholeCamera.from_settings(cam, job.render.width, job.render.height)
    cols, rows = np.meshgrid(np.linspace(0, job.render.width, 33),
                             np.linspace(0, job.render.height, 33))
    d_cam = pin.directions_cam(cols.ravel(), rows.ravel())
    for frame, ev in frame_events(job):
        _, D = lab_rays(d_cam, ev.beta)
        speed = float(np.linalg.norm(ev.beta))
        print(f"frame {frame}: beta = {np.array2string(ev.beta, precision=6)} "
              f"|beta| = {speed:.9g}  gamma = {relativity.gamma(ev.beta):.9g}  "
              f"ct' = {ev.tau:.6g}  t_lab = {ev.t:.6g}  "
              f"x_lab = {np.array2string(ev.x, precision=4)}  "
              f"D over the image: {D.min():.6g} .. {D.max():.6g}")
    return 0


def cmd_contact_sheet(args: argparse.Namespace) -> int:
    from .contact import write_contact_sheet

    frames = sorted(p for p in args.folder.glob("*.png") if not p.name.startswith("."))
    if not frames:
        raise UserError("no PNG frames found", key="folder", file=args.folder)
    path = write_contact_sheet(frames, args.out, columns=max(1, args.columns))
    print(f"contact sheet of {len(frames)} frames: {path}")
    return 0


def main(argv: list[str] | None = None) -> int:
    logging.basicConfig(level=logging.WARNING, format="relray: %(message)s")
    args = build_parser().parse_args(argv)
    commands = {"render": cmd_render, "info": cmd_info, "contact-sheet": cmd_contact_sheet}
    try:
        return commands[args.command](args)
    except UserError as e:
        print(f"relray: error: {e}", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print("relray: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())

