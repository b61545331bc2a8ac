"""Rendering one frame: from a prepared scene and a shutter event to a film.

``prepare`` turns a :class:`scene.Scene` into what the kernels need (Embree BVH, spectral
tables, light table) once per job; every frame of an animation reuses it.
:class:`FrameRenderer` renders one frame: image tiles are the units of work (pixel
groups of about ``WAVEFRONT`` paths in adaptive sampling's passes, which run over the
whole frame so that the stopping decision sees every pixel); a unit traces its samples
in wavefronts of about ``WAVEFRONT`` paths, each pixel's samples are added in order, so
the result does not depend on the thread count, and worker threads overlap Embree and
the numba kernels, which all release the GIL.

Primary rays start at the shutter event, in float64; before they are handed to Embree
in float32 they are advanced to the scene's bounding sphere, so a camera far from the
scene keeps its precision (the skipped distance is added back to the depth AOV).
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np

from ..physics import relativity, spectrum
from ..scene.description import Job, RenderSettings
from ..scene.geometry import Scene, build_scene
from ..scene.motion import resolve_camera
from ..scene.spectral_model import resolved_job
from . import environment, lane_paths, whole_paths
from .accel import MISS_DISTANCE, Accel, max_distance
from .camera import PinholeCamera
from .film import Film, clamp_samples
from .integrator import (
    KernelScene,
    kernel_scene,
    sensor_values,
    trace,
    triangle_geometry,
    wavefront_buffers,
)
from .lights import LightTable, build_lights
from .materials import SpectralTables, build_tables
from .rest_frames import GroupAccel, MovingScene
from .sampling import path_keys, progressive_offsets
from .starfield import occlusion_test, star_splats
from .textures import (
    TextureTable,
    build_textures,
    coefficient_table,
    lab_spread,
    pixel_spread,
)

WAVEFRONT = 1 << 16
#: The per-chunk arrays of :meth:`FrameRenderer._trace_chunk` (see wavefront_buffers).
CHUNK_BUFFERS = (("pix", 0, np.int64), ("samp", 0, np.int64), ("sensor", 3, np.float64),
                 ("alpha", 0, np.float64), ("lam_weight", 4, np.float64),
                 ("lam", 4, np.float64), ("pdf", 4, np.float64), ("lamu", 4, np.float32),
                 ("w_d", 0, np.float64), ("keys", 0, np.uint64), ("o", 3, np.float32),
                 ("d", 3, np.float32), ("D", 0, np.float64), ("skipped", 0, np.float64),
                 ("u", 0, np.float64))
#: Those of :meth:`FrameRenderer.camera_paths`' ``out``, in its order.
CAMERA_BUFFERS = ("lam", "pdf", "lamu", "w_d", "keys", "o", "d", "D", "skipped", "u")
ESCAPED_DEPTH = 1e10


class CameraPaths(NamedTuple):
    """:meth:`FrameRenderer.camera_paths`: what the integrators start from."""
    keys: np.ndarray      # uint64 (N,) the paths' random-number keys
    o: np.ndarray         # float32 (N, 3) camera ray origins, accelerator coordinates
    d: np.ndarray         # float32 (N, 3) unit lab directions
    D: np.ndarray         # (N,) the camera's Doppler factor ν_camera/ν_lab per ray
    skipped: np.ndarray   # the distance skipped before the origin (far cameras)
    lam: np.ndarray       # (N, 4) hero wavelengths, nm (rgb mode: 0)
    pdf: np.ndarray       # (N, 4) their pdfs
    lamu: np.ndarray      # float32 (N, 4) lab table coordinates
    w_d: np.ndarray       # (N,) the searchlight weight D⁵ (1 without)
    d_min: float
    d_max: float
    nlanes: int           # 4 hero lanes, 3 in the rgb mode


@dataclass
class PreparedScene:
    """A scene ready for the kernels; shared by every frame.

    ``accel`` is the static lab BVH (None when every object moves), ``tracer`` what the
    integrator traces: that BVH, or the :class:`.rest_frames.MovingScene` over it and the
    velocity groups' BVHs. ``origin`` is the lab point of the accelerator coordinates,
    ``radius`` the static scene's bounding sphere about it (inf when objects move: they
    are not bounded over time)."""

    scene: Scene
    accel: Accel | None
    tables: SpectralTables
    lights: LightTable
    kernel: KernelScene
    radius: float
    mode: str
    tracer: Accel | MovingScene | None = None
    origin: np.ndarray | None = None


def _bounding_radius(triangles: np.ndarray, origin: np.ndarray) -> float:
    corners = np.ascontiguousarray(triangles, np.float64).reshape(-1, 3)
    return max_distance(corners, np.asarray(origin, np.float64)) * 1.001 + 1e-9


def prepare(scene: Scene, mode: str, env_nee: bool = True) -> PreparedScene:
    """Build the BVHs (the static scene's and one per velocity group), the spectral tables
    and the light table of ``scene`` (``env_nee`` False: the environment map is no light
    of next-event estimation, reached by BSDF sampling only; for benchmarks).

    The area lights' quads (``scene.light_triangles``, the last static triangles) are in
    no BVH: they are lights, not geometry (as in Cycles), so they block no ray; the kernel
    finds the rays crossing their front itself (``KernelScene.area_tris``, empty when the
    scene has none: then nothing changes). Their triangles stay in the kernel's tables
    (the light table samples them) and inside ``radius``."""
    n_static = scene.n_static
    n_geometry = scene.n_geometry
    tris = scene.triangles
    accel = Accel(tris[:n_geometry]) if n_geometry else None
    if accel is not None:
        origin = accel.origin
    else:
        lo, hi = scene.bounds()
        origin = 0.5 * (lo + hi)
    geoms = [triangle_geometry(tris[:n_static], origin)]
    groups: list[GroupAccel] = []
    extent = accel.extent if accel is not None else 0.0
    first = 0
    for g, group in enumerate(scene.groups, start=1):
        rows = np.flatnonzero(scene.tri_group == g)
        start, stop = int(rows[0]), int(rows[-1]) + 1
        g_accel = Accel(tris[start:stop])
        groups.append(GroupAccel(g_accel, start, group.segments, first))
        first += len(group.segments)
        geoms.append(triangle_geometry(tris[start:stop], g_accel.origin))
        extent = max(extent, g_accel.extent)
    geom = {k: np.concatenate([gm[k] for gm in geoms]) for k in geoms[0]}
    radius = _bounding_radius(scene.lab_triangles()[:n_static] if n_static
                              else scene.lab_triangles(), origin)
    tables = build_tables(list(scene.materials), mode)
    textures = scene_textures(scene, tables, mode)
    env_image = scene.environment
    env_row = (tables.add_emission_row(environment.base_row(mode)) if env_image is not None
               else -1)
    env = environment.kernel_environment(env_image, mode, env_row)
    env_power = environment.power_estimate(env, radius) if env.on and env_nee else 0.0
    lights = build_lights(scene, tables, origin, geom["area"].astype(np.float64), radius,
                          env_power)
    tracer: Accel | MovingScene | None = accel
    segments = None
    if groups:
        tracer = MovingScene(accel, groups, origin)
        segments = tracer.segments.f
        radius = math.inf
    elif accel is None:  # nothing but area lights: every ray escapes (no BVH, no group)
        tracer = MovingScene(None, [], origin)
    emits = tables.mat_emit_row[scene.material_ids[n_geometry:n_static]] >= 0
    area_tris = np.arange(n_geometry, n_static, dtype=np.int32)[emits]
    kscene = kernel_scene(extent, scene.normals, scene.material_ids, tables, lights, geom,
                          segments, area_tris, env, textures)
    return PreparedScene(scene, accel, tables, lights, kscene, radius, mode, tracer, origin)


def scene_textures(scene: Scene, tables: SpectralTables, mode: str) -> TextureTable | None:
    """The scene's :class:`.textures.TextureTable`, None when no material has a texture.
    Emission textures add the D65_ext row to ``tables.emit`` (spectral modes), colour
    textures read the RGB→spectrum table (:func:`..physics.rgb_table.coefficient_table`)."""
    materials = list(scene.materials)
    if not any(m.textured() for m in materials):
        return None
    d65_row = -1
    if mode != "rgb" and any(m.emission_texture is not None for m in materials):
        d65_row = tables.add_emission_row(spectrum.d65_ext())
    coef = None
    if mode == "cie1931" and any(m.base_color_texture is not None
                                 or m.emission_texture is not None for m in materials):
        table = coefficient_table()
        coef = (table.scale, table.data)
    return build_textures(materials, scene.uvs, len(scene.triangles), mode, d65_row, coef)


ADAPTIVE_FIRST_PASS = 64
"""Samples every pixel gets before adaptive sampling may stop it (a power of two).

Fewer give variance estimates that miss rare bright paths, so pixels stop too dark; on
the Cornell box 64 beat 32 in both relative MSE and ΔE00 at equal samples."""


def sample_passes(s_lo: int, s_hi: int, adaptive: bool) -> list[tuple[int, int]]:
    """Sample ranges rendered one after the other.

    Without adaptive sampling, one pass [s_lo, s_hi).  With it (``noise_threshold`` > 0,
    whole frames only, so s_lo = 0), a first pass [0, F), F = ``ADAPTIVE_FIRST_PASS``,
    then passes that double the count, [F, 2F), [2F, 4F), ... (the last one cut at s_hi).
    Every pass is an aligned power-of-two block of sample indices, so the samples a pixel
    keeps when it stops — [0, 2^k F) — are a power-of-two prefix of its Owen-scrambled
    Sobol sequence, a (0, m, 2)-net.  After each pass but the last, every pixel for
    which :meth:`Film.converged` holds (its error and its 3x3 window's mean error at most
    ``noise_threshold``, see core/render/film.py) stops; the others take the next pass.
    """
    if not adaptive:
        return [(s_lo, s_hi)]
    bounds = [s_lo, min(s_hi, s_lo + ADAPTIVE_FIRST_PASS)]
    while bounds[-1] < s_hi:
        bounds.append(min(s_hi, 2 * bounds[-1]))
    return list(zip(bounds[:-1], bounds[1:], strict=True))


def pass_units(pixels: np.ndarray, n_samples: int, threads: int) -> list[np.ndarray]:
    """Split the pixels of one adaptive pass into work units of about ``WAVEFRONT`` paths
    (at least 4 per thread, so the threads stay balanced up to the pass's end)."""
    if len(pixels) == 0:
        return []
    pieces = max(4 * threads, -(-len(pixels) * n_samples // WAVEFRONT))
    return [u for u in np.array_split(pixels, min(pieces, len(pixels))) if len(u)]


def tiles(width: int, height: int, threads: int) -> list[tuple[int, int, int, int]]:
    """Square image tiles (x0, y0, x1, y1), small enough to give every thread work."""
    size = 64
    while size > 16 and math.ceil(width / size) * math.ceil(height / size) < 4 * threads:
        size //= 2
    return [(x, y, min(x + size, width), min(y + size, height))
            for y in range(0, height, size) for x in range(0, width, size)]


@dataclass
class FrameStats:
    paths: int = 0
    seconds: float = 0.0
    d_min: float = math.inf
    d_max: float = 0.0
    lock: threading.Lock = field(default_factory=threading.Lock, repr=False)


class RenderCancelled(Exception):  # noqa: N818 - a signal, not an error
    """The caller's cancel check asked the render to stop."""


class FrameRenderer:
    """Renders frames of one prepared scene with fixed render settings."""

    def __init__(self, prep: PreparedScene, settings: RenderSettings, camera: PinholeCamera,
                 aovs: tuple[str, ...] = (), bands: tuple[float, float, float] | None = None):
        self.prep = prep
        self.settings = settings
        self.camera = camera
        self.aovs = tuple(aovs)
        self.bands = bands if prep.mode != "rgb" else None
        mode = prep.mode
        self.rgb_mode = mode == "rgb"
        self.sampler = spectrum.make_sampler(
            "seed-gaussian" if mode == "seed-gaussian" else "cie1931", bands=self.bands)
        self.response = (np.zeros((3, 2), np.float32) if self.rgb_mode
                         else spectrum.sensor_response(mode).astype(np.float32))
        self.to_rgb = spectrum.sensor_to_rgb(mode)
        self.doppler = settings.doppler and not self.rgb_mode
        self.searchlight = settings.searchlight and mode == "cie1931"
        self.threads = settings.threads or os.cpu_count() or 1
        # moving bodies shift and beam as the camera does (physics.md, "Moving objects")
        self.kernel = prep.kernel._replace(shift=self.doppler, beam=self.searchlight)
        # the denoising albedo/normal AOVs: traced only when asked for
        self.features = "albedo" in self.aovs or "normal" in self.aovs
        # a scene of Lambert surfaces (no alpha masks, no area-light quads), moving or not:
        # whole paths in one kernel call (whole_paths.py), else the wavefront integrator
        self.whole_paths = whole_paths.applies(self.kernel, prep.tracer, self.features)
        # ... and of those, one with a light to sample (a spectral map's bands excepted;
        # with moving bodies, lights at rest and no map or textures): sixteen paths at a
        # time in SIMD lanes (lane_paths.py; either flag False turns to the next
        # integrator)
        self.lane_paths = self.whole_paths and lane_paths.applies(self.kernel, prep.tracer,
                                                                   self.features)
        self._chunk_buffers: list[dict] = []   # wavefront buffer sets, see _trace_chunk

    def render(self, event: relativity.ShutterEvent, frame: int,
               progress: Callable[[int], None] | None = None,
               cancel: Callable[[], bool] | None = None,
               samples: tuple[int, int] | None = None) -> tuple[Film, FrameStats]:
        """Render one frame seen from ``event``; returns the film and statistics.

        ``samples = (s0, s1)`` renders only the pixel samples s0 ≤ s < s1 of the frame's
        ``spp`` (a sample batch: batches of one frame merge with :meth:`Film.merge` into
        the frame, because every random number is keyed by the sample index).  Adaptive
        sampling (``noise_threshold`` > 0) applies to whole frames only, not to batches.
        """
        s = self.settings
        s_lo, s_hi = samples if samples is not None else (0, s.spp)
        if not 0 <= s_lo < s_hi <= s.spp:
            raise ValueError(f"sample range {samples} is not inside [0, {s.spp})")
        film = Film(s.width, s.height, aovs=self.aovs, bands=self.bands)
        if s_lo == 0:  # once per frame: a batch split merges it once (film.py)
            self._add_stars(event, film)
        stats = FrameStats()
        lock = threading.Lock()
        t0 = time.perf_counter()

        # (a cap within the first pass leaves nothing to decide: one plain pass by tiles)
        adaptive = s.noise_threshold > 0.0 and samples is None and s_hi > ADAPTIVE_FIRST_PASS

        def work(pixels, a, b):
            """Trace samples [a, b) of ``pixels`` (one work unit), in wavefronts.

            Each pixel is in one unit per pass and its samples are added in order, so
            the film does not depend on how pixels are grouped into units or threads.
            """
            chunk = max(1, WAVEFRONT // len(pixels))
            for s0 in range(a, b, chunk):
                if cancel is not None and cancel():
                    raise RenderCancelled
                s1 = min(b, s0 + chunk)
                self._trace_chunk(event, frame, pixels, s0, s1, film, lock, stats)
                if progress is not None:
                    progress(len(pixels) * (s1 - s0))

        tile_pixels = []
        for x0, y0, x1, y1 in tiles(s.width, s.height, self.threads):
            cols, rows = np.meshgrid(np.arange(x0, x1), np.arange(y0, y1))
            tile_pixels.append((rows * s.width + cols).ravel().astype(np.int64))
        with ThreadPoolExecutor(self.threads) as pool:
            if not adaptive:
                for f in [pool.submit(work, px, s_lo, s_hi) for px in tile_pixels]:
                    f.result()
            else:
                # Passes over the whole frame: the stopping decision after a pass sees
                # every pixel's samples, so it is the same for any tiling/thread count.
                order = np.concatenate(tile_pixels)
                active = np.ones(s.width * s.height, bool)
                for a, b in sample_passes(s_lo, s_hi, True):
                    units = pass_units(order[active[order]], b - a, self.threads)
                    for f in [pool.submit(work, px, a, b) for px in units]:
                        f.result()
                    if b < s_hi:
                        done = active & film.converged(s.noise_threshold).ravel()
                        if progress is not None:
                            progress(int(done.sum()) * (s_hi - b))
                        active &= ~done
                        if not active.any():
                            break
        stats.seconds = time.perf_counter() - t0
        return film, stats

    def _add_stars(self, event: relativity.ShutterEvent, film: Film) -> None:
        """The scene's stars as the film's sample-free layer (core/render/starfield.py);
        nothing without stars, and none on a transparent film (the sky is not seen)."""
        stars = self.prep.scene.stars
        if stars is None or len(stars) == 0 or self.settings.transparent:
            return
        camera = self.camera if event.rotation is None else \
            replace(self.camera, rotation=event.rotation)
        bands = None
        if film.num_bands:
            bands = (film.band_centers_nm, film.bands[2])
        prep = self.prep
        splats = star_splats(stars, camera, event.beta, mode=prep.mode, doppler=self.doppler,
                             searchlight=self.searchlight, bands=bands,
                             blocked=occlusion_test(prep.tracer, prep.origin, prep.radius,
                                                    event))
        film.add_layer(splats.pixel, splats.sensor, splats.bands)

    def camera_paths(self, event: relativity.ShutterEvent, frame: int, pix: np.ndarray,
                     samp: np.ndarray, out: tuple[np.ndarray, ...] | None = None
                     ) -> CameraPaths:
        """The camera stage of the paths (pixel ``pix[i]``, sample ``samp[i]``) of
        ``frame`` at ``event``: their keys, camera rays (float32 lab directions, origins
        in accelerator coordinates) with the camera's Doppler factors D and skipped
        distances, and hero lanes (λ, pdf, table coordinates shifted by D, D⁵ weight; the
        rgb mode: columns 0..2 of the RGB tables, w_d = 1), what the integrators start
        from. ``out``: arrays to fill (else new): (λ, pdf, table coordinates, w_d, keys,
        o, d, D, skipped, hero offsets), as :data:`CHUNK_BUFFERS` names them
        (:data:`CAMERA_BUFFERS`)."""
        s = self.settings
        n = len(pix)
        if out is None:
            fresh = wavefront_buffers(n, None, tuple(b for b in CHUNK_BUFFERS
                                                     if b[0] in CAMERA_BUFFERS))
            out = tuple(fresh[k] for k in CAMERA_BUFFERS)
        keys = path_keys(s.seed, frame, pix, samp, out[4])
        camera = self.camera if event.rotation is None else \
            replace(self.camera, rotation=event.rotation)
        o, d, D, skipped = camera.primary_rays(
            event.beta, keys, pix, np.asarray(event.x, np.float64) - self.prep.origin,
            self.prep.radius, out[5:9])
        if self.rgb_mode:  # columns 0..2 of the RGB tables; w_d = 1 (no searchlight)
            lam, pdf, lamu, w_d = (a[:n] for a in out[:4])
            lam[:], pdf[:], lamu[:], w_d[:] = 0.0, 1.0, (0.0, 1.0, 2.0, 0.0), 1.0
            d_min, d_max = (float(D.min()), float(D.max())) if n else (math.inf, 0.0)
            return CameraPaths(keys, o, d, D, skipped, lam, pdf, lamu, w_d, d_min, d_max, 3)
        u = progressive_offsets(s.seed, frame, pix, samp, out[9])
        # hero λ, pdf, table coordinates (Doppler-shifted), D⁵ and D's range: one pass
        lam, pdf, lamu, w_d, d_min, d_max = self.sampler.lanes(
            u, D, doppler=self.doppler, searchlight=self.searchlight, out=out[:4])
        return CameraPaths(keys, o, d, D, skipped, lam, pdf, lamu, w_d, d_min, d_max, 4)

    def _trace_chunk(self, event, frame, pixels, s0, s1, film, lock, stats):
        s = self.settings
        prep = self.prep
        n_s = s1 - s0
        n = len(pixels) * n_s
        # Wavefront buffers, kept by the renderer across chunks, threads and frames (one set
        # per concurrent chunk; list pop/append are atomic).  A set returns to the pool
        # once the film has consumed it.
        keep = self._chunk_buffers.pop() if self._chunk_buffers else {}
        b = wavefront_buffers(n, keep, CHUNK_BUFFERS)
        pix, samp = b["pix"], b["samp"]
        pix.reshape(len(pixels), n_s)[:] = pixels[:, None]
        samp.reshape(len(pixels), n_s)[:] = np.arange(s0, s1, dtype=np.int64)
        cp = self.camera_paths(event, frame, pix, samp, tuple(b[k] for k in CAMERA_BUFFERS))
        keys, o_local, d_lab, D, skipped = cp.keys, cp.o, cp.d, cp.D, cp.skipped
        lam, pdf, lamu, w_d, nlanes = cp.lam, cp.pdf, cp.lamu, cp.w_d, cp.nlanes
        spread = 0.0
        if self.kernel.tex.enabled:  # the ray cones' start (textures.py)
            spread = lab_spread(pixel_spread(self.camera.tan_half_fov, self.camera.height), D)
        feats = None
        if self.whole_paths and self.lane_paths:
            L, t_hit, seg = lane_paths.trace(self.kernel, prep.tracer, s.max_depth, keys,
                                             o_local, d_lab, lamu, nlanes,
                                             sky_seen=not s.transparent,
                                             buffers=keep.setdefault("whole", {}),
                                             spread=spread, t0=float(event.t))
        elif self.whole_paths:
            L, t_hit, seg = whole_paths.trace(self.kernel, prep.tracer, s.max_depth, keys,
                                              o_local, d_lab, lamu, nlanes,
                                              sky_seen=not s.transparent,
                                              buffers=keep.setdefault("whole", {}),
                                              t0=float(event.t), spread=spread)
        else:
            L, t_hit, seg, feats = trace(self.kernel, prep.tracer, s.max_depth, keys,
                                         o_local, d_lab, lamu, nlanes,
                                         sky_seen=not s.transparent,
                                         buffers=keep.setdefault("trace", {}),
                                         t0=float(event.t), features=self.features,
                                         spread=spread)
        alpha = np.less(t_hit, MISS_DISTANCE, out=b["alpha"])  # 1.0 where it hit
        sensor, lam_weight = b["sensor"], b["lam_weight"]
        sensor_values(L, lam, pdf, w_d, self.response, self.rgb_mode, sensor, lam_weight,
                      self.bands is not None)
        if s.clamp > 0.0:  # render.clamp (film.py, "Clamp"): off, the samples are untouched
            clamp_samples(sensor, self.to_rgb, s.clamp, lam_weight if self.bands else None)
        if "doppler" in self.aovs and prep.scene.groups:
            D = D * body_doppler(prep.tracer, d_lab, seg)
        aov = {"doppler": D}  # the AOV arrays only when the film has them
        if "depth" in self.aovs or "lab_time" in self.aovs:
            dist = np.where(alpha > 0.0, t_hit + skipped, ESCAPED_DEPTH)
            aov.update(depth=dist, lab_time=event.t - dist)
        if feats is not None:
            aov.update(albedo=feats.albedo, normal=feats.normal)
        aov = {k: aov[k] for k in self.aovs}
        with lock:
            film.add_samples(pix, sensor, alpha, aov,
                             lam if self.bands else None, lam_weight if self.bands else None)
            stats.paths += n
            stats.d_min = min(stats.d_min, cp.d_min)
            stats.d_max = max(stats.d_max, cp.d_max)
        self._chunk_buffers.append(keep)


def body_doppler(tracer: MovingScene, d_lab: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """D_u = ν_lab/ν_rest = 1/(γ_u (1 + u·d)) of the moving body each primary ray hit
    (1 where it hit a static one or nothing), for the ``doppler`` AOV ν_camera/ν_rest."""
    out = np.ones(len(seg))
    segments = [s for g in tracer.groups for s in g.segments]
    for k in np.unique(seg[seg >= 0]):
        rows = seg == k
        out[rows] = 1.0 / np.asarray(relativity.doppler_factor_lab(
            d_lab[rows].astype(np.float64), segments[k].u), np.float64).reshape(-1)
    return out


def build_renderer(job: Job, scene: Scene | None = None,
                   threads: int | None = None, env_nee: bool = True) -> FrameRenderer:
    """A :class:`FrameRenderer` for ``job`` (scene, BVH, tables); ``threads`` overrides;
    ``env_nee``: :func:`prepare`'s."""
    scene = scene if scene is not None else build_scene(job)
    job = resolved_job(job)  # render.spectral = "auto" (the drivers' jobs are resolved)
    cam = resolve_camera(job, scene)
    s = job.render if threads is None else replace(job.render, threads=int(threads))
    prep = prepare(scene, s.spectral, env_nee)
    bands = job.output.spectral_bands if "spectral-exr" in job.output.formats else None
    return FrameRenderer(prep, s, PinholeCamera.from_settings(cam, s.width, s.height),
                         aovs=job.output.aovs, bands=bands)


