"""Motion from the animation: sample animated world matrices over the scene clock.

The camera or object whose motion source is "ANIMATION" has its animated world location
as its lab worldline on the scene clock ct = c · frame / fps (:class:`.motion.SceneClock`).
This module decides which (sub-)frames to evaluate and turns the samples into shutter
events and worldlines; it never touches ``bpy`` itself: the caller passes
``set_frame(frame, subframe)`` (``RenderEngine.frame_set`` during a render,
``Scene.frame_set`` in the farm export) and ``matrix_of(name)`` (the evaluated object's
world matrix, float64 (4, 4)), so F12 and the farm export sample the same frames.

Samples (all in lab time on the scene clock):

- **objects**: every integer frame from min(frame_start, f) − 1 to max(frame_end, f) + 1,
  then sub-frames where the chord velocity jumps by more than ``REFINE_DBETA`` (|Δβ|),
  halving up to ``MAX_REFINE`` times (:func:`.motion.refine_frames`). The worldline is
  piecewise-linear between the samples and continues at its end segments' velocities.
- **camera**: the frame f itself (its shutter event is (ct_f, x(f))), f ± ½ for its β
  (the central difference: the F-curve's derivative to second order), and the integer
  frames from frame_start to f for its proper time.
- The **rest pose** of a moving object is its rotation and scale at frame_start; an object
  whose rotation or scale is animated is warned about (once) and keeps that pose.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from . import motion

SetFrame = Callable[[int, float], None]
MatrixOf = Callable[[str], np.ndarray]


@dataclass
class Samples:
    """World matrices of named objects at (sub-)frames: {name: {frame: (4, 4)}}."""

    by_name: dict[str, dict[float, np.ndarray]]

    def missing(self, names: Iterable[str], frames: Iterable[float]) -> list[float]:
        frames = list(frames)
        need = set()
        for n in names:
            have = self.by_name.get(n, {})
            need.update(f for f in frames if f not in have)
        return sorted(need)

    def positions(self, name: str, frames: Sequence[float]) -> np.ndarray:
        return np.array([self.by_name[name][f][:3, 3] for f in frames], np.float64)


def evaluate(samples: Samples, names: Sequence[str], frames: Iterable[float],
             set_frame: SetFrame, matrix_of: MatrixOf) -> None:
    """Evaluate the frames the samples lack (one ``set_frame`` per frame for all names)."""
    for f in samples.missing(names, frames):
        whole = int(np.floor(f))
        set_frame(whole, float(f - whole))
        for n in names:
            samples.by_name.setdefault(n, {})[f] = np.array(matrix_of(n), np.float64)


def object_frames(frame_start: int, frame_end: int, frame: int) -> list[float]:
    """The integer frames an object's worldline is sampled at (see the module docstring)."""
    return [float(f) for f in range(min(frame_start, frame) - 1, max(frame_end, frame) + 2)]


@dataclass(frozen=True)
class ObjectMotion:
    """An animated object's worldline (core ``Worldline``), its pivot now and rest pose."""

    worldline: object
    pivot: np.ndarray  # (3,) its world location at the rendered frame
    rest_linear: np.ndarray  # (3, 3) rotation and scale at frame_start
    posed: bool  # its rotation or scale changes over the samples (warned)


def object_motions(samples: Samples, names: Sequence[str], clock: motion.SceneClock,
                   frame_start: int, frame_end: int, frame: int, set_frame: SetFrame,
                   matrix_of: MatrixOf) -> dict[str, ObjectMotion]:
    """Worldlines of the named objects (those that never move are left out)."""
    frames = object_frames(frame_start, frame_end, frame)
    evaluate(samples, names, frames, set_frame, matrix_of)
    out = {}
    for n in names:
        fs = list(frames)
        for _ in range(motion.MAX_REFINE):
            extra = motion.refine_frames(fs, samples.positions(n, fs), clock)
            extra = [f for f in extra if f not in fs]
            if not extra:
                break
            evaluate(samples, [n], extra, set_frame, matrix_of)
            fs = sorted(set(fs) | set(extra))
        wl = motion.object_worldline(clock, fs, samples.positions(n, fs), f"object '{n}'")
        if wl is None:
            continue
        mats = samples.by_name[n]
        rest = mats[float(frame_start)][:3, :3] if float(frame_start) in mats \
            else mats[fs[0]][:3, :3]
        posed = any(not np.allclose(mats[f][:3, :3], rest, rtol=1e-6, atol=1e-9) for f in fs)
        out[n] = ObjectMotion(wl, mats[float(frame)][:3, 3].copy(), rest.copy(), posed)
    return out


def camera_frames(frame_start: int, frame: int) -> list[float]:
    """The frames the camera is sampled at for ``frame`` (module docstring)."""
    h = motion.VELOCITY_HALF_STEP
    ints = range(min(frame_start, frame), max(frame_start, frame) + 1)
    return sorted({float(f) for f in ints} | {frame - h, frame + h})


def camera_event(samples: Samples, name: str, clock: motion.SceneClock, frame_start: int,
                 frame: int, set_frame: SetFrame, matrix_of: MatrixOf):
    """The shutter event of ``frame`` of a camera whose motion is its animation, and its
    world matrix at the frame."""
    frames = camera_frames(frame_start, frame)
    evaluate(samples, [name], frames, set_frame, matrix_of)
    h = motion.VELOCITY_HALF_STEP
    ints = [float(f) for f in range(min(frame_start, frame), max(frame_start, frame) + 1)]
    tau = motion.proper_time(clock, ints, samples.positions(name, ints), frame_start, frame) \
        if len(ints) > 1 else 0.0
    pos = samples.positions(name, [float(frame), frame - h, frame + h])
    event = motion.animation_event(clock, frame, pos[0], pos[1], pos[2], tau,
                                   who=f"camera '{name}'")
    return event, samples.by_name[name][float(frame)]
