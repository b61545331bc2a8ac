"""The command line: ``relray render``, ``relray info``, ``relray contact-sheet``.

Every user error (a malformed job, a missing file, |β| ≥ 1, an unreachable
``--scheduler``, ...) ends with one line on stderr naming the key and the file, exit
code 2, and no file written.

``relray render`` renders in this process by default; ``--scheduler tcp://HOST:8786``
sends the frames to a Dask cluster and ``--workers N`` to a LocalCluster on 127.0.0.1
(see :mod:`.farm`). ``--json-progress`` prints JSON lines for other programs (the
subprocess contract in :mod:`.farm`). Exit codes: 0 done, 1 some frames failed, 2 a
user error, 130 interrupted (SIGINT or SIGTERM; finished frames stay, a rerun resumes).
"""

from __future__ import annotations

import argparse
import contextlib
import logging
import os
import re
import signal
import sys
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import NoReturn

import numpy as np

from . import farm, resources
from .errors import UserError
from .files import is_regular_file
from .output.contact import write_contact_sheet
from .output.frame_files import check_frame_names
from .physics import relativity
from .progress import JsonReporter, TqdmReporter, default_reporter
from .render.camera import PinholeCamera, lab_rays
from .render.frames import RenderCancelled
from .runner import render_job
from .scene import job as jobmod
from .scene import schema as schemamod
from .scene.motion import camera_settings, frame_events
from .scene.spectral_model import AUTO, resolve

EXIT_FRAMES_FAILED = 1
EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141
"""The reader of stdout went away (``relray info job.toml | head``): 128 + SIGPIPE, as a
shell reports a command killed by SIGPIPE, but silently and without dying by it."""
DEBUG_ENV = "RELRAY_DEBUG"
"""Set to 1 to get the Python traceback of an internal error."""


def parse_frames(text: str, file: Path | None = None) -> tuple[int, int]:
    """'A-B' or 'A' -> (A, B); errors name ``--frames`` and the job ``file``."""
    try:
        a, _, b = text.partition("-")
        first, last = int(a), int(b or a)
    except ValueError:
        raise UserError(f"expected A-B or A, got {text!r}", key="--frames", file=file) from None
    if last < first:
        raise UserError(f"last frame {last} is before first frame {first}", key="--frames",
                        file=file)
    return first, last


def parse_vector(text: str, key: str, file: Path | None = None) -> np.ndarray:
    """'x,y,z' -> a float64 3-vector; errors name ``key`` and the job ``file``."""
    try:
        v = np.array([float(x) for x in text.split(",")], np.float64)
    except ValueError:
        raise UserError(f"expected x,y,z numbers, got {text!r}", key=key, file=file) from None
    if v.shape != (3,):
        raise UserError(f"expected three numbers x,y,z, got {text!r}", key=key, file=file)
    return v


class OneLineParser(argparse.ArgumentParser):
    """argparse whose errors (an option of the wrong type, a missing argument) are one
    line naming the option, exit code 2, like every other user error."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USER_ERROR, f"relray: error: {' '.join(message.split())}\n")


def add_overrides(p: argparse.ArgumentParser) -> None:
    """The job file and the options that override its keys (``render`` and ``info``)."""
    p.add_argument("job", type=Path)
    p.add_argument("--frames", help="A-B: render only these frames")
    p.add_argument("--spp", type=int, help="samples per pixel")
    p.add_argument("--beta", help="camera velocity x,y,z (lab frame, |beta| < 1)")
    p.add_argument("--ct", type=float, help="camera proper time of the first frame")
    p.add_argument("--out", type=Path, help="output folder")
    p.add_argument("--threads", type=int, help="worker threads (0 = all cores)")


_NEGATIVE_VALUE = re.compile(r"-(\d|\.\d|inf|nan)", re.IGNORECASE)


def join_negative_values(argv: list[str], parser: argparse.ArgumentParser) -> list[str]:
    """``--beta -0.5,0,0`` -> ``--beta=-0.5,0,0`` for every option that takes a value.

    argparse reads a token that starts with '-' as an option unless it is a plain
    negative number, so a negative vector (or ``--ct -1e3``) would be refused with
    "expected one argument".
    """
    takes_value = {opt for action in parser._actions if action.nargs is None
                   and action.option_strings for opt in action.option_strings}
    for sub in parser._actions:
        for choice in getattr(sub, "choices", None) or {}:
            takes_value |= {opt for action in sub.choices[choice]._actions
                            if action.nargs is None and action.option_strings
                            for opt in action.option_strings}
    out: list[str] = []
    i = 0
    while i < len(argv):
        if argv[i] in takes_value and i + 1 < len(argv) and _NEGATIVE_VALUE.match(argv[i + 1]):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def build_parser() -> argparse.ArgumentParser:
    p = OneLineParser(prog="relray", description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render", help="render a job's frames")
    add_overrides(r)
    r.add_argument("--overwrite", action="store_true", help="render finished frames again")
    r.add_argument("--quiet", action="store_true", help="no progress bar")
    r.add_argument("--scheduler", metavar="ADDRESS",
                   help="render on a Dask cluster: its scheduler, tcp://HOST:8786")
    r.add_argument("--workers", type=int, metavar="N",
                   help="render on a local Dask cluster of N processes (127.0.0.1)")
    r.add_argument("--batches", type=int, default=16, metavar="N",
                   help="sample batches of a still on a Dask cluster (default 16)")
    r.add_argument("--connect-timeout", type=float, default=10.0, metavar="S",
                   help="seconds to reach --scheduler (default 10)")
    r.add_argument("--json-progress", action="store_true",
                   help="print progress as JSON lines on stdout (for other programs)")
    i = sub.add_parser("info", help="print the parsed job, gamma and the D range "
                       "(with the same overrides as render: what a render would do)")
    add_overrides(i)
    c = sub.add_parser("contact-sheet", help="tile a folder's PNG frames into one image")
    c.add_argument("folder", type=Path)
    c.add_argument("--out", type=Path, required=True)
    c.add_argument("--columns", type=int, default=8)
    s = sub.add_parser("schema", help="print the job file's JSON Schema (for editors: "
                       "docs/job-format.md, \"Editor support\")")
    s.add_argument("-o", "--out", type=Path, help="write it to this file instead")
    return p


def load_with_overrides(args: argparse.Namespace):
    job = jobmod.load_job(args.job)
    return jobmod.with_overrides(
        job,
        spp=getattr(args, "spp", None),
        beta=parse_vector(args.beta, "--beta", args.job) if getattr(args, "beta", None)
        else None,
        ct=getattr(args, "ct", None),
        frames=parse_frames(args.frames, args.job) if getattr(args, "frames", None) else None,
        out=getattr(args, "out", None),
        threads=getattr(args, "threads", None),
    )


def check_farm_options(args: argparse.Namespace) -> None:
    """The Dask options make sense together (user errors name the option)."""
    if args.scheduler is not None and args.workers is not None:
        raise UserError("give either --scheduler or --workers, not both", key="--workers")
    if args.scheduler is not None and not args.scheduler.strip():
        raise UserError("expected tcp://HOST:PORT, got ''", key="--scheduler")
    most = resources.max_threads()
    if args.workers is not None and not 1 <= args.workers <= most:
        raise UserError(f"must be 1..{most} ({resources.MAX_THREADS_PER_CORE} per usable core "
                        f"here), got {args.workers}", key="--workers")
    if not 1 <= args.batches <= 65536:
        raise UserError(f"must be 1..65536, got {args.batches}", key="--batches")
    if not 0.0 < args.connect_timeout <= 3600.0:
        raise UserError(f"must be in (0, 3600] seconds, got {args.connect_timeout}",
                        key="--connect-timeout")


@contextlib.contextmanager
def interrupts(cancel: threading.Event) -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP set ``cancel`` and raise KeyboardInterrupt (main thread
    only), after calling the handler they replace (if it is a Python function)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        cancel.set()
        previous = old.get(signum)
        if callable(previous):  # relray.cli_main's: it remembers the signal too
            previous(signum, frame)
        raise KeyboardInterrupt

    names = ("SIGINT", "SIGTERM", "SIGHUP", "SIGBREAK")
    sigs = [getattr(signal, n) for n in names if hasattr(signal, n)]
    old = {sig: signal.signal(sig, handler) for sig in sigs}
    try:
        yield
    finally:
        for sig, h in old.items():
            signal.signal(sig, h)


def cmd_render(args: argparse.Namespace) -> int:
    reporter = default_reporter(not args.quiet, args.json_progress)
    cancel = threading.Event()
    failed: dict[int, str] = {}
    code = 0
    try:
        with interrupts(cancel):
            check_farm_options(args)
            job = load_with_overrides(args)
            if args.scheduler is not None or args.workers is not None:
                farm.quiet_dask_logging()
                result = farm.render(job, scheduler=args.scheduler, workers=args.workers or 0,
                                     overwrite=args.overwrite, reporter=reporter,
                                     batches=args.batches,
                                     connect_timeout=args.connect_timeout)
                written, failed, code = result.written, result.failed, result.exit_code
            else:
                written = render_job(job, overwrite=args.overwrite, reporter=reporter,
                                     cancel=cancel.is_set)
    except UserError as e:
        if isinstance(reporter, JsonReporter):
            reporter.error(None, str(e), kind="user")
        reporter.finish("error", exit_code=EXIT_USER_ERROR)
        raise
    except (KeyboardInterrupt, RenderCancelled):
        reporter.finish("cancelled", exit_code=EXIT_INTERRUPTED)
        raise KeyboardInterrupt from None
    if not isinstance(reporter, TqdmReporter):  # the bar printed them as they came
        for frame, message in sorted(failed.items()):
            print(f"relray: error: frame {frame} failed: {message}", file=sys.stderr)
    if failed:
        print(f"relray: error: {len(failed)} frame(s) failed: "
              f"{', '.join(str(f) for f in sorted(failed))}; the others are done, "
              "a rerun renders only the missing frames", file=sys.stderr)
        return code
    if not args.json_progress:
        for path in written:
            print(path)
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    job = load_with_overrides(args)
    events = frame_events(job)
    check_frame_names(job)
    print(jobmod.job_summary(job))
    if job.render.spectral == AUTO:
        model, why = resolve(job)
        print(f"spectral    auto renders with {model} ({why})")
    cam = camera_settings(job)
    pin = PinholeCamera.from_settings(cam, job.render.width, job.render.height)
    cols, rows = np.meshgrid(np.linspace(0, job.render.width, 33),
                             np.linspace(0, job.render.height, 33))
    d_cam = pin.directions_cam(cols.ravel(), rows.ravel())
    for frame, ev in events:
        _, D = lab_rays(d_cam, ev.beta)
        speed = float(np.linalg.norm(ev.beta))
        print(f"frame {frame}: beta = {np.array2string(ev.beta, precision=6)} "
              f"|beta| = {speed:.9g}  gamma = {relativity.gamma(ev.beta):.9g}  "
              f"ct' = {ev.tau:.6g}  t_lab = {ev.t:.6g}  "
              f"x_lab = {np.array2string(ev.x, precision=4)}  "
              f"D over the image: {D.min():.6g} .. {D.max():.6g}")
    return 0


def cmd_contact_sheet(args: argparse.Namespace) -> int:
    frames = sorted(p for p in args.folder.glob("*.png")
                    if not p.name.startswith(".") and is_regular_file(p))
    if not frames:
        raise UserError("no PNG frames found", key="folder", file=args.folder)
    path = write_contact_sheet(frames, args.out, columns=max(1, args.columns))
    print(f"contact sheet of {len(frames)} frames: {path}")
    return 0


def cmd_schema(args: argparse.Namespace) -> int:
    if args.out is None:
        sys.stdout.write(schemamod.json_text())
        return 0
    try:
        args.out.write_text(schemamod.json_text(), encoding="utf-8")
    except OSError as e:
        raise UserError(f"cannot write: {e.strerror or e}", key="--out", file=args.out) from None
    print(args.out)
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run one command; every failure ends as one line on stderr and an exit code.

    0 done; 1 some frames failed (or an internal error: a bug, whose traceback
    ``RELRAY_DEBUG=1`` shows); 2 a user or environment error (the job, a file, the disk,
    memory); 130 interrupted; 141 stdout closed by its reader.
    """
    before = list(logging.getLogger().handlers)
    logging.basicConfig(level=logging.WARNING, format="relray: %(message)s")
    for handler in logging.getLogger().handlers:  # libraries' INFO chatter (Dask) stays out
        if handler not in before:
            handler.setLevel(logging.WARNING)
    parser = build_parser()
    args = parser.parse_args(join_negative_values(list(sys.argv[1:] if argv is None
                                                       else argv), parser))
    commands = {"render": cmd_render, "info": cmd_info, "contact-sheet": cmd_contact_sheet,
                "schema": cmd_schema}
    try:
        return commands[args.command](args)
    except UserError as e:
        return fail(str(e), EXIT_USER_ERROR)
    except farm.SchedulerLostError as e:
        return fail(str(e), EXIT_FRAMES_FAILED)
    except KeyboardInterrupt:
        return fail("interrupted", EXIT_INTERRUPTED, prefix="relray: ")
    except BrokenPipeError:
        silence_stdout()
        return EXIT_BROKEN_PIPE
    except MemoryError:
        return fail("out of memory: lower render.width, render.height or the scene's "
                    "subdivisions, or free memory", EXIT_USER_ERROR, file=args.job
                    if hasattr(args, "job") else None)
    except RecursionError:
        return fail("nested too deeply to read", EXIT_USER_ERROR,
                    file=getattr(args, "job", None))
    except OSError as e:
        return fail(os_error_message(e), EXIT_USER_ERROR)
    except Exception as e:  # a bug: one line, the traceback only on request
        if os.environ.get(DEBUG_ENV):
            raise
        return fail(f"internal error: {type(e).__name__}: {' '.join(str(e).split())} "
                    f"(set {DEBUG_ENV}=1 for the traceback, and please report it)",
                    EXIT_FRAMES_FAILED)


def fail(message: str, code: int, file: Path | None = None,
         prefix: str = "relray: error: ") -> int:
    """Print one line on stderr (``file: message``); return ``code``."""
    where = f"{file}: " if file is not None else ""
    with contextlib.suppress(OSError):
        print(f"{prefix}{where}{message}", file=sys.stderr)
    return code


def os_error_message(e: OSError) -> str:
    """An environment error (disk full, permissions, a symlink loop ...) as one line that
    names the file."""
    reason = e.strerror or " ".join(str(e).split()) or type(e).__name__
    names = [str(f) for f in (e.filename, e.filename2) if f is not None]
    return f"{' -> '.join(names)}: {reason}" if names else reason


def silence_stdout() -> None:
    """Point stdout at the null device, so that the interpreter's final flush of a
    closed pipe does not print "Exception ignored ... BrokenPipeError"."""
    with contextlib.suppress(OSError, ValueError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())


if __name__ == "__main__":
    sys.exit(main())
