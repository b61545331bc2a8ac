"""The camera's motion: from the Relativity properties to lab β and shutter events.

Pure numpy on plain values; the callers read the (evaluated) Blender data and pass
it in, so everything here is testable without Blender.

Per frame f the camera has a lab velocity β_f (lab axes; from ``beta`` or
``speed`` × ``direction``, turned by the camera's world rotation when the axes are
"CAMERA") and a proper time. The shutter event follows physics.md:

- **snapshot**: ``snapshot_event(position_f, β_f, ct_f)``: t = γ ct', x = position +
  γ β ct', with the camera's own location of frame f and the frame's ct'.
- **worldline**: the camera starts at its own location (its position at ct' = 0) and
  β(τ) is linear in proper time between the integer frames f_start, f_start + 1, …,
  with τ_f = ct'(f_start) + (f - f_start)·ct'_per_frame and β held at β(f_start) for
  τ < τ(f_start). ``core.relativity.worldline_events`` integrates this exactly, as the
  job file's ``keyframes`` (one per frame) do: the farm export therefore renders the
  same events.

A speed of 1 or more (possible with a vector β whose components are each below 1, or
from a driver) is a :class:`MotionError` that names the frame.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..core.physics import relativity
from ..core.render.camera import PinholeCamera
from ..core.scene.description import CameraSettings


class MotionError(ValueError):
    """A user error in the camera's motion; the message names the frame."""


@dataclass(frozen=True)
class VelocitySettings:
    """The Relativity properties of one frame that give β (plain values)."""

    velocity_input: str = "VECTOR"  # "VECTOR" | "SPEED"
    beta: tuple[float, float, float] = (0.0, 0.0, 0.0)
    speed: float = 0.0
    direction: tuple[float, float, float] = (0.0, 0.0, -1.0)
    axes: str = "WORLD"  # "WORLD" | "CAMERA"

    @classmethod
    def from_rna(cls, settings) -> VelocitySettings:
        """Copy the values out of a ``RelrayCameraSettings`` (evaluated or not)."""
        return cls(
            velocity_input=str(settings.velocity_input),
            beta=tuple(float(x) for x in settings.beta),
            speed=float(settings.speed),
            direction=tuple(float(x) for x in settings.direction),
            axes=str(settings.axes),
        )


def beta_local(v: VelocitySettings) -> np.ndarray:
    """β in the settings' own axes, float64 (3,)."""
    if v.velocity_input == "SPEED":
        d = np.asarray(v.direction, np.float64)
        n = float(np.linalg.norm(d))
        if n == 0.0 or v.speed == 0.0:
            return np.zeros(3)
        return (float(v.speed) / n) * d
    return np.asarray(v.beta, np.float64)


def beta_lab(v: VelocitySettings, camera_rotation: np.ndarray) -> np.ndarray:
    """β in lab (world) axes. ``camera_rotation``: (3, 3), columns the camera's axes."""
    b = beta_local(v)
    if v.axes == "CAMERA":
        return np.asarray(camera_rotation, np.float64) @ b
    return b


def check_speed(beta: np.ndarray, frame: int) -> np.ndarray:
    """β unchanged if |β| < 1 and finite, else a MotionError naming the frame."""
    beta = np.asarray(beta, np.float64)
    if not np.all(np.isfinite(beta)):
        raise MotionError(f"frame {frame}: the camera's β = {beta.tolist()} is not finite")
    speed = math.hypot(math.hypot(beta[0], beta[1]), beta[2])
    if speed >= 1.0:
        raise MotionError(
            f"frame {frame}: the camera's |β| = {speed:.6g} is not below 1 (the speed of "
            f"light); check the β keyframes, F-curves and drivers at this frame"
        )
    return beta


def camera_beta(settings, matrix_world: np.ndarray, frame: int | None = None) -> np.ndarray:
    """β in lab axes of a camera object: its Relativity ``settings`` (evaluated RNA or
    :class:`VelocitySettings`), turned by the rotation of ``matrix_world`` (4, 4) when the
    axes are the camera's. With ``frame``, checked below c (:func:`check_speed`)."""
    v = settings if isinstance(settings, VelocitySettings) else VelocitySettings.from_rna(settings)
    beta = beta_lab(v, unit_rotation(np.asarray(matrix_world, np.float64)[:3, :3]))
    return beta if frame is None else check_speed(beta, frame)


def gamma_or_zero(beta: np.ndarray | float) -> float:
    """γ of β (:func:`relativity.gamma`), or 0 where |β| ≥ 1 or β is not finite (a value
    the UI shows as invalid instead of raising)."""
    try:
        return float(relativity.gamma(beta))
    except ValueError:
        return 0.0


def unit_rotation(matrix3: np.ndarray) -> np.ndarray:
    """The proper rotation nearest to a (scaled, possibly sheared) 3×3 matrix."""
    m = np.asarray(matrix3, np.float64)
    u, _, vt = np.linalg.svd(m)
    r = u @ vt
    if np.linalg.det(r) < 0:  # a mirrored camera: keep its axes as they point
        u[:, -1] *= -1.0
        r = u @ vt
    return r


@dataclass(frozen=True)
class WorldlineClock:
    """Proper time of frames in worldline mode: τ_f = ct0 + (f - frame_start)·ct_per_frame."""

    frame_start: int
    ct0: float
    ct_per_frame: float

    def tau(self, frame: int) -> float:
        return self.ct0 + (frame - self.frame_start) * self.ct_per_frame

    def check(self) -> WorldlineClock:
        if not (math.isfinite(self.ct0) and math.isfinite(self.ct_per_frame)):
            raise MotionError("worldline mode: ct' and ct' per frame must be finite")
        if self.ct_per_frame < 0.0:
            raise MotionError("worldline mode: ct' per frame must be >= 0")
        return self


def snapshot_event(position: np.ndarray, beta: np.ndarray, ct: float, frame: int):
    """The snapshot shutter event of one frame."""
    if not math.isfinite(ct):
        raise MotionError(f"frame {frame}: ct' = {ct} is not finite")
    return relativity.snapshot_event(position, check_speed(beta, frame), float(ct))


def worldline_event(position: np.ndarray, betas: Mapping[int, np.ndarray],
                    clock: WorldlineClock, frame: int):
    """The worldline shutter event of ``frame``.

    ``betas`` maps every integer frame from min(frame_start, frame) to ``frame`` to its
    lab β; ``position`` is the camera's lab position at ct' = 0.
    """
    first = min(clock.frame_start, frame)
    keys = []
    for f in range(first, frame + 1):
        if f not in betas:
            raise ValueError(f"worldline: β of frame {f} is missing")
        keys.append((f, check_speed(betas[f], f)))
    events = relativity.worldline_events(
        np.asarray(position, np.float64), (first, frame), clock.tau(first),
        clock.ct_per_frame, keyframes=keys)
    return events[-1]


def affine_fit(frames: Sequence[int], values: Sequence[float],
               tol: float = 1e-9) -> tuple[float, float] | None:
    """(value at frames[0], slope) if ``values`` are affine in ``frames``, else None."""
    f = np.asarray(frames, np.float64)
    v = np.asarray(values, np.float64)
    if len(f) == 1:
        return float(v[0]), 0.0
    slope = (v[-1] - v[0]) / (f[-1] - f[0])
    pred = v[0] + slope * (f - f[0])
    scale = max(1.0, float(np.max(np.abs(v))))
    if np.max(np.abs(pred - v)) > tol * scale:
        return None
    return float(v[0]), float(slope)


def view_doppler_range(camera: CameraSettings, beta: np.ndarray, width: int, height: int,
                       samples: int = 33) -> tuple[float, float]:
    """(min, max) of D over the image: a grid of pixel centres and corners, plus the
    direction of motion when it lies inside the view (where D peaks)."""
    beta = np.asarray(beta, np.float64)
    if not np.any(beta):
        return 1.0, 1.0
    cam = PinholeCamera.from_settings(camera, width, height)
    cols = np.linspace(0.0, width, samples)
    rows = np.linspace(0.0, height, samples)
    c, r = np.meshgrid(cols, rows)
    d_cam = cam.directions_cam(c.ravel(), r.ravel())
    extremes = [d_cam]
    b_hat = beta / np.linalg.norm(beta)
    for sign in (1.0, -1.0):  # is ±β̂ inside the view? (then D is extreme there)
        local = cam.rotation.T @ (sign * b_hat)
        if local[2] < 0:
            x, y = -local[0] / local[2], -local[1] / local[2]
            th = cam.tan_half_fov
            aspect = width / height
            if abs(x) <= th * aspect * 1.0001 and abs(y) <= th * 1.0001:
                extremes.append((sign * b_hat)[None, :])
    d = np.concatenate(extremes)
    D = np.atleast_1d(relativity.doppler_factor(d, beta))
    return float(D.min()), float(D.max())


# ------------------------------------------------------------------ motion from animation
#
# The scene clock (Scene › Relativity › Speed of Light): frame f happens at lab time
# ct_f = c · f / fps (scene units; c in scene units per second, fps = fps / fps_base), so
# frame 0 is lab time 0. A camera or object whose motion source is "ANIMATION" has its
# animated world location x(f) as its lab worldline on this clock.

#: Sub-frame half step of the camera's velocity (frames): β_f is the central difference
#: of the animated location over f ± h, the F-curve's own derivative to O(h²).
VELOCITY_HALF_STEP = 0.5
#: A worldline segment pair whose velocities differ by more than this |Δβ| is refined
#: with sub-frame samples (up to :data:`MAX_REFINE` halvings).
REFINE_DBETA = 0.02
MAX_REFINE = 3


@dataclass(frozen=True)
class SceneClock:
    """ct = c · frame / fps: the lab time of a (sub-)frame, scene units."""

    speed_of_light: float  # scene units per second
    fps: float  # frames per second

    def __post_init__(self) -> None:
        for name, v in (("speed of light", self.speed_of_light), ("frame rate", self.fps)):
            if not (math.isfinite(v) and v > 0.0):
                raise MotionError(f"the scene's {name} must be a positive number, not {v}")

    @property
    def ct_per_frame(self) -> float:
        return self.speed_of_light / self.fps

    def t(self, frame: float) -> float:
        return frame * self.ct_per_frame


def chord_beta(x0: np.ndarray, x1: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """β of the straight worldline segment from (t0, x0) to (t1, x1): Δx / Δ(ct)."""
    return (np.asarray(x1, np.float64) - np.asarray(x0, np.float64)) / (t1 - t0)


def checked_object_speed(beta: np.ndarray, who: str, frame: float) -> np.ndarray:
    """β unchanged if finite and |β| < 1, else a MotionError naming ``who`` and the frame."""
    beta = np.asarray(beta, np.float64)
    if not np.all(np.isfinite(beta)):
        raise MotionError(f"{who}: its animated location is not finite at frame {frame:g}")
    speed = float(np.linalg.norm(beta))
    if speed >= 1.0:
        raise MotionError(
            f"{who}: its animation moves it at {speed:.6g} c at frame {frame:g}, not below "
            "the speed of light; raise Scene › Relativity › Speed of Light or slow the "
            "animation down")
    return beta


def animation_event(clock: SceneClock, frame: int, x: np.ndarray, x_before: np.ndarray,
                    x_after: np.ndarray, tau: float, who: str = "the camera"):
    """The shutter event of ``frame`` for a camera whose motion is its animation.

    Event (ct_f, x(f)) with ct_f = c f / fps; β_f = (x(f + h) − x(f − h)) / (c · 2h / fps),
    h = :data:`VELOCITY_HALF_STEP` (``x_before``, ``x_after``); ``tau`` its proper time."""
    h = VELOCITY_HALF_STEP
    beta = chord_beta(x_before, x_after, clock.t(frame - h), clock.t(frame + h))
    beta = checked_object_speed(beta, who, frame)
    return relativity.ShutterEvent(t=clock.t(frame), x=np.asarray(x, np.float64),
                                   beta=beta, tau=tau)


def proper_time(clock: SceneClock, frames: Sequence[float], positions: np.ndarray,
                frame_start: float, frame: float) -> float:
    """The proper time ct' at ``frame`` along the sampled worldline, 0 at ``frame_start``:
    Σ Δ(ct) / γ over the straight segments between the samples (``frames`` increasing,
    covering both frames)."""
    f = np.asarray(frames, np.float64)
    x = np.asarray(positions, np.float64)
    t = f * clock.ct_per_frame
    beta = np.diff(x, axis=0) / np.diff(t)[:, None]
    dtau = np.diff(t) * np.sqrt(np.maximum(0.0, 1.0 - np.sum(beta * beta, axis=1)))
    tau = np.concatenate(([0.0], np.cumsum(dtau)))
    return float(np.interp(frame, f, tau) - np.interp(frame_start, f, tau))


def refine_frames(frames: Sequence[float], positions: np.ndarray, clock: SceneClock,
                  threshold: float = REFINE_DBETA) -> list[float]:
    """Sub-frames to sample next: the midpoints of both segments around every sample where
    the chord velocity jumps by more than ``threshold`` (|Δβ|), so light-travel time sees
    where a fast, turning object was. Empty when the samples already suffice."""
    f = np.asarray(frames, np.float64)
    x = np.asarray(positions, np.float64)
    if len(f) < 3:
        return []
    beta = np.diff(x, axis=0) / (np.diff(f) * clock.ct_per_frame)[:, None]
    jump = np.linalg.norm(np.diff(beta, axis=0), axis=1)
    new: set[float] = set()
    for k in np.nonzero(jump > threshold)[0]:
        new.add(0.5 * (f[k] + f[k + 1]))
        new.add(0.5 * (f[k + 1] + f[k + 2]))
    return sorted(new)


def object_worldline(clock: SceneClock, frames: Sequence[float], positions: np.ndarray,
                     who: str, tol: float = 1e-12):
    """The core's :class:`Worldline` of an object's pivot from its animated location
    samples (lab time ct = c f / fps), or None when it never moves. Every segment must be
    slower than light (a MotionError names the object and the frame)."""
    from ..core.scene.description import Worldline, frozen

    f = np.asarray(frames, np.float64)
    x = np.asarray(positions, np.float64)
    if not np.all(np.isfinite(x)):
        bad = f[np.nonzero(~np.all(np.isfinite(x), axis=1))[0][0]]
        raise MotionError(f"{who}: its animated location is not finite at frame {bad:g}")
    scale = max(1.0, float(np.max(np.abs(x))))
    if len(f) < 2 or float(np.max(np.abs(x - x[0]))) <= tol * scale:
        return None
    t = clock.t(f)
    for k in range(len(f) - 1):
        checked_object_speed(chord_beta(x[k], x[k + 1], t[k], t[k + 1]), who, f[k])
    return Worldline(t=frozen(t), pivot=frozen(x))
