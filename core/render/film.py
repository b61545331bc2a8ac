"""The film: per-pixel accumulation of sensor samples (the camera's sensor).

The integrator hands the film batches of samples; the film keeps float64 running sums
per pixel and turns them into an image on :meth:`Film.resolve`.

Pixels
    A pixel is addressed by its flat index ``p = row * width + col``, row 0 = the TOP of
    the picture (the output contract of job-format.md), so a resolved ``(h, w)`` array
    is written to disk without a flip.

What is summed (per pixel, float64)
    ====================  =========================================================
    ``sum_sensor[p, c]``  Σ s_c, the three sensor channels (XYZ, or RGB in the
                          ``rgb`` mode), each already divided by p(λ) and by the 4
                          hero lanes by the integrator
    ``sum_sq[p, c]``      Σ s_c², per sensor channel (``sum_y2`` is its column 1:
                          Σ Y², Y = s_1 the sensor's luminance channel; G in ``rgb``)
    ``sum_alpha[p]``      Σ α, α = 1 where the primary ray hit geometry, 0 where it
                          escaped
    ``sum_aov[p, k]``     Σ a_k, one column per AOV component, in the order of
                          ``aov_names`` (``albedo`` R, G, B and ``normal`` X, Y, Z take
                          three columns each: :data:`AOV_COMPONENTS`)
    ``count[p]``          n, the samples taken
    ``sum_band[p, b]``    Σ over the sample's hero lanes j with λ_j in band b of
                          w_j = L(λ_j) / (4 p(λ_j))
    ====================  =========================================================

    The sums are built by one fused numba loop that adds each sample straight into the
    running sums, in input order. (This is what ``np.bincount`` followed by ``+=`` would
    do for one batch, but without the per-batch partial sum: a stream of samples gives
    bit-identical sums however it is split into batches, as long as each pixel's samples
    arrive in the same order.) :meth:`Film.merge` adds two partial sums, which
    re-associates the additions: equal to rounding, not bit for bit.

Estimators (on :meth:`Film.resolve`)
    * pixel value: the mean ``m_c = Σ s_c / n``; ``rgb = M · m`` with ``M`` the
      sensor-to-linear-Rec.709 matrix; alpha and AOVs are plain means too.
    * spectral band b, centre λ_b, width Δ: the mean camera-frame spectral radiance
      over [λ_b - Δ/2, λ_b + Δ/2],

          S_b = (1 / (n Δ)) Σ_samples Σ_{j: λ_j ∈ band b} L(λ_j) / (4 p(λ_j)),

      an unbiased estimate of (1/Δ) ∫_band L dλ. A lane belongs to band
      ``b = floor((λ - (start - Δ/2)) · (1/Δ))``; lanes outside every band are ignored
      (their samples still count in n: they are part of the same estimator).
    * relative standard error of the luminance mean (``FilmImage.rel_error``; the
      tests use it as each pixel's Monte Carlo error bar):

          var(Y) = (Σ Y² / n - (Σ Y / n)²) · n / (n - 1)     (unbiased, clamped at 0)
          rel_error = sqrt(var(Y) / n) / max(|Σ Y / n|, luminance_floor)

      ``luminance_floor`` (default :data:`LUMINANCE_FLOOR`) keeps near-black pixels
      from demanding endless samples; a pixel whose samples are all 0 has error 0. A
      pixel with fewer than 2 samples has no variance estimate and reports
      :data:`REL_ERROR_UNKNOWN` (finite, huge). The one-pass variance loses precision
      only when the noise is below ~1e-8 of the mean, far under any useful threshold.
    * the adaptive-sampling error (:meth:`Film.adaptive_error`, what ``noise_threshold``
      is compared with), over all three sensor channels c, so colour noise counts:

          m_c = Σ s_c / n,   var_c = (Σ s_c² / n - m_c²) · n / (n - 1)   (clamped at 0)
          se  = sqrt(Σ_c var_c / n)        standard error of the pixel's mean, L2 over c
          I   = sqrt(Σ_c m_c²)             the pixel's brightness; Ī = mean I over the
                                           pixels with samples
          adaptive_error = se / sqrt(max(I, luminance_floor · Ī) · Ī)

      For a pixel as bright as the image average this is its relative standard error;
      a pixel k times darker is allowed a relative error √k larger (Cycles normalises
      by √I the same way: noise in dark pixels is less visible, and the relative MSE
      and ΔE00 of the image fall faster per sample spent on brighter pixels); dividing
      by Ī too keeps it independent of the scene's overall brightness. All-black
      pixels have error 0; fewer than 2 samples: :data:`REL_ERROR_UNKNOWN`.
      :meth:`Film.converged` stops a pixel when its own error *and* the mean error of
      its 3x3 window (clipped at the image border) are at most the threshold: the
      window keeps a pixel whose first samples happened to miss rare bright paths
      (low variance, too dark) sampling while its neighbours are still noisy. That
      halves the dark bias of judging a pixel by its own samples (what is left: the
      stopped pixels' luminance about 0.4 % low on the Cornell box at threshold 0.1),
      and the own-error test keeps a noisy pixel among quiet ones from stopping.
      (Cycles' half-buffer estimate |mean - mean of half the samples| was tried: with
      one degree of freedom per channel it is much noisier than var_c, and it gained
      less at equal samples, with no less bias.)

Clamp (``render.clamp`` = C > 0; Cycles' "Clamp Direct/Indirect")
    :func:`clamp_samples` scales each path sample down, before it reaches the film, so
    that the largest absolute component of its linear Rec.709 value M · s is at most C:

        k = min(1, C / max_c |(M s)_c|),   s ← k s,   w_j ← k w_j (the spectral bands)

    One factor for the whole sample (its 3 sensor channels and its 4 hero lanes), so the
    sample's colour (chromaticity) is unchanged; only its weight drops. It is the
    quantity the film accumulates (a path's sensor values, w_D and 1/p(λ) included)
    measured in the output's units, so a clamp of C guarantees that no sample adds more
    than C to any RGB channel of a pixel's sum. Cycles instead scales each *contribution*
    (every emission hit and light sample, with separate limits for the camera's first
    bounce and later ones) so that the *mean* of its |R|, |G|, |B| is at most C
    (intern/cycles/kernel/film/light_passes.h ``film_clamp_light``, the limit stored as
    3 C by scene/integrator.cpp); relray clamps the whole path sample, by its largest
    component, so at equal C it clamps at least as hard. Clamping is biased by design:
    it removes energy (fireflies, but also true caustics and bright highlights seen
    through few paths), and the image no longer converges to the right answer as spp
    grows; the adaptive-sampling error is that of the clamped samples. C = 0 (the
    default) skips it: the film then sees bit-identical samples.

Sample-free layer (the stars, core/render/starfield.py)
    Radiance that no path sample carries, computed once per frame: :meth:`add_layer`
    keeps a sparse list of splats, ``layer_pixel[k]``, ``layer_sensor[k, c]`` (sensor
    values) and ``layer_band[k, b]`` (mean band radiance), as a pixel's mean would be
    (memory in proportion to the splats, not to the image). :meth:`Film.resolve` adds
    their per-pixel sums (:meth:`Film.layer_sums`) to the pixels' means
    (``rgb = M · (m + layer)``). The layer is not clamped and is no part of the noise
    estimates or ``spp``. A frame split into sample batches carries it in the batch that
    starts at sample 0 only, so :meth:`Film.merge` simply appends the other's splats.

Finite outputs
    A sample with any non-finite value (sensor, alpha, an AOV, a hero wavelength or lane
    weight) is dropped whole in :meth:`Film.add_samples` and counted in
    :attr:`Film.nonfinite_samples`, so one Inf cannot poison a pixel. A pixel without
    samples resolves to 0 (alpha 0). Any value still non-finite after resolving (a
    float32 overflow) is set to 0 and counted in :attr:`FilmImage.nonfinite_values`, and
    :meth:`Film.resolve` logs one warning on the "relray" logger saying how many (this
    happens only for radiances beyond 3.4e38: D⁵ with |β| within ~1e-15 of 1).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..jit import njit
from ..scene.description import AOV_COMPONENTS, aov_components

log = logging.getLogger("relray")

__all__ = ["AOV_COMPONENTS", "Film", "FilmImage", "clamp_samples", "band_centers",
           "window_mean", "LUMINANCE_FLOOR", "REL_ERROR_UNKNOWN"]

LUMINANCE_FLOOR = 1e-4
"""Smallest |mean Y| used as the denominator of the relative error."""

REL_ERROR_UNKNOWN = 1e30
"""Relative error reported for pixels with fewer than 2 samples (no variance estimate)."""


@dataclass
class FilmImage:
    """A resolved film: everything the image writers need. Row 0 = top of the picture."""

    rgba: np.ndarray
    """float32 (h, w, 4): linear Rec.709, scene-referred; alpha = hit coverage."""
    aovs: dict[str, np.ndarray]
    """float32 per-pixel means: (h, w) each ("depth", "doppler", "lab_time", ...), (h, w, 3)
    for "albedo" (R, G, B) and "normal" (X, Y, Z)."""
    spectral: np.ndarray | None
    """float32 (h, w, nb): mean camera-frame spectral radiance per band, or None."""
    band_centers_nm: np.ndarray | None
    """float64 (nb,): band centres in nm, or None."""
    spp: np.ndarray
    """int32 (h, w): samples accumulated per pixel (dropped non-finite samples excluded)."""
    rel_error: np.ndarray
    """float32 (h, w): relative standard error of the luminance mean."""
    nonfinite_values: int = 0
    """Output values that were non-finite after resolving and were set to 0."""


def window_mean(a: np.ndarray) -> np.ndarray:
    """Mean of each element's 3x3 neighbourhood in a 2-D array, clipped at the border
    (a corner averages 4 values, an edge 6)."""
    a = np.asarray(a, np.float64)
    h, w = a.shape
    pad = np.zeros((h + 2, w + 2))
    pad[1:-1, 1:-1] = a
    ones = np.zeros((h + 2, w + 2))
    ones[1:-1, 1:-1] = 1.0
    total = np.zeros((h, w))
    count = np.zeros((h, w))
    for dy in range(3):
        for dx in range(3):
            total += pad[dy:dy + h, dx:dx + w]
            count += ones[dy:dy + h, dx:dx + w]
    return total / count


def band_centers(bands: tuple[float, float, float]) -> np.ndarray:
    """Band centres λ = start, start + step, ..., stop (inclusive), float64 nm."""
    start, stop, step = (float(v) for v in bands)
    if not (step > 0.0 and math.isfinite(start) and math.isfinite(stop) and stop >= start):
        raise ValueError(f"bad spectral bands (start, stop, step) = {bands}")
    n = int(math.floor((stop - start) / step + 1e-9)) + 1
    return start + step * np.arange(n, dtype=np.float64)


@njit(cache=True, nogil=True, error_model="numpy")
def _clamp(sensor, lam_w, m, limit, n_lanes):  # pragma: no cover - compiled
    """In place: each row's sensor values (and its ``n_lanes`` band weights) times
    min(1, limit / max_c |(m · s)_c|). Returns how many samples were scaled down."""
    scaled = 0
    for i in range(sensor.shape[0]):
        s0, s1, s2 = sensor[i, 0], sensor[i, 1], sensor[i, 2]
        big = 0.0
        for c in range(3):
            big = max(big, abs(m[c, 0] * s0 + m[c, 1] * s1 + m[c, 2] * s2))
        if big > limit:  # False for NaN: a non-finite sample stays for the film to drop
            k = limit / big
            sensor[i, 0] = s0 * k
            sensor[i, 1] = s1 * k
            sensor[i, 2] = s2 * k
            for j in range(n_lanes):
                lam_w[i, j] *= k
            scaled += 1
    return scaled


def clamp_samples(sensor: np.ndarray, sensor_to_rgb: np.ndarray, limit: float,
                  lam_weight: np.ndarray | None = None) -> int:
    """``render.clamp``: scale each sample (row of ``sensor`` (N, 3), and of
    ``lam_weight`` (N, lanes) when given) in place so that the largest absolute linear
    Rec.709 component of ``sensor_to_rgb · s`` is at most ``limit`` > 0 (module
    docstring, "Clamp"). Returns the number of samples scaled down."""
    if not limit > 0.0:
        raise ValueError(f"clamp limit must be > 0, got {limit}")
    m = np.ascontiguousarray(sensor_to_rgb, np.float64)
    if m.shape != (3, 3) or sensor.ndim != 2 or sensor.shape[1] != 3:
        raise ValueError(f"clamp_samples: sensor {sensor.shape} / matrix {m.shape}")
    lanes = np.zeros((0, 0), sensor.dtype) if lam_weight is None else lam_weight
    if lam_weight is not None and lam_weight.shape[0] != sensor.shape[0]:
        raise ValueError(f"clamp_samples: lam_weight {lam_weight.shape} for {sensor.shape}")
    return int(_clamp(sensor, lanes, m, float(limit), lanes.shape[1]))


@njit(cache=True, nogil=True)
def _accumulate(
    pixel,
    sensor,
    alpha,
    aov,
    lam,
    lam_w,
    band_lo,
    inv_step,
    sum_sensor,
    sum_sq,
    sum_alpha,
    sum_aov,
    count,
    sum_band,
):  # pragma: no cover - compiled
    """Add samples i = 0..N-1 in order; skip (and count) samples with a non-finite value.

    aov is (K, N); lam, lam_w are (N, lanes) (ignored when sum_band has 0 columns);
    sum_band is (n_pix, nb). Returns the number of dropped samples.
    """
    n = pixel.shape[0]
    n_aov = aov.shape[0]
    nb = sum_band.shape[1]
    use_bands = nb > 0
    lanes = lam.shape[1]
    dropped = 0
    for i in range(n):
        s0 = np.float64(sensor[i, 0])
        s1 = np.float64(sensor[i, 1])
        s2 = np.float64(sensor[i, 2])
        a = np.float64(alpha[i])
        # x - x is 0 for finite x and NaN for ±Inf/NaN: one well-predicted branch.
        check = (s0 - s0) + (s1 - s1) + (s2 - s2) + (a - a)
        for k in range(n_aov):
            v = np.float64(aov[k, i])
            check += v - v
        if use_bands:
            for j in range(lanes):
                v = np.float64(lam[i, j])
                u = np.float64(lam_w[i, j])
                check += (v - v) + (u - u)
        if check != 0.0:
            dropped += 1
            continue
        p = pixel[i]
        sum_sensor[p, 0] += s0
        sum_sensor[p, 1] += s1
        sum_sensor[p, 2] += s2
        sum_sq[p, 0] += s0 * s0
        sum_sq[p, 1] += s1 * s1
        sum_sq[p, 2] += s2 * s2
        sum_alpha[p] += a
        for k in range(n_aov):
            sum_aov[p, k] += np.float64(aov[k, i])
        count[p] += 1
        if use_bands:
            for j in range(lanes):
                x = (np.float64(lam[i, j]) - band_lo) * inv_step
                if x >= 0.0 and x < nb:
                    sum_band[p, int(x)] += np.float64(lam_w[i, j])
    return dropped


class Film:
    """Per-pixel float64 sums of sensor samples, alpha, AOVs and spectral bands.

    ``Film(width, height, aovs=("depth", "doppler"), bands=(380, 780, 10))``.
    Feed it with :meth:`add_samples`, combine partial films with :meth:`merge`, read it
    with :meth:`resolve` (:meth:`converged` drives adaptive sampling). See the
    module docstring for the estimators.
    """

    def __init__(
        self,
        width: int,
        height: int,
        aovs: Sequence[str] = (),
        bands: tuple[float, float, float] | None = None,
        luminance_floor: float = LUMINANCE_FLOOR,
    ):
        if int(width) <= 0 or int(height) <= 0:
            raise ValueError(f"film size must be positive, got {width}x{height}")
        self.width = int(width)
        self.height = int(height)
        self.aov_names: tuple[str, ...] = tuple(aovs)
        if len(set(self.aov_names)) != len(self.aov_names):
            raise ValueError(f"duplicate AOV names: {self.aov_names}")
        #: the first column of each AOV in ``sum_aov`` and its number of components
        self.aov_columns: dict[str, tuple[int, int]] = {}
        col = 0
        for name in self.aov_names:
            self.aov_columns[name] = (col, aov_components(name))
            col += aov_components(name)
        self.bands = None if bands is None else tuple(float(v) for v in bands)
        self.band_centers_nm = None if bands is None else band_centers(bands)
        self.luminance_floor = float(luminance_floor)
        n = self.width * self.height
        nb = 0 if self.band_centers_nm is None else len(self.band_centers_nm)
        self.sum_sensor = np.zeros((n, 3), np.float64)
        self.sum_sq = np.zeros((n, 3), np.float64)
        self.sum_alpha = np.zeros(n, np.float64)
        self.sum_aov = np.zeros((n, col), np.float64)
        self.count = np.zeros(n, np.int64)
        self.sum_band = np.zeros((n, nb), np.float64)
        self.layer_pixel = np.zeros(0, np.int64)
        self.layer_sensor = np.zeros((0, 3), np.float64)
        self.layer_band = np.zeros((0, nb), np.float64)
        self.nonfinite_samples = 0
        """Samples dropped by :meth:`add_samples` because a value was non-finite."""

    # ------------------------------------------------------------------ properties
    @property
    def num_pixels(self) -> int:
        return self.width * self.height

    @property
    def num_bands(self) -> int:
        return self.sum_band.shape[1]

    @property
    def sum_y2(self) -> np.ndarray:
        """Σ Y² per pixel (a view of column 1 of :attr:`sum_sq`)."""
        return self.sum_sq[:, 1]

    @property
    def total_samples(self) -> int:
        """Samples accumulated (after dropping non-finite ones)."""
        return int(self.count.sum())

    @property
    def samples_per_pixel(self) -> np.ndarray:
        """int32 (h, w): samples accumulated per pixel, row 0 = top."""
        return self.count.reshape(self.height, self.width).astype(np.int32)

    # ------------------------------------------------------------------ accumulation
    def add_samples(
        self,
        pixel: np.ndarray,
        sensor: np.ndarray,
        alpha: np.ndarray,
        aov: dict[str, np.ndarray] | None = None,
        lam_cam: np.ndarray | None = None,
        lam_weight: np.ndarray | None = None,
    ) -> None:
        """Add N samples, in order.

        pixel (N,) int: flat index row*width + col (row 0 = top); sensor (N, 3): sensor
        values already divided by the wavelength pdf and the 4 lanes; alpha (N,);
        aov: name -> (N,) for every AOV of the film (extra names are ignored);
        lam_cam, lam_weight (N, lanes): camera-frame hero wavelengths (nm) and
        L(λ)/(4 p(λ)) per lane, required when the film has bands (ignored otherwise).
        float32 or float64 inputs; sums are float64.
        """
        pixel = np.ascontiguousarray(pixel, dtype=np.int64)
        sensor = np.asarray(sensor)
        alpha = np.asarray(alpha)
        n_in = pixel.shape[0]
        if pixel.ndim != 1 or sensor.shape != (n_in, 3) or alpha.shape != (n_in,):
            raise ValueError(
                f"add_samples: shapes pixel {pixel.shape}, sensor {sensor.shape}, "
                f"alpha {alpha.shape} do not match (N,), (N, 3), (N,)"
            )
        if n_in == 0:
            return
        if int(pixel.min()) < 0 or int(pixel.max()) >= self.num_pixels:
            raise ValueError(
                f"add_samples: pixel index outside [0, {self.num_pixels - 1}]: "
                f"[{int(pixel.min())}, {int(pixel.max())}]"
            )
        aov_stack = self._stack_aovs(aov, n_in, sensor.dtype)
        if self.num_bands:
            if lam_cam is None or lam_weight is None:
                raise ValueError("add_samples: the film has bands; lam_cam/lam_weight needed")
            lam = np.asarray(lam_cam)
            lam_w = np.asarray(lam_weight)
            if lam.ndim != 2 or lam.shape[0] != n_in or lam_w.shape != lam.shape:
                raise ValueError(
                    f"add_samples: lam_cam {lam.shape} / lam_weight {lam_w.shape} "
                    f"must be (N, lanes)"
                )
            start, _, step = self.bands
            band_lo = start - 0.5 * step
        else:
            lam = lam_w = np.zeros((0, 4), np.float32)
            band_lo, step = 0.0, 1.0
        self.nonfinite_samples += int(
            _accumulate(
                pixel,
                sensor,
                alpha,
                aov_stack,
                lam,
                lam_w,
                float(band_lo),
                1.0 / float(step),
                self.sum_sensor,
                self.sum_sq,
                self.sum_alpha,
                self.sum_aov,
                self.count,
                self.sum_band,
            )
        )

    def add_layer(self, pixel: np.ndarray, sensor: np.ndarray,
                  bands: np.ndarray | None = None) -> None:
        """Add sample-free radiance (module docstring, "Sample-free layer"): ``sensor``
        (K, 3) sensor values and, when the film has bands, ``bands`` (K, nb) mean band
        radiance, to the pixels ``pixel`` (K,) (repeats add up). Rows with a non-finite
        value are dropped and counted in :attr:`nonfinite_samples`."""
        pixel = np.asarray(pixel, np.int64).reshape(-1)
        sensor = np.asarray(sensor, np.float64).reshape(len(pixel), 3)
        if len(pixel) and (int(pixel.min()) < 0 or int(pixel.max()) >= self.num_pixels):
            raise ValueError("add_layer: pixel index outside the film")
        ok = np.isfinite(sensor).all(axis=1)
        band = None
        if self.num_bands:
            if bands is None:
                raise ValueError("add_layer: the film has bands; bands needed")
            band = np.asarray(bands, np.float64).reshape(len(pixel), self.num_bands)
            ok &= np.isfinite(band).all(axis=1)
        self.nonfinite_samples += int(np.count_nonzero(~ok))
        self.layer_pixel = np.concatenate([self.layer_pixel, pixel[ok]])
        self.layer_sensor = np.concatenate([self.layer_sensor, sensor[ok]])
        if band is not None:
            self.layer_band = np.concatenate([self.layer_band, band[ok]])

    def layer_sums(self) -> tuple[np.ndarray, np.ndarray]:
        """The sample-free layer per pixel: sensor values (num_pixels, 3) and band
        radiance (num_pixels, nb), float64 (splats in one pixel add up, in order)."""
        sensor = np.zeros((self.num_pixels, 3))
        band = np.zeros((self.num_pixels, self.num_bands))
        np.add.at(sensor, self.layer_pixel, self.layer_sensor)
        if self.num_bands:
            np.add.at(band, self.layer_pixel, self.layer_band)
        return sensor, band

    def _stack_aovs(
        self, aov: dict[str, np.ndarray] | None, n_in: int, dtype: np.dtype
    ) -> np.ndarray:
        """The film's AOVs as one (K, N) array, one row per component, in ``aov_names``
        order (the columns of ``sum_aov``)."""
        dt = np.float32 if dtype == np.float32 else np.float64
        out = np.empty((self.sum_aov.shape[1], n_in), dt)
        for name, (k, nc) in self.aov_columns.items():
            if aov is None or name not in aov:
                raise ValueError(f"add_samples: AOV '{name}' missing")
            a = np.asarray(aov[name])
            want = (n_in,) if nc == 1 else (n_in, nc)
            if a.shape != want:
                raise ValueError(f"add_samples: AOV '{name}' has shape {a.shape}, want {want}")
            if nc == 1:
                out[k] = a
            else:
                out[k:k + nc] = a.T
        return out

    def merge(self, other: Film) -> None:
        """Add another film's sums to this one (same size, AOVs and bands)."""
        mine = (self.width, self.height, self.aov_names, self.bands)
        theirs = (other.width, other.height, other.aov_names, other.bands)
        if mine != theirs:
            raise ValueError(f"merge: films differ (size, AOVs, bands): {mine} vs {theirs}")
        self.sum_sensor += other.sum_sensor
        self.sum_sq += other.sum_sq
        self.sum_alpha += other.sum_alpha
        self.sum_aov += other.sum_aov
        self.count += other.count
        self.sum_band += other.sum_band
        self.layer_pixel = np.concatenate([self.layer_pixel, other.layer_pixel])
        self.layer_sensor = np.concatenate([self.layer_sensor, other.layer_sensor])
        self.layer_band = np.concatenate([self.layer_band, other.layer_band])
        self.nonfinite_samples += other.nonfinite_samples

    # ------------------------------------------------------------------ resolving
    def _mean(self, s: np.ndarray) -> np.ndarray:
        """s / n per pixel (first axis), 0 where n = 0, float64."""
        n = self.count.reshape((-1,) + (1,) * (s.ndim - 1))
        return np.divide(s, n, out=np.zeros(s.shape, np.float64), where=n > 0)

    def relative_error(self, pixels: np.ndarray | None = None) -> np.ndarray:
        """float32 (h, w): relative standard error of each pixel's luminance mean.

        With ``pixels`` (flat indices), only those pixels, as a float32 (len(pixels),).
        """
        sel = slice(None) if pixels is None else np.asarray(pixels, np.int64)
        count = self.count[sel]
        n = count.astype(np.float64)
        y, y2 = self.sum_sensor[sel, 1], self.sum_y2[sel]
        mean_y = np.divide(y, n, out=np.zeros_like(n), where=count > 0)
        mean_y2 = np.divide(y2, n, out=np.zeros_like(n), where=count > 0)
        enough = count >= 2
        bessel = np.divide(n, n - 1.0, out=np.zeros_like(n), where=enough)
        var = bessel * np.maximum(mean_y2 - mean_y * mean_y, 0.0)
        se = np.sqrt(np.divide(var, n, out=np.zeros_like(n), where=enough))
        rel = se / np.maximum(np.abs(mean_y), self.luminance_floor)
        rel[~enough | ~np.isfinite(rel)] = REL_ERROR_UNKNOWN
        if pixels is not None:
            return rel.astype(np.float32)
        return rel.reshape(self.height, self.width).astype(np.float32)

    def adaptive_error(self) -> np.ndarray:
        """float64 (h, w): the error adaptive sampling compares with ``noise_threshold``.

        Relative standard error of the pixel mean over the three sensor channels,
        normalised by sqrt(I · Ī) (module docstring).
        """
        count = self.count
        n = count.astype(np.float64)
        ok = count > 0
        enough = count >= 2
        m = self._mean(self.sum_sensor)
        m2 = self._mean(self.sum_sq)
        bessel = np.divide(n, n - 1.0, out=np.zeros_like(n), where=enough)
        var = (bessel[:, None] * np.maximum(m2 - m * m, 0.0)).sum(axis=1)
        se = np.sqrt(np.divide(var, n, out=np.zeros_like(n), where=enough))
        bright = np.sqrt((m * m).sum(axis=1))
        i_mean = float(bright[ok].mean()) if ok.any() else 0.0
        if not (math.isfinite(i_mean) and i_mean > 0.0):
            i_mean = self.luminance_floor
        norm = np.sqrt(np.maximum(bright, self.luminance_floor * i_mean) * i_mean)
        with np.errstate(over="ignore", invalid="ignore"):
            err = se / norm
        err[~enough | ~np.isfinite(err)] = REL_ERROR_UNKNOWN
        return err.reshape(self.height, self.width)

    def converged(self, threshold: float) -> np.ndarray:
        """bool (h, w): pixels whose :meth:`adaptive_error` and whose 3x3 window's mean
        error (the window clipped at the image border) are both at most ``threshold``."""
        err = self.adaptive_error()
        return (err <= threshold) & (window_mean(err) <= threshold)

    def resolve(self, sensor_to_rgb: np.ndarray) -> FilmImage:
        """Per-pixel means: rgba = (M · mean sensor, mean alpha), AOV and band means."""
        m = np.asarray(sensor_to_rgb, dtype=np.float64)
        if m.shape != (3, 3):
            raise ValueError(f"resolve: sensor_to_rgb must be (3, 3), got {m.shape}")
        h, w = self.height, self.width
        bad = 0

        def finite32(a: np.ndarray) -> np.ndarray:
            nonlocal bad
            with np.errstate(over="ignore", invalid="ignore"):
                out = a.astype(np.float32)
            nf = ~np.isfinite(out)
            if nf.any():
                bad += int(np.count_nonzero(nf))
                out[nf] = 0.0
            return out

        layer_sensor, layer_band = self.layer_sums()
        with np.errstate(over="ignore", invalid="ignore"):
            rgb = (self._mean(self.sum_sensor) + layer_sensor) @ m.T  # (n, 3)
        rgba = np.empty((h, w, 4), np.float32)
        rgba[..., :3] = finite32(rgb.reshape(h, w, 3))
        rgba[..., 3] = finite32(self._mean(self.sum_alpha).reshape(h, w))
        mean_aov = self._mean(self.sum_aov)
        aovs = {
            name: finite32(mean_aov[:, k].reshape(h, w) if nc == 1
                           else mean_aov[:, k:k + nc].reshape(h, w, nc))
            for name, (k, nc) in self.aov_columns.items()
        }
        spectral = None
        if self.num_bands:
            step = self.bands[2]
            spectral = finite32((self._mean(self.sum_band) / step + layer_band)
                                .reshape(h, w, self.num_bands))
        if bad:
            log.warning("%d output values exceed float32's range (3.4e38) and were set to 0",
                        bad)
        return FilmImage(
            rgba=rgba,
            aovs=aovs,
            spectral=spectral,
            band_centers_nm=None if self.band_centers_nm is None else self.band_centers_nm.copy(),
            spp=self.samples_per_pixel,
            rel_error=self.relative_error(),
            nonfinite_values=bad,
        )
