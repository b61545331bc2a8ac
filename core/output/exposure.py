"""Automatic exposure: metering a frame, and smoothing the exposure over an animation.

Job key ``output.exposure``: a number of stops is applied as given; ``"auto"`` meters
every frame (:func:`meter`) and smooths the readings over the animation
(:func:`smooth`, :class:`ExposureChain`). Relativity needs it: the searchlight effect
(D^5) and the Doppler shift change the brightness by orders of magnitude over a fly-by
(head-on at β = 0.5 the view is white at exposure 0, looking back at β = 0.9 it is black).

Like a number, the exposure is applied to the PNG only (``png = sRGB(rgb · 2^stops)``,
:func:`.imageio.png_codes`); the EXR keeps the linear, unexposed, scene-referred pixels.
Each frame's files record ``relray:exposure`` (the stops applied to the PNG) and, with
``"auto"``, ``relray:exposure_metered`` (this frame's reading, ``"none"`` for a frame with
nothing to meter).

Metering (:func:`meter`)
------------------------
The convention of Reinhard, Stark, Shirley and Ferwerda (2002), "Photographic Tone
Reproduction for Digital Images", ACM Transactions on Graphics 21(3) (SIGGRAPH 2002),
eq. 1 and 2: the log-average (geometric mean) luminance L̄ of the image is scaled onto
the *key value* a = 0.18 (middle grey) by the factor a / L̄. In stops::

    L_p = 0.2126 R_p + 0.7152 G_p + 0.0722 B_p        (Rec.709 luminance, linear RGB)
    P   = { p : R_p, G_p, B_p finite and L_p > 0 },
          less its TRIM_FRACTION darkest and TRIM_FRACTION brightest pixels (by rank)
    m   = log2(a) - (1/|P|) · Σ_{p in P} log2 L_p
    m   is clamped to [-MAX_EXPOSURE_STOPS, +MAX_EXPOSURE_STOPS]

so that a uniform image of luminance L meters log2(0.18 / L), and the image × 2^k
meters m - k exactly (ranks do not change under scaling). Where Reinhard adds a small δ
to every luminance (log 0), pixels with L <= 0 are left out instead: a black pixel says
nothing about how bright the rest is (at β = 0.9 looking back most of the visible band
is black), and δ would break the scaling law. Every pixel that shows light counts, the
scene's (alpha > 0) and the sky's when the camera sees it (the PNG shows both); alpha is
not a weight. The trim keeps a few fireflies or a lamp from darkening the frame. A frame
with no such pixel (black, or all NaN) has no reading: :func:`meter` returns None.

Smoothing over an animation (:func:`smooth`)
--------------------------------------------
An exponential moving average in stops, causal, over the frames of the run's range in
frame order (``motion.frames``, or the ``--frames`` sub-range), with the time constant
τ = :data:`TIME_CONSTANT_FRAMES` frames::

    α   = 1 - exp(-1/τ)
    e_0 = m_0                          (the range's first frame; 0 when it has no reading)
    e_n = e_(n-1) + α (m_n - e_(n-1))  (e_n = e_(n-1) when frame n has no reading)

The stops applied to frame n are e_n. A step of the meter is half caught up after
τ·ln 2 ≈ 1.4 frames and to 5% after 3τ = 6 frames; noise and a bright object that pops
into view are damped by α.

Determinism and resume: e_n depends only on the readings of the range's frames up to n,
and a reading depends only on the frame's pixels, which the seed fixes. The reading is
recorded in the frame's files (``relray:exposure_metered``, exact ``repr``), so a
resumed run reads the readings of the frames already done back from their metadata
instead of rendering them again, and computes the same e_n as an uninterrupted run
(:class:`ExposureChain`, :func:`.frame_files.exposure_chain`). A range is its own
animation: ``--frames 10-20`` starts its average at frame 10. The frames must be written
in order: a Dask farm renders them side by side, and its workers hand the resolved
images back to the client, which writes them in frame order through one chain, so the
farm's exposures equal a local run's (:class:`.farm._FramesInOrder`).

For the Blender add-on (per frame, frames in order): ``stops = meter(rgba)`` then
``applied = smooth(previous_applied, stops)`` (``previous_applied`` None on the first
frame), and ``2 ** applied`` is the factor; or :func:`frame_exposure` for both.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..scene.description import AUTO_EXPOSURE, MAX_EXPOSURE_STOPS

__all__ = ["AUTO_EXPOSURE", "KEY_VALUE", "TRIM_FRACTION", "TIME_CONSTANT_FRAMES",
           "MAX_EXPOSURE_STOPS", "REC709_LUMINANCE", "luminance", "log_average_luminance",
           "meter", "smoothing_weight", "smooth", "smooth_series", "frame_exposure",
           "FrameExposure", "ExposureChain", "METERED_KEY", "APPLIED_KEY", "parse_metered"]

KEY_VALUE = 0.18
"""Reinhard et al.'s key value a: the log-average luminance is mapped onto middle grey."""
TRIM_FRACTION = 0.01
"""Fraction of the metered pixels left out at each end (by luminance rank)."""
TIME_CONSTANT_FRAMES = 2.0
"""τ of the exponential moving average, in frames."""
METERED_KEY = "relray:exposure_metered"
"""Metadata key of a frame's meter reading (auto exposure)."""
APPLIED_KEY = "relray:exposure"
"""Metadata key of the stops applied to the frame's PNG."""
REC709_LUMINANCE = (0.2126, 0.7152, 0.0722)
"""Y of linear Rec.709 R, G, B (ITU-R BT.709, D65 white): the PNG's luminance."""


def luminance(rgba: np.ndarray) -> np.ndarray:
    """(h, w) float64 Rec.709 luminance of a linear (h, w, 3|4) image (alpha ignored)."""
    rgb = np.asarray(rgba)
    if rgb.ndim != 3 or rgb.shape[2] not in (3, 4):
        raise ValueError(f"image has shape {rgb.shape}, want (h, w, 3 or 4)")
    rgb = rgb[..., :3].astype(np.float64)
    with np.errstate(invalid="ignore", over="ignore"):
        return rgb @ np.asarray(REC709_LUMINANCE, np.float64)


def _metered_logs(rgba: np.ndarray, trim: float) -> np.ndarray:
    """Sorted log2 L of the pixels :func:`meter` uses (see the module docstring)."""
    if not 0.0 <= trim < 0.5:
        raise ValueError(f"trim must lie in [0, 0.5), got {trim}")
    rgb = np.asarray(rgba)
    L = luminance(rgb)
    ok = np.all(np.isfinite(rgb[..., :3]), axis=-1) & np.isfinite(L) & (L > 0.0)
    logs = np.sort(np.log2(L[ok]))
    cut = int(math.floor(trim * logs.size))
    return logs[cut:logs.size - cut] if logs.size - 2 * cut > 0 else logs


def log_average_luminance(rgba: np.ndarray, trim: float = TRIM_FRACTION) -> float | None:
    """L̄ = 2^mean(log2 L) over the metered pixels (Reinhard et al. 2002, eq. 1 without
    δ); None when no pixel shows light."""
    logs = _metered_logs(rgba, trim)
    return float(2.0 ** float(np.mean(logs))) if logs.size else None


def meter(rgba: np.ndarray, key: float = KEY_VALUE, trim: float = TRIM_FRACTION
          ) -> float | None:
    """The exposure in stops that puts the frame's log-average luminance on ``key``.

    ``m = log2(key) - mean(log2 L)`` over the pixels with finite RGB and L > 0, less the
    ``trim`` fraction at each end, clamped to ±:data:`MAX_EXPOSURE_STOPS`; None when no
    pixel shows light (black or non-finite). ``rgba``: linear Rec.709, (h, w, 3|4).
    """
    if not (math.isfinite(key) and key > 0.0):
        raise ValueError(f"key must be finite and > 0, got {key}")
    logs = _metered_logs(rgba, trim)
    if not logs.size:
        return None
    m = math.log2(key) - float(np.mean(logs))
    return min(MAX_EXPOSURE_STOPS, max(-MAX_EXPOSURE_STOPS, m))


def smoothing_weight(tau: float = TIME_CONSTANT_FRAMES) -> float:
    """α = 1 - exp(-1/τ) of the moving average (τ in frames; τ = 0: no smoothing)."""
    if not (math.isfinite(tau) and tau >= 0.0):
        raise ValueError(f"time constant must be finite and >= 0 frames, got {tau}")
    return 1.0 if tau == 0.0 else -math.expm1(-1.0 / tau)


def smooth(previous: float | None, metered: float | None,
           tau: float = TIME_CONSTANT_FRAMES) -> float:
    """One step of the moving average: the stops applied to a frame.

    ``previous``: the stops applied to the frame before (None for the range's first
    frame); ``metered``: this frame's :func:`meter` reading (None: nothing to meter).
    ``e = previous + α (metered - previous)``; the reading itself on the first frame;
    ``previous`` (0 on the first frame) when there is no reading.
    """
    if metered is None:
        return 0.0 if previous is None else float(previous)
    if previous is None:
        return float(metered)
    return float(previous) + smoothing_weight(tau) * (float(metered) - float(previous))


def smooth_series(metered: Iterable[float | None], tau: float = TIME_CONSTANT_FRAMES
                  ) -> list[float]:
    """:func:`smooth` over a range's readings in frame order: the stops of each frame."""
    out: list[float] = []
    previous: float | None = None
    for m in metered:
        previous = smooth(previous, m, tau)
        out.append(previous)
    return out


@dataclass(frozen=True)
class FrameExposure:
    """The exposure of one written frame: ``stops`` applied to the PNG; with ``auto``,
    ``metered`` is the frame's own reading (None: nothing to meter)."""

    stops: float
    metered: float | None = None
    auto: bool = False

    def metadata(self) -> dict[str, str]:
        """``relray:exposure`` and, when auto, ``relray:exposure_metered`` (exact repr)."""
        meta = {APPLIED_KEY: repr(float(self.stops))}
        if self.auto:
            meta[METERED_KEY] = "none" if self.metered is None else repr(float(self.metered))
        return meta

    def text(self) -> str:
        """For the progress line: ``EV +1.25`` or ``EV auto +1.25 (meter +2.5)``."""
        if not self.auto:
            return f"EV {self.stops:+.3g}"
        reading = "none" if self.metered is None else f"{self.metered:+.3g}"
        return f"EV auto {self.stops:+.3g} (meter {reading})"


def parse_metered(text: str | None) -> float | None:
    """A recorded ``relray:exposure_metered`` back as a reading; None for "none", a
    missing key or anything that is not a finite number."""
    try:
        value = float(text) if text is not None else math.nan
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def frame_exposure(rgba: np.ndarray, previous: float | None,
                   tau: float = TIME_CONSTANT_FRAMES) -> FrameExposure:
    """Meter ``rgba`` and smooth: the next frame's :class:`FrameExposure` (auto), given
    the stops applied to the frame before (None for the first frame). The per-frame
    call for callers that render frames in order (the Blender add-on)."""
    m = meter(rgba)
    return FrameExposure(smooth(previous, m, tau), m, auto=True)


@dataclass
class ExposureChain:
    """The moving average of one run, over ``frames`` (the range, in frame order).

    Readings come from :meth:`record` (frames metered in this process) or, for frames
    of the range before them that this process did not render (done in an earlier run),
    from ``lookup(frame)`` (their recorded reading; None when there is none). Frames
    must be asked for in order: :meth:`stops` of frame n needs the readings of every
    frame of the range before n.
    """

    frames: Sequence[int]
    lookup: Callable[[int], float | None] = lambda _frame: None
    tau: float = TIME_CONSTANT_FRAMES
    readings: dict[int, float | None] = field(default_factory=dict)
    _index: dict[int, int] = field(default_factory=dict, repr=False)
    _done: int = 0  # frames[:_done] are folded into _state
    _state: float | None = None

    def __post_init__(self) -> None:
        self.frames = list(self.frames)
        self._index = {f: i for i, f in enumerate(self.frames)}
        smoothing_weight(self.tau)  # a bad tau fails here

    def record(self, frame: int, rgba: np.ndarray) -> FrameExposure:
        """Meter ``frame``'s image and return its exposure (the average up to it)."""
        self.readings[frame] = meter(rgba)
        return FrameExposure(self.stops(frame), self.readings[frame], auto=True)

    def stops(self, frame: int) -> float:
        """The stops applied to ``frame``: :func:`smooth` over the range up to it."""
        if frame not in self._index:
            raise ValueError(f"frame {frame} is not in the range {self.frames[:1]}..."
                             f"{self.frames[-1:]}")
        target = self._index[frame]
        if target < self._done - 1:  # asked again for an earlier frame: start over
            self._done, self._state = 0, None
        while self._done <= target:
            f = self.frames[self._done]
            if f not in self.readings:
                self.readings[f] = self.lookup(f)
            self._state = smooth(self._state, self.readings[f], self.tau)
            self._done += 1
        assert self._state is not None
        return self._state
