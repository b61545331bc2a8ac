"""The "Relativistic" render engine: hands the evaluated scene to the core.

One frame, in order:

1. **Motion** (:mod:`.motion`): the camera's lab β of this frame (a clear error naming
   the frame when |β| >= 1) and its shutter event. In worldline mode the β of every
   frame from the scene's start frame on is needed: the engine evaluates earlier
   frames with ``RenderEngine.frame_set`` (so keyframes, F-curve modifiers, drivers,
   parents and constraints all count) and keeps them for the rest of the render job.
2. **Export** (:mod:`.export`): the depsgraph at this frame → a core ``Scene``.
3. **Prepare**: ``core.render.prepare`` (BVH, spectral tables, lights); reused while the
   exported scene stays byte-for-byte the same (a static scene in an animation).
4. **Render**: ``core.render.FrameRenderer.render`` runs in a worker thread; this thread
   polls ``test_break`` every 0.1 s (the core checks the cancel flag between wavefronts),
   and shows progress and a stats line: frame, spp, γ, the D range of the view.
5. **Result**: Combined (RGBA), Depth (Z), Doppler (D) and LabTime (T) passes, flipped
   to Blender's bottom-up rows. Blender then applies its view transform and writes the
   output format. With a transparent film, pixels no primary ray hit are transparent
   black; otherwise alpha is 1.

User errors (|β| >= 1, no camera, an orthographic camera, ...) are reported with
``report({'ERROR'}, ...)``: that stops the render (and an animation at that frame) and
makes ``bpy.ops.render.render`` raise ``RuntimeError`` with the message.
"""

from __future__ import annotations

import hashlib
import os
import threading
import time
import weakref
from dataclasses import dataclass, replace

import bpy
import numpy as np

#: Passes: name -> (channels, channel ids, type, the core's AOV or None for Combined).
PASSES = {
    "Combined": (4, "RGBA", "COLOR", None),
    "Depth": (1, "Z", "VALUE", "depth"),
    "Doppler": (1, "D", "VALUE", "doppler"),
    "LabTime": (1, "T", "VALUE", "lab_time"),
    # Cycles' denoising data, for the compositor's Denoise node (OpenImageDenoise)
    "Denoising Albedo": (3, "RGB", "COLOR", "albedo"),
    "Denoising Normal": (3, "XYZ", "VECTOR", "normal"),
}
#: Seconds between test_break / progress polls while the core renders.
POLL_SECONDS = 0.1
#: Polled together with ``test_break``: a script (or a test) can stop a render from
#: Python, which cannot press Esc in background mode. None, or a callable -> bool.
SCRIPT_CANCEL = None

# β (lab) of already evaluated frames, per render job: {(scene, camera): {frame: β}},
# plus the worldline clock's inputs; cleared when a render job starts or ends.
_HISTORY: dict[tuple[str, str], dict[int, np.ndarray]] = {}
_CLOCK: dict[tuple[str, str], tuple[float, float]] = {}
# The warnings already reported in this render job.
_WARNED: set[str] = set()
# The viewport's limits already reported (once per object and session).
_VIEW_WARNED: set[str] = set()
# The stops applied to the last frame of this render job, per scene (auto exposure).
_EXPOSURE: dict[str, float] = {}
# World matrices sampled for motion from the animation, per render job and scene.
_SAMPLES: dict[str, object] = {}
# The last prepared scene: (content hash, PreparedScene).
_PREPARED: list[tuple[str, object]] = []

#: The last frames rendered in this Blender session, by frame number (at most
#: :data:`RESULTS_KEPT`, default the last one only: images are big): the core's resolved
#: image (row 0 = top), its AOVs, the shutter event and timings. For tests and scripts;
#: Blender's own result is the render result.
RESULTS: dict[int, dict] = {}
RESULTS_KEPT = 1


@bpy.app.handlers.persistent
def clear_caches(*_args) -> None:
    """Forget the motion history and the prepared scene (render job boundaries)."""
    _HISTORY.clear()
    _CLOCK.clear()
    _SAMPLES.clear()
    _EXPOSURE.clear()
    _WARNED.clear()


@bpy.app.handlers.persistent
def passes_into_file(scene, *_args) -> None:
    """After Blender writes a frame (``render_write``): when the output is a multilayer
    EXR without this engine's passes (Blender 5.0 writes only Combined there, for every
    engine), add Depth, Doppler and LabTime as ``<view layer>.<Pass>.<channel>``."""
    if scene.render.engine != RelrayRenderEngine.bl_idname:
        return
    settings = scene.render.image_settings
    if settings.file_format != "OPEN_EXR_MULTILAYER":
        return
    kept = RESULTS.get(scene.frame_current)
    if not kept or not kept.get("planes"):
        return
    path = written_file(scene, kept["started"])
    if path is None:
        print("relray: warning: the written EXR was not found; its passes are not added",
              flush=True)
        return
    from ..core.output.imageio import add_exr_channels

    add_exr_channels(path, kept["planes"])


def written_file(scene, since: float):
    """The file Blender has just written for the current frame (animation frames carry the
    frame number, stills not), modified after ``since`` (a time.time())."""
    from pathlib import Path

    frame_path = Path(scene.render.frame_path(frame=scene.frame_current))
    still = Path(bpy.path.abspath(scene.render.filepath))
    if scene.render.use_file_extension and still.suffix.lower() != ".exr":
        still = still.with_name(still.name + ".exr")
    found = [p for p in (frame_path, still) if p.is_file() and p.stat().st_mtime >= since - 1]
    return max(found, key=lambda p: p.stat().st_mtime) if found else None


def free_prepared() -> None:
    _PREPARED.clear()


class RenderFailed(Exception):  # noqa: N818 - a signal to stop, shown as is
    """A user error that stops the render; the message is shown as is."""


@dataclass
class FrameSetup:
    """Everything the core needs for one frame."""

    frame: int
    event: object  # core.relativity.ShutterEvent
    exported: object  # export.ExportedScene
    gamma: float


class RelrayRenderEngine(bpy.types.RenderEngine):
    """Blender's entry point: F12, animations, ``blender -b file -E RELRAY -f 1`` / ``-a``."""

    bl_idname = "RELRAY"
    bl_label = "Relativistic"
    bl_use_preview = False
    bl_use_postprocess = True
    bl_use_eevee_viewport = True
    bl_use_shading_nodes_custom = False

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.viewport = None  # a viewport.ViewportSession, made on the first view_draw
        self.view_error: str | None = None
        self.view_dirty = True
        self.view_scene = None  # view_scene(): the exported and prepared scene

    def __del__(self):
        try:
            session = self.viewport
        except (ReferenceError, AttributeError):  # Blender freed the engine first
            return
        if session is not None:
            session.stop()

    # ------------------------------------------------------------------ viewport
    def view_update(self, context, depsgraph):
        """The scene changed (geometry, materials, lights, frame, settings): the next
        draw exports it again and restarts the progressive render if it differs."""
        self.view_dirty = True
        self.tag_redraw()

    def view_draw(self, context, depsgraph):
        """Draw the newest progressive image of this view (never waits for the worker);
        while it refines, ask for another redraw."""
        from . import viewport, warmup

        region = context.region
        width, height = max(1, region.width), max(1, region.height)
        if warmup.running():
            self.update_stats("", "relray: compiling render kernels…")
            self.tag_redraw()
            return
        if self.viewport is None:
            self.viewport = viewport.ViewportSession()
            _SESSIONS.add(self.viewport)
        try:
            if self.view_dirty or self.view_scene is None:
                self.view_dirty = False
                self.view_scene = None
                self.view_scene = view_scene(context, depsgraph, width, height)
            state = view_state(context, depsgraph, width, height, self.view_scene)
            self.view_error = None
        except RenderFailed as e:
            self.view_error = str(e)
            state = None
        if state is not None:
            self.viewport.show(state)
        image = self.viewport.latest()
        if self.viewport.error is not None:
            self.view_error = f"{type(self.viewport.error).__name__}: {self.viewport.error}"
        if image is not None and image.rgba.shape[:2] == (height, width):
            draw_image(self, depsgraph.scene, image.rgba,
                       opaque=not depsgraph.scene.render.film_transparent)
        if self.view_error:
            self.update_stats("", f"relray: {self.view_error}")
        elif image is not None:
            self.update_stats("", f"relray: {image.samples} spp"
                                  + ("" if image.done else " …"))
        if image is None or not image.done or image.key != getattr(state, "key", None):
            self.tag_redraw()

    # ------------------------------------------------------------------ passes
    def update_render_passes(self, scene=None, renderlayer=None):
        for name in enabled_passes(renderlayer):
            channels, chan_id, kind, _ = PASSES[name]
            self.register_pass(scene, renderlayer, name, channels, chan_id, kind)

    # ------------------------------------------------------------------ render
    def render(self, depsgraph):
        try:
            self._render(depsgraph)
        except RenderFailed as e:
            self._fail(str(e))
        except ImportError as e:
            self._fail(f"the render core cannot be loaded ({e}); install the "
                       "extension zip built for this platform (it bundles the core's wheels)")

    def _fail(self, message: str) -> None:
        print(f"relray: error: {message}", flush=True)
        self.error_set(message)
        self.report({"ERROR"}, message)

    def _render(self, depsgraph) -> None:
        from ..core.errors import UserError
        from .export import ExportError
        from .motion import MotionError

        try:
            setup = self._setup(depsgraph)
        except (MotionError, ExportError, UserError) as e:
            raise RenderFailed(str(e)) from None
        except InterruptedError:  # cancelled while exporting
            return
        for message in setup.exported.warnings.messages:
            if message in _WARNED:  # once per render job, not once per frame
                continue
            _WARNED.add(message)
            print(f"relray: warning: {message}", flush=True)
            self.report({"WARNING"}, message)
        self._render_frame(depsgraph, setup)

    def _setup(self, depsgraph) -> FrameSetup:
        from . import export, motion

        scene = depsgraph.scene
        frame = scene.frame_current
        cam = self.camera_override or scene.camera
        if cam is None:
            raise export.ExportError("the scene has no active camera")
        cam_eval = cam.evaluated_get(depsgraph)
        if cam_eval.type != "CAMERA":
            raise export.ExportError(f"the active camera '{cam.name}' is not a camera object")
        settings = cam_eval.data.relray
        if settings.motion_source == "ANIMATION":
            return self._setup_animation(depsgraph, cam, frame)
        m = export.matrix_np(cam_eval.matrix_world)
        beta = motion.camera_beta(settings, m, frame)
        position = m[:3, 3].copy()
        if settings.mode == "WORLDLINE":
            betas, clock = self._worldline_history(depsgraph, cam, frame)
            betas[frame] = beta
            event = motion.worldline_event(position, betas, clock, frame)
        else:
            event = motion.snapshot_event(position, beta, float(settings.ct), frame)
        exported = export.export_scene(depsgraph, cam, self.resolution_x, self.resolution_y,
                                       test_break=self.test_break)
        return FrameSetup(frame, event, exported, motion.gamma_or_zero(event.beta))

    def _setup_animation(self, depsgraph, cam, frame: int) -> FrameSetup:
        """A camera whose motion is its animation: its event on the scene clock, and the
        objects that move along their animation (:mod:`.animation`)."""
        from . import animation, export, motion

        scene = depsgraph.scene
        clock = scene_clock(scene)
        names = animated_candidates(depsgraph)
        samples = _SAMPLES.setdefault(scene.name, animation.Samples({}))

        def matrix_of(name: str):
            return export.matrix_np(bpy.data.objects[name].evaluated_get(depsgraph).matrix_world)

        try:
            event, _ = animation.camera_event(samples, cam.name, clock, scene.frame_start,
                                              frame, self.frame_set, matrix_of)
            moving = animation.object_motions(samples, names, clock, scene.frame_start,
                                              scene.frame_end, frame, self.frame_set,
                                              matrix_of)
        finally:
            self.frame_set(frame, 0.0)
        exported = export.export_scene(depsgraph, cam, self.resolution_x, self.resolution_y,
                                       test_break=self.test_break, animated=moving)
        return FrameSetup(frame, event, exported, motion.gamma_or_zero(event.beta))

    def _worldline_history(self, depsgraph, cam, frame: int):
        """β (lab) of frames min(start, frame) .. frame - 1, and the worldline clock."""
        from . import export, motion

        scene = depsgraph.scene
        start = scene.frame_start
        key = (scene.name, cam.name)
        history = _HISTORY.setdefault(key, {})
        needed = [f for f in range(min(start, frame), frame) if f not in history]
        if start == frame:  # this frame's values are the clock's
            settings = cam.evaluated_get(depsgraph).data.relray
            _CLOCK[key] = (float(settings.ct), float(settings.ct_per_frame))
        elif key not in _CLOCK and start not in needed:
            needed.append(start)  # rendering before the start frame: visit it too
        if needed:
            try:
                for f in needed:
                    self.frame_set(f, 0.0)
                    cam_eval = cam.evaluated_get(depsgraph)
                    m = export.matrix_np(cam_eval.matrix_world)
                    settings = cam_eval.data.relray
                    history[f] = motion.camera_beta(settings, m, f)
                    if f == start:
                        _CLOCK[key] = (float(settings.ct), float(settings.ct_per_frame))
            finally:
                self.frame_set(frame, 0.0)
        ct0, per_frame = _CLOCK[key]
        clock = motion.WorldlineClock(start, ct0, per_frame).check()
        return dict(history), clock

    def _render_frame(self, depsgraph, setup: FrameSetup) -> None:
        from ..core.render import frames as core_render
        from ..core.render.camera import PinholeCamera
        from . import warmup
        from .motion import view_doppler_range

        if warmup.running():
            self.update_stats("", f"Frame {setup.frame} | waiting for the render kernels "
                                  "to compile (first use)")
            if not warmup.wait(self.test_break):
                return
        scene = depsgraph.scene
        rs = scene.relray
        ex = setup.exported
        w, h = ex.width, ex.height
        settings = render_settings(scene, w, h)
        layer = depsgraph.view_layer
        passes = enabled_passes(layer)
        aovs = tuple(PASSES[p][3] for p in passes if PASSES[p][3] is not None)
        _STARTED[0] = time.time()
        check_fits(settings, aovs, len(ex.scene.triangles))
        self.update_stats("", f"Frame {setup.frame} | preparing")
        t_prep = time.perf_counter()
        prep = prepared_scene(ex.scene, rs.spectral)
        t_prep = time.perf_counter() - t_prep
        if self.test_break():
            return
        renderer = core_render.FrameRenderer(prep, settings,
                                             PinholeCamera.from_settings(ex.camera, w, h),
                                             aovs=aovs)
        d_lo, d_hi = view_doppler_range(ex.camera, setup.event.beta, w, h)
        head = (f"Frame {setup.frame} | {rs.samples} spp | γ {setup.gamma:.4f} | "
                f"D {d_lo:.3f}–{d_hi:.3f}")
        film, stats = self._run_cancellable(renderer, setup, w * h * rs.samples, head)
        if film is None:
            self.update_stats("", f"{head} | cancelled")
            return
        image = film.resolve(renderer.to_rgb)
        exposure = auto_exposure(scene, image.rgba) if rs.auto_exposure else None
        self._write_result(image, passes, scene.render.film_transparent, w, h, exposure)
        _keep_result(setup, image, stats, t_prep, exposure,
                     file_planes(image, passes, layer.name))
        print(f"relray: frame {setup.frame}: {w}x{h}, {rs.samples} spp, γ {setup.gamma:.6g}, "
              f"D {stats.d_min:.4g}..{stats.d_max:.4g}, β {np.round(setup.event.beta, 6)}, "
              f"ct' {setup.event.tau:.6g}, export {ex.seconds * 1000:.1f} ms, render "
              f"{stats.seconds:.2f} s", flush=True)
        ev = "" if exposure is None else f" | {exposure.text()}"
        self.update_stats("", f"Frame {setup.frame} | {rs.samples} spp | γ {setup.gamma:.4f} | "
                              f"D {stats.d_min:.3f}–{stats.d_max:.3f}{ev} | "
                              f"{stats.seconds:.2f} s")

    def _run_cancellable(self, renderer, setup: FrameSetup, total: int, head: str):
        """Render in a worker thread; poll test_break and show progress from this one."""
        from ..core.render.frames import RenderCancelled

        done = [0]
        lock = threading.Lock()
        stop = threading.Event()
        out: dict[str, object] = {}

        def progress(n: int) -> None:
            with lock:
                done[0] += n

        def work() -> None:
            try:
                out["result"] = renderer.render(setup.event, setup.frame, progress=progress,
                                                cancel=stop.is_set)
            except RenderCancelled:
                out["cancelled"] = True
            except BaseException as e:  # noqa: BLE001 - re-raised in this thread
                out["error"] = e

        worker = threading.Thread(target=work, name="relray-render", daemon=True)
        t0 = time.perf_counter()
        worker.start()
        while worker.is_alive():
            worker.join(POLL_SECONDS)
            if not stop.is_set() and (self.test_break()
                                      or (SCRIPT_CANCEL is not None and SCRIPT_CANCEL())):
                stop.set()
                out["cancel_requested_at"] = time.perf_counter()
            with lock:
                frac = done[0] / total if total else 1.0
            self.update_progress(min(frac, 1.0))
            self.update_stats("", f"{head} | {100 * frac:.0f}% | "
                                  f"{time.perf_counter() - t0:.1f} s")
        if "cancel_requested_at" in out:
            global LAST_CANCEL_LATENCY
            LAST_CANCEL_LATENCY = time.perf_counter() - out["cancel_requested_at"]
        if "error" in out:
            raise out["error"]
        if "result" not in out:
            return None, None
        return out["result"]

    def _write_result(self, image, passes: list[str], transparent: bool, w: int, h: int,
                      exposure=None):
        """Fill the render result; rows flipped (Blender's row 0 is the bottom). With an
        auto ``exposure`` (``core.output.exposure.FrameExposure``) Combined is scaled by
        2^stops and the stops go into the result's metadata."""
        rgba = np.array(image.rgba[::-1], np.float32)
        if exposure is not None:
            rgba[..., :3] *= np.float32(2.0 ** exposure.stops)
        if transparent:
            rgba[rgba[..., 3] <= 0.0, :3] = 0.0
        else:
            rgba[..., 3] = 1.0
        result = self.begin_result(0, 0, w, h)
        layer = result.layers[0]
        layer.passes["Combined"].rect = rgba.reshape(-1, 4)
        for name in passes:
            channels, _, _, aov = PASSES[name]
            if aov is not None:
                plane = np.array(image.aovs[aov][::-1], np.float32).reshape(-1, channels)
                layer.passes[name].rect = plane
        self.end_result(result)
        if exposure is not None:  # on the final result: a partial one's stamps are lost
            final = self.get_result()
            for key, value in exposure.metadata().items():
                final.stamp_data_add_field(key, value)


def file_planes(image, passes: list[str], layer: str) -> dict[str, np.ndarray]:
    """The extra passes as multilayer EXR channels: ``<layer>.<Pass>.<channel>``."""
    out = {}
    for name in passes:
        channels, chan, _, aov = PASSES[name]
        if aov is None:
            continue
        plane = np.asarray(image.aovs[aov]).reshape(*image.aovs[aov].shape[:2], channels)
        for i, c in enumerate(chan):
            out[f"{layer}.{name}.{c}"] = plane[..., i]
    return out


def _keep_result(setup: FrameSetup, image, stats, prepare_seconds: float,
                 exposure=None, planes: dict | None = None) -> None:
    RESULTS.pop(setup.frame, None)  # re-inserted last
    RESULTS[setup.frame] = {
        "frame": setup.frame, "rgba": image.rgba, "aovs": image.aovs, "event": setup.event,
        "gamma": setup.gamma, "d_range": (stats.d_min, stats.d_max),
        "export_seconds": setup.exported.seconds, "prepare_seconds": prepare_seconds,
        "render_seconds": stats.seconds, "paths": stats.paths,
        "warnings": list(setup.exported.warnings.messages),
        "triangles": len(setup.exported.scene.triangles),
        "exposure": exposure, "planes": planes or {}, "started": _STARTED[0],
    }
    while len(RESULTS) > RESULTS_KEPT:
        RESULTS.pop(next(iter(RESULTS)))


#: The viewport sessions alive (stopped when the add-on is disabled).
_SESSIONS: weakref.WeakSet = weakref.WeakSet()
_STARTED = [0.0]  # time.time() when the last frame's render began (written_file)

#: Seconds from a test_break request to the core stopping, in the last cancelled render.
LAST_CANCEL_LATENCY: float | None = None


def render_settings(scene, width: int, height: int):
    """The core's RenderSettings of the scene's Relativistic settings (F12's; the viewport
    replaces the sample count)."""
    from ..core.scene.description import RenderSettings

    rs = scene.relray
    return RenderSettings(width=width, height=height, spp=rs.samples, max_depth=rs.max_depth,
                          clamp=rs.clamp,
                          noise_threshold=(rs.adaptive_threshold
                                           if rs.use_adaptive_sampling else 0.0),
                          seed=rs.seed, spectral=rs.spectral, doppler=rs.doppler,
                          searchlight=rs.searchlight,
                          threads=rs.threads or scene.render.threads)


def region_camera(context, width: int, height: int):
    """The core camera of the 3D view being drawn."""
    from . import export

    rv3d = context.region_data
    try:
        return export.view_camera(np.array(rv3d.view_matrix), np.array(rv3d.window_matrix),
                                  width, height)
    except export.ExportError as e:
        raise RenderFailed(str(e)) from None


def view_scene(context, depsgraph, width: int, height: int):
    """(exported scene, prepared scene, animated objects, content hash) for the viewport:
    exported again only after a ``view_update`` (the engine keeps it while the view just
    moves)."""
    from ..core.errors import UserError
    from . import export, motion

    scene = depsgraph.scene
    cam = region_camera(context, width, height)
    try:
        _, animated = view_motion(depsgraph, False, cam)
        ex = export.export_scene(depsgraph, width=width, height=height, view=cam,
                                 animated=animated)
    except (export.ExportError, motion.MotionError, UserError) as e:
        raise RenderFailed(str(e)) from None
    mode = scene.relray.spectral
    return ex, prepared_scene(ex.scene, mode), animated, scene_hash(ex.scene, mode)


def view_state(context, depsgraph, width: int, height: int, exported):
    """The :class:`.viewport.ViewState` of a 3D view: its own camera (the region's view
    and projection matrices; through the scene camera in camera view, which then brings
    its β and shutter event, else β = 0 at the scene clock's time), the scene of
    :func:`view_scene` and the viewport sample count."""
    from ..core.errors import UserError
    from ..core.physics import relativity
    from . import motion, viewport

    scene = depsgraph.scene
    rs = scene.relray
    ex, prep, _, scene_key = exported
    cam = region_camera(context, width, height)
    try:
        event, _ = view_motion(depsgraph, context.region_data.view_perspective == "CAMERA",
                               cam, objects=False)
    except (motion.MotionError, UserError) as e:
        raise RenderFailed(str(e)) from None
    # the viewport refines by sample batches, which adaptive sampling does not take
    settings = replace(render_settings(scene, width, height), spp=max(1, rs.preview_samples),
                       noise_threshold=0.0)
    key = hashlib.blake2b(repr((scene_key, np.asarray(
        cam.rotation).tobytes(), np.asarray(cam.position).tobytes(), cam.fov, cam.shift,
        relativity.ShutterEvent.four_position(event).tobytes(), event.beta.tobytes(),
        settings)).encode(), digest_size=16).hexdigest()
    return viewport.ViewState(key, prep, settings, cam, event, scene.frame_current)


def view_motion(depsgraph, camera_view: bool, cam, objects: bool = True):
    """(shutter event, animated objects) of the view. In camera view the scene camera's
    motion as F12 has it at this frame (a worldline-mode camera: its β here, as a
    snapshot at this frame's ct'); a free view is at rest. With the camera's motion from
    its animation, the scene clock gives the time, and camera and objects move along
    their F-curves and their parents' (sampled without changing the frame: the viewport
    cannot; constraints are not followed there, warned once per object:
    :class:`FcurveSampler`)."""
    from . import animation, export, motion

    scene = depsgraph.scene
    obj = scene.camera
    settings = obj.data.relray if obj is not None and obj.type == "CAMERA" else None
    position = np.asarray(cam.position, np.float64)
    if settings is None or settings.motion_source != "ANIMATION":
        if not camera_view or settings is None:
            return motion.snapshot_event(position, np.zeros(3), 0.0, scene.frame_current), {}
        m = export.matrix_np(obj.evaluated_get(depsgraph).matrix_world)
        beta = motion.camera_beta(settings, m, scene.frame_current)
        ct = settings.ct + (settings.ct_per_frame * (scene.frame_current - scene.frame_start)
                            if settings.mode == "WORLDLINE" else 0.0)
        return motion.snapshot_event(position, beta, ct, scene.frame_current), {}
    clock = scene_clock(scene)
    names = animated_candidates(depsgraph) if objects else []
    sampler = FcurveSampler(depsgraph, [*names, obj.name])
    for message in sampler.limits.values():
        if message not in _VIEW_WARNED:  # once per object and session
            _VIEW_WARNED.add(message)
            print(f"relray: viewport: warning: {message}", flush=True)
    samples = animation.Samples({})
    frame = scene.frame_current
    moving = animation.object_motions(samples, names, clock, scene.frame_start,
                                      scene.frame_end, frame, sampler.set_frame,
                                      sampler.matrix_of) if names else {}
    if camera_view:
        event, _ = animation.camera_event(samples, obj.name, clock, scene.frame_start, frame,
                                          sampler.set_frame, sampler.matrix_of)
        event = motion.relativity.ShutterEvent(t=event.t, x=position, beta=event.beta,
                                               tau=event.tau)
    else:
        event = motion.relativity.ShutterEvent(t=clock.t(frame), x=position,
                                               beta=np.zeros(3), tau=0.0)
    return event, moving


_TRANSFORM_PATHS = ("location", "rotation_euler", "rotation_quaternion", "scale")


class FcurveSampler:
    """World matrices at other frames from the F-curves of the objects and their parents
    (the viewport cannot change the frame), as Blender composes them for a parent of type
    Object:

        world(f) = world_parent(f) · matrix_parent_inverse · basis(f)
        basis(f) = T(location(f) + Δlocation) · R_Δ · R(rotation(f)) · S(scale(f) ∘ Δscale)

    with each location, rotation (Euler in its order, or quaternion) and scale channel
    from its F-curve where it has one, else its current value. An object whose chain
    (itself or an ancestor) has constraints, a parent that is not an Object (a bone, a
    vertex), an axis-angle rotation or drivers on its transform keeps its current matrix
    at every frame, and is named in :attr:`limits` (the viewport warns once per object;
    F12 and the farm export evaluate the whole scene at every frame and follow them)."""

    def __init__(self, depsgraph, names):
        from . import export

        self.frame = 0.0
        self.base: dict[str, np.ndarray] = {}
        self.chains: dict[str, list] = {}
        self.limits: dict[str, str] = {}
        for name in names:
            obj = bpy.data.objects[name]
            self.base[name] = export.matrix_np(obj.evaluated_get(depsgraph).matrix_world)
            chain, why = _parent_chain(obj)
            if why is not None:
                self.limits[name] = why
            elif any(_transform_curves(o) for o in chain):
                self.chains[name] = chain

    def set_frame(self, frame: int, subframe: float) -> None:
        self.frame = frame + subframe

    def matrix_of(self, name: str) -> np.ndarray:
        chain = self.chains.get(name)
        if chain is None:
            return self.base[name].copy()
        from mathutils import Matrix

        m = Matrix.Identity(4)
        for i, ob in enumerate(chain):  # root first
            if i:
                m = m @ ob.matrix_parent_inverse
            m = m @ _basis_at(ob, self.frame)
        return np.array(m, np.float64)


def _parent_chain(obj) -> tuple[list, str | None]:
    """The object's ancestors and itself, root first; or why the viewport cannot follow
    them by F-curves (None when it can)."""
    chain = []
    ob = obj
    while ob is not None:
        if ob.constraints:
            return [], (f"object '{obj.name}': the constraints of '{ob.name}' are not "
                        "followed in the viewport (F12 follows them)")
        if ob.parent is not None and ob.parent_type != "OBJECT":
            return [], (f"object '{obj.name}': the {ob.parent_type.lower()} parent of "
                        f"'{ob.name}' is not followed in the viewport (F12 follows it)")
        if ob.rotation_mode == "AXIS_ANGLE" and _transform_curves(ob):
            return [], (f"object '{obj.name}': the axis-angle rotation of '{ob.name}' is "
                        "not followed in the viewport (F12 follows it)")
        if _driven(ob):
            return [], (f"object '{obj.name}': the drivers on the transform of '{ob.name}' "
                        "are not followed in the viewport (F12 follows them)")
        chain.append(ob)
        ob = ob.parent
    return chain[::-1], None


def _transform_curves(ob) -> dict[tuple[str, int], object]:
    from . import presets

    return {(fc.data_path, fc.array_index): fc for fc in presets.fcurves_of(ob)
            if fc.data_path in _TRANSFORM_PATHS}


def _driven(ob) -> bool:
    ad = ob.animation_data
    return ad is not None and any(d.data_path in _TRANSFORM_PATHS for d in ad.drivers)


def _basis_at(ob, frame: float):
    """The object's basis matrix (``matrix_basis``) with its F-curves at ``frame``."""
    from mathutils import Euler, Matrix, Quaternion, Vector

    curves = _transform_curves(ob)

    def channel(path: str, current) -> list[float]:
        return [float(curves[(path, i)].evaluate(frame)) if (path, i) in curves
                else float(v) for i, v in enumerate(current)]

    loc = Vector(channel("location", ob.location)) + ob.delta_location
    scale = Vector([a * b for a, b in zip(channel("scale", ob.scale), ob.delta_scale,
                                          strict=True)])
    if ob.rotation_mode == "QUATERNION":
        q = Quaternion(channel("rotation_quaternion", ob.rotation_quaternion)).normalized()
        rot = (ob.delta_rotation_quaternion.normalized() @ q).to_matrix()
    elif ob.rotation_mode == "AXIS_ANGLE":  # not animated (see _parent_chain)
        rot = ob.matrix_basis.to_3x3().normalized()
    else:
        e = Euler(channel("rotation_euler", ob.rotation_euler), ob.rotation_mode)
        delta = Euler(ob.delta_rotation_euler, ob.rotation_mode)
        rot = delta.to_matrix() @ e.to_matrix()
    return Matrix.LocRotScale(loc, rot, scale)


def draw_image(engine, scene, rgba: np.ndarray, opaque: bool = True) -> None:
    """Draw a linear RGBA image over the region through the scene's view transform
    (``bind_display_space_shader``), premultiplied alpha; ``opaque``: alpha 1 (as F12
    without a transparent film), so the background is the world's, not the viewport's."""
    import gpu
    from gpu_extras.presets import draw_texture_2d

    if opaque:
        rgba = rgba.copy()
        rgba[..., 3] = 1.0
    h, w = rgba.shape[:2]
    buffer = gpu.types.Buffer("FLOAT", w * h * 4, np.ascontiguousarray(rgba).ravel())
    texture = gpu.types.GPUTexture((w, h), format="RGBA16F", data=buffer)
    gpu.state.blend_set("ALPHA_PREMULT")
    engine.bind_display_space_shader(scene)
    draw_texture_2d(texture, (0, 0), w, h)
    engine.unbind_display_space_shader()
    gpu.state.blend_set("NONE")


def auto_exposure(scene, rgba: np.ndarray):
    """Meter this frame and smooth over the frames of the render job before it, in order
    (``core.output.exposure.frame_exposure``; a still is metered alone)."""
    from ..core.output import exposure

    fe = exposure.frame_exposure(rgba, _EXPOSURE.get(scene.name))
    _EXPOSURE[scene.name] = fe.stops
    return fe


def check_fits(settings, aovs: tuple[str, ...], triangles: int) -> None:
    """The core's memory check (as ``relray render`` makes it): a render that would not
    fit stops with a RenderFailed, before anything is allocated."""
    from pathlib import Path

    from ..core.errors import UserError
    from ..core.scene.description import OutputSettings
    from ..core.scene.footprint import check_memory

    try:
        check_memory(settings, OutputSettings(Path("."), aovs=aovs),
                     [("the scene's meshes", triangles)], None)
    except UserError as e:
        raise RenderFailed(f"the render would not fit in memory: {e.detail} (Output › "
                           "Resolution, or the passes)") from None


def scene_clock(scene):
    """The scene clock ct = c · frame / fps (:class:`.motion.SceneClock`)."""
    from .motion import SceneClock

    return SceneClock(float(scene.relray.speed_of_light),
                      float(scene.render.fps) / float(scene.render.fps_base))


def animated_candidates(depsgraph) -> list[str]:
    """The rendered objects (not instances) whose motion source is their animation."""
    from .export import GEOMETRY_TYPES

    names = []
    for inst in depsgraph.object_instances:
        obj = inst.object
        if inst.is_instance or not inst.show_self or obj.type not in GEOMETRY_TYPES:
            continue
        orig = obj.original
        settings = getattr(orig, "relray", None)
        if not orig.hide_render and settings is not None \
                and settings.motion_source == "ANIMATION":
            names.append(orig.name)
    return names


def enabled_passes(view_layer) -> list[str]:
    """The passes a view layer asks for (Combined always)."""
    names = ["Combined"]
    if view_layer is None:
        return names
    if view_layer.use_pass_z:
        names.append("Depth")
    settings = getattr(view_layer, "relray", None)
    if settings is None or settings.use_pass_doppler:
        names.append("Doppler")
    if settings is None or settings.use_pass_lab_time:
        names.append("LabTime")
    if settings is not None and settings.use_pass_denoising:
        names += ["Denoising Albedo", "Denoising Normal"]
    return names


def scene_hash(scene, mode: str) -> str:
    """A content hash of an exported core Scene (geometry, materials, lights, sky,
    environment map, stars, and the moving objects' groups: their velocities and
    pivots)."""
    h = hashlib.blake2b(digest_size=16)
    for a in (scene.triangles, scene.normals, scene.material_ids, scene.background,
              scene.tri_group, scene.uvs):
        if a is not None:
            h.update(np.ascontiguousarray(a).tobytes())
    for group in scene.groups:
        for seg in group.segments:
            h.update(np.array([*seg.u, seg.t_ref, *seg.p_ref, seg.t_lo, seg.t_hi]).tobytes())
    if scene.environment is not None:  # the world's Environment Texture
        env = scene.environment
        if env.source:  # its file's path, size and time: no pass over a 2k map's pixels
            h.update(env.source.encode())
        else:
            h.update(np.ascontiguousarray(env.pixels).tobytes())
        h.update(np.array([env.strength, env.rotation_z]).tobytes())
    if scene.stars is not None:  # the world's stars (World › Stars)
        for a in (scene.stars.directions, scene.stars.temperature, scene.stars.omega):
            h.update(np.ascontiguousarray(a).tobytes())
    h.update(repr(scene.materials).encode())
    for m in scene.materials:  # an image saved again under its name renders anew
        for tex in m.textures():
            if tex is not None:
                try:
                    st = os.stat(tex.file)
                    h.update(f"{st.st_size}:{st.st_mtime_ns}".encode())
                except OSError:
                    h.update(b"missing")
    h.update(str(scene.light_triangles).encode())  # which triangles are area lights
    for light in scene.lights:
        h.update(repr(light).encode())
        for a in (light.position, light.direction, light.color):
            h.update(np.ascontiguousarray(a).tobytes())
    h.update(mode.encode())
    return h.hexdigest()


def prepared_scene(scene, mode: str):
    """core.render.prepare, reused while the exported scene is unchanged."""
    from ..core.render import frames as core_render

    key = scene_hash(scene, mode)
    if _PREPARED and _PREPARED[0][0] == key:
        return _PREPARED[0][1]
    prep = core_render.prepare(scene, mode)
    _PREPARED[:] = [(key, prep)]
    return prep


def register() -> None:
    bpy.utils.register_class(RelrayRenderEngine)
    for handlers in (bpy.app.handlers.render_init, bpy.app.handlers.render_complete,
                     bpy.app.handlers.render_cancel):
        if clear_caches not in handlers:
            handlers.append(clear_caches)
    if passes_into_file not in bpy.app.handlers.render_write:
        bpy.app.handlers.render_write.append(passes_into_file)


def unregister() -> None:
    for handlers in (bpy.app.handlers.render_init, bpy.app.handlers.render_complete,
                     bpy.app.handlers.render_cancel):
        while clear_caches in handlers:
            handlers.remove(clear_caches)
    for session in list(_SESSIONS):
        session.stop()
    while passes_into_file in bpy.app.handlers.render_write:
        bpy.app.handlers.render_write.remove(passes_into_file)
    clear_caches()
    free_prepared()
    bpy.utils.unregister_class(RelrayRenderEngine)
