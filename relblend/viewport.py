"""The Rendered viewport: progressive relativistic renders in a worker thread.

No ``bpy`` here (the engine's ``view_update``/``view_draw`` are thin, in
:mod:`.engine`): a :class:`ViewportSession` takes what one view needs (a prepared core
scene, render settings, the view's camera and shutter event) as a :class:`ViewState`,
and renders it progressively in a daemon thread:

1. a **preview** at 1/:data:`PREVIEW_DIVISOR` of the view's size, 1 sample per pixel
   (the first image within about a second once the kernels are loaded);
2. then the full size, in sample batches that double (1, 1, 2, 4, ...) up to the
   viewport's sample count, merged into one film (``Film.merge``: every random number is
   keyed by the sample index, so the batches add up to the one-pass image).

A new state (any change: geometry, materials, camera, β, size, settings) cancels the
batch in flight (the core checks the flag between wavefronts) and starts over; the same
state leaves it alone. :meth:`ViewportSession.latest` hands the newest image to the draw
call (linear Rec.709 RGBA, row 0 at the bottom, as Blender's textures are), never
waiting for the worker.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

#: The preview pass renders at 1/PREVIEW_DIVISOR of the view's width and height.
PREVIEW_DIVISOR = 4


@dataclass(frozen=True, eq=False)
class ViewState:
    """Everything a view's image depends on; ``key`` identifies it (equal keys: same
    image). ``prep``: ``core.render.frames.PreparedScene``; ``settings``: the core's
    RenderSettings at the view's full size (``spp``: the viewport's sample count);
    ``camera``: core CameraSettings; ``event``: the shutter event; ``aovs``: none."""

    key: str
    prep: object
    settings: object
    camera: object
    event: object
    frame: int = 1


@dataclass
class ViewImage:
    """The newest image of a view: rgba (h, w, 4) float32, row 0 at the bottom;
    ``samples`` per pixel so far; ``done`` when the sample count is reached."""

    rgba: np.ndarray
    samples: int
    done: bool
    key: str


def batches(spp: int) -> list[tuple[int, int]]:
    """Sample ranges of the full-size passes: [0, 1), [1, 2), [2, 4), [4, 8), ... < spp."""
    out, lo, size = [], 0, 1
    while lo < spp:
        hi = min(spp, lo + size)
        out.append((lo, hi))
        size = max(1, hi)  # the next batch doubles the count so far
        lo = hi
    return out


class ViewportSession:
    """Progressive renders of one 3D view (see the module docstring)."""

    def __init__(self, make_renderer: Callable | None = None):
        self._lock = threading.Lock()
        self._image: ViewImage | None = None
        self._state: ViewState | None = None
        self._cancel = threading.Event()
        self._thread: threading.Thread | None = None
        self._make_renderer = make_renderer or _core_renderer
        self.error: BaseException | None = None

    # ------------------------------------------------------------------ control
    def show(self, state: ViewState) -> bool:
        """Render ``state`` unless it is the one in progress; True when it (re)started."""
        with self._lock:
            if self._state is not None and self._state.key == state.key:
                return False
        self.stop()
        with self._lock:
            self._state = state
            self._cancel = threading.Event()
            self.error = None
            cancel = self._cancel
        self._thread = threading.Thread(target=self._work, args=(state, cancel),
                                        name="relray-viewport", daemon=True)
        self._thread.start()
        return True

    def stop(self) -> None:
        """Cancel the render in flight and wait for the worker to end."""
        self._cancel.set()
        if self._thread is not None:
            self._thread.join()
            self._thread = None
        with self._lock:
            self._state = None

    def latest(self) -> ViewImage | None:
        with self._lock:
            return self._image

    def busy(self) -> bool:
        return self._thread is not None and self._thread.is_alive()

    # ------------------------------------------------------------------- worker
    def _publish(self, state: ViewState, rgba: np.ndarray, samples: int, done: bool,
                 cancel: threading.Event) -> None:
        with self._lock:
            if not cancel.is_set():
                self._image = ViewImage(np.ascontiguousarray(rgba[::-1], np.float32),
                                        samples, done, state.key)

    def _work(self, state: ViewState, cancel: threading.Event) -> None:
        from ..core.render.frames import RenderCancelled

        s = state.settings
        try:
            w, h = (max(1, s.width // PREVIEW_DIVISOR), max(1, s.height // PREVIEW_DIVISOR))
            if (w, h) != (s.width, s.height):
                small = self._make_renderer(state, replace(s, width=w, height=h, spp=1))
                film, _ = small.render(state.event, state.frame, cancel=cancel.is_set)
                rgba = film.resolve(small.to_rgb).rgba
                self._publish(state, upscale(rgba, s.width, s.height), 0, False, cancel)
            full = self._make_renderer(state, s)
            total = None
            for lo, hi in batches(s.spp):
                film, _ = full.render(state.event, state.frame, cancel=cancel.is_set,
                                      samples=(lo, hi))
                if total is None:
                    total = film
                else:
                    total.merge(film)
                self._publish(state, total.resolve(full.to_rgb).rgba, hi, hi >= s.spp,
                              cancel)
        except RenderCancelled:
            return
        except BaseException as e:  # noqa: BLE001 - shown by the draw call
            self.error = e


def upscale(rgba: np.ndarray, width: int, height: int) -> np.ndarray:
    """Nearest-neighbour enlargement of a preview to the view's size."""
    h, w = rgba.shape[:2]
    rows = np.minimum((np.arange(height) * h) // height, h - 1)
    cols = np.minimum((np.arange(width) * w) // width, w - 1)
    return rgba[rows][:, cols]


def _core_renderer(state: ViewState, settings):
    from ..core.render.camera import PinholeCamera
    from ..core.render.frames import FrameRenderer

    return FrameRenderer(state.prep, settings,
                         PinholeCamera.from_settings(state.camera, settings.width,
                                                     settings.height))
