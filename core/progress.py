"""Progress of a run: a tqdm bar, JSON lines for other programs, or silence.

The JSON lines are the subprocess contract of ``relray render --json-progress``
(for the Blender add-on and farm managers): one JSON object per line on stdout,
flushed, and nothing else there (:class:`JsonReporter`); stderr carries human-readable
warnings only. Every object has ``"event"``:

============  ==========================================================================
event         fields
============  ==========================================================================
start         version, job, out, mode ("local" | "dask"), scheduler, workers,
              frames [first, last], done, to_render, stale (of to_render: changed
              since they were rendered), stale_reasons {reason: count} (reasons:
              "job", "renderer", "no digest"), todo [frames], unit, units
progress      fraction (0..1), frames_done, frames_total, elapsed, eta_seconds (or null)
frame_done    frame, path (the EXR, else the first file), paths, seconds, fraction,
              frames_done, frames_total, exposure (stops applied to the PNG, or null
              when not known: a farm frame), exposure_metered (output.exposure = "auto":
              the frame's meter reading in stops, null for a black frame; else absent)
error         frame (null when not about one frame), message, kind ("frame" | "user")
finish        status ("ok" | "failed" | "cancelled" | "error"), exit_code, rendered,
              failed [frames], seconds
============  ==========================================================================

Exit codes: 0 every frame done; 1 some frames failed (each named in an ``error``
event and on stderr); 2 a user error (one line on stderr naming the key and the file,
nothing written); 130 cancelled. :func:`parse_event` reads a line back; the command line
and environment of such a child come from :func:`relray.core.farm.render_command` and
:func:`relray.core.farm.subprocess_env`.
"""

from __future__ import annotations

import json
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TextIO

from tqdm import tqdm

from .. import __version__
from .output.exposure import FrameExposure
from .output.frame_files import STALE_REASONS, FramePlan
from .scene.description import Job

PROGRESS_INTERVAL_S = 0.5
"""Least time between two JSON ``progress`` events of the local renderer."""


# ------------------------------------------------------------------------------ reporters
class Reporter:
    """Hears a run's events; this base class stays silent (``--quiet``).

    Sub-classes print a tqdm bar (:class:`TqdmReporter`) or JSON lines
    (:class:`JsonReporter`). ``advance`` may be called from render threads.
    """

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.t0 = time.perf_counter()
        self.units = 0
        self.units_done = 0
        self.frames_total = 0
        self.frames_done = 0
        self.rendered: list[int] = []
        self.exposures: dict[int, FrameExposure] = {}
        """Each finished frame's exposure, where the run knows it."""
        self.failed: list[int] = []
        self.finished = False

    def start(self, job: Job, plan: FramePlan, mode: str, units: int, unit: str,
              scheduler: str | None = None, workers: int | None = None) -> None:
        self.t0 = time.perf_counter()
        self.units, self.units_done = int(units), 0
        self.frames_total = len(plan.todo)
        self._started(job, plan, mode, unit, scheduler, workers)

    def advance(self, n: int) -> None:
        with self.lock:
            self.units_done += int(n)
            self._advanced(int(n))

    def frame_done(self, frame: int, paths: Sequence[Path | str], seconds: float,
                   d_range: tuple[float, float] | None = None,
                   exposure: FrameExposure | None = None) -> None:
        with self.lock:
            self.frames_done += 1
            self.rendered.append(frame)
            if exposure is not None:
                self.exposures[frame] = exposure
            self._frame_done(frame, [str(p) for p in paths], seconds, d_range)

    def error(self, frame: int | None, message: str, kind: str = "frame") -> None:
        with self.lock:
            if frame is not None:
                self.failed.append(frame)
            self._error(frame, message, kind)

    def finish(self, status: str, seconds: float | None = None, exit_code: int = 0) -> None:
        if self.finished:
            return
        self.finished = True
        took = time.perf_counter() - self.t0 if seconds is None else seconds
        self._finished(status, took, exit_code)

    @property
    def fraction(self) -> float:
        return min(1.0, self.units_done / self.units) if self.units else 1.0

    def eta_seconds(self) -> float | None:
        f = self.fraction
        if f <= 0.0 or f >= 1.0:
            return None if f <= 0.0 else 0.0
        return (time.perf_counter() - self.t0) * (1.0 - f) / f

    # hooks for sub-classes
    def _started(self, job, plan, mode, unit, scheduler, workers) -> None:
        pass

    def _advanced(self, n: int) -> None:
        pass

    def _frame_done(self, frame, paths, seconds, d_range) -> None:
        pass

    def _error(self, frame, message, kind) -> None:
        pass

    def _finished(self, status, seconds, exit_code) -> None:
        pass


def plan_message(plan: FramePlan, out_dir: Path) -> str:
    """"relray: N done, M to render (K changed since they were rendered: WHY) -> DIR",
    WHY from :data:`.output.frame_files.STALE_REASONS` (with counts when they differ)."""
    stale = ""
    if plan.stale:
        reasons = plan.stale_reasons or {}
        if len(reasons) == 1:
            why = ": " + STALE_REASONS.get(next(iter(reasons)), next(iter(reasons)))
        else:
            why = ": " + "; ".join(f"{n} {STALE_REASONS.get(r, r)}" for r, n in reasons.items())
        stale = f" ({plan.stale} changed since they were rendered{why if reasons else ''})"
    return f"relray: {plan.done} done, {len(plan.todo)} to render{stale} -> {out_dir}"


class TqdmReporter(Reporter):
    """"N done, M to render" on stdout, then a tqdm bar (paths locally, frames on Dask)."""

    def __init__(self, stream: TextIO | None = None) -> None:
        super().__init__()
        self.stream = stream
        self.bar = None

    def _started(self, job, plan, mode, unit, scheduler, workers) -> None:
        where = "" if mode == "local" else f" on {scheduler or f'{workers} local workers'}"
        print(plan_message(plan, job.output.dir) + where, flush=True)
        if plan.todo:
            self.bar = tqdm(total=self.units, unit=unit, unit_scale=unit == "path",
                            desc="render", dynamic_ncols=True, file=self.stream)

    def _advanced(self, n: int) -> None:
        if self.bar is not None:
            self.bar.update(n)

    def _frame_done(self, frame, paths, seconds, d_range) -> None:
        if self.bar is not None:
            d = f" D {d_range[0]:.3g}..{d_range[1]:.3g}" if d_range else ""
            ev = self.exposures.get(frame)
            e = f" {ev.text()}" if ev is not None else ""
            self.bar.set_postfix_str(f"frame {frame}{d}{e}")

    def _error(self, frame, message, kind) -> None:
        what = f"frame {frame} failed: " if frame is not None else ""
        tqdm.write(f"relray: error: {what}{message}", file=sys.stderr)

    def _finished(self, status, seconds, exit_code) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class JsonReporter(Reporter):
    """One JSON object per line on ``stream`` (stdout): the subprocess contract."""

    def __init__(self, stream: TextIO | None = None,
                 interval: float = PROGRESS_INTERVAL_S) -> None:
        super().__init__()
        self.stream = stream if stream is not None else sys.stdout
        self.interval = interval
        self.last_emit = 0.0
        self.mode, self.unit = "local", "path"

    def emit(self, event: str, **fields: Any) -> None:
        line = json.dumps({"event": event, **fields}, allow_nan=False, default=str)
        self.stream.write(line + "\n")
        self.stream.flush()

    def _progress(self) -> None:
        self.last_emit = time.perf_counter()
        eta = self.eta_seconds()
        self.emit("progress", fraction=round(self.fraction, 6), frames_done=self.frames_done,
                  frames_total=self.frames_total,
                  elapsed=round(time.perf_counter() - self.t0, 3),
                  eta_seconds=None if eta is None else round(eta, 3))

    def _started(self, job, plan, mode, unit, scheduler, workers) -> None:
        self.mode, self.unit = mode, unit
        first, last = plan.frames[0], plan.frames[-1]
        self.emit("start", version=__version__, job=str(job.path), out=str(job.output.dir),
                  mode=mode, scheduler=scheduler, workers=workers, frames=[first, last],
                  done=plan.done, to_render=len(plan.todo), stale=plan.stale,
                  stale_reasons=dict(plan.stale_reasons),
                  todo=[f for f, _ in plan.todo],
                  unit=unit, units=self.units, message=plan_message(plan, job.output.dir))

    def _advanced(self, n: int) -> None:
        # paths (local): at most every `interval`; batches: each; frames: after frame_done
        if self.unit == "batch" or (self.unit == "path" and
                                    time.perf_counter() - self.last_emit >= self.interval):
            self._progress()

    def _frame_done(self, frame, paths, seconds, d_range) -> None:
        main = next((p for p in paths if p.endswith(".exr") and not p.endswith(".spectral.exr")),
                    paths[0] if paths else None)
        ev = self.exposures.get(frame)
        exposure: dict[str, float | None] = {"exposure": None if ev is None else ev.stops}
        if ev is not None and ev.auto:
            exposure["exposure_metered"] = ev.metered
        self.emit("frame_done", frame=frame, path=main, paths=paths, seconds=round(seconds, 4),
                  fraction=round(self.fraction, 6), frames_done=self.frames_done,
                  frames_total=self.frames_total, **exposure)
        if self.unit != "batch":
            self._progress()

    def _error(self, frame, message, kind) -> None:
        self.emit("error", frame=frame, message=message, kind=kind)
        if frame is not None and self.unit == "frame":
            self._progress()

    def _finished(self, status, seconds, exit_code) -> None:
        self.emit("finish", status=status, exit_code=exit_code, rendered=sorted(self.rendered),
                  failed=sorted(self.failed), seconds=round(seconds, 3))


def default_reporter(show_progress: bool = True, json_progress: bool = False) -> Reporter:
    """The reporter of the CLI's flags: JSON lines, a tqdm bar, or silence."""
    if json_progress:
        return JsonReporter()
    return TqdmReporter() if show_progress else Reporter()


def parse_event(line: str) -> dict[str, Any] | None:
    """One ``--json-progress`` line -> its event dict (None for anything else)."""
    try:
        obj = json.loads(line)
    except (ValueError, TypeError):
        return None
    return obj if isinstance(obj, dict) and "event" in obj else None
