"""The machine's resources a render may use: memory (with its real limit) and threads.

A job is refused before any work when its estimated peak memory exceeds the memory
this process may really use: the smallest of the physical memory, the cgroup limit
(containers, SLURM and Kubernetes farm nodes: cgroup v2 ``memory.max``, v1
``memory.limit_in_bytes``) and the address-space and data rlimits (``ulimit -v``,
``ulimit -d``). Threads are capped at :data:`MAX_THREADS_PER_CORE` per usable core.
"""

from __future__ import annotations

import contextlib
import os
from dataclasses import dataclass
from pathlib import Path

CGROUP_FILES = (Path("/sys/fs/cgroup/memory.max"),
                Path("/sys/fs/cgroup/memory/memory.limit_in_bytes"))
"""Where cgroup v2 and v1 publish this container's memory limit."""
MAX_THREADS_PER_CORE = 4
"""Render threads above this many per usable core are refused: more only add overhead."""
MEMORY_FIXED_BYTES = 300 * 2**20
"""Peak memory of a render, measured (README, "Numerical limits"): about 300 MB of fixed
cost (Python, numba, Embree, wavefront buffers) plus, per pixel, the film's float64 sums
and the copies made while resolving and writing it: 260 bytes with the three AOVs, about
32 more per AOV or spectral band."""
MEMORY_BYTES_PER_PIXEL = 164
MEMORY_BYTES_PER_PIXEL_PER_LAYER = 32
MEMORY_BYTES_PER_TRIANGLE = 800
"""Peak bytes per triangle from tessellation to the BVH: float64 triangles and normals,
their float32 copies, the degeneracy test's temporaries and Embree's BVH. Measured
730-740 on a 1.3 M-triangle scene (sphere subdivision 8, and four at 7), plus 10 %."""


@dataclass(frozen=True)
class MemoryLimit:
    """The memory this process may use, and which limit it is (for the message)."""

    bytes: int
    source: str


def memory_limit(cgroup_files: tuple[Path, ...] = CGROUP_FILES) -> MemoryLimit | None:
    """The smallest of physical memory, the cgroup limit and the rlimits; None if the OS
    says nothing."""
    limits: list[MemoryLimit] = []
    with contextlib.suppress(AttributeError, ValueError, OSError):
        limits.append(MemoryLimit(int(os.sysconf("SC_PAGE_SIZE"))
                                  * int(os.sysconf("SC_PHYS_PAGES")), "physical memory"))
    for path in cgroup_files:
        with contextlib.suppress(OSError, ValueError):
            text = path.read_text().strip()
            if text and text != "max" and int(text) < 2**60:
                limits.append(MemoryLimit(int(text), f"the cgroup limit ({path})"))
    with contextlib.suppress(ImportError, AttributeError, ValueError, OSError):
        import resource

        for name, what in (("RLIMIT_AS", "ulimit -v"), ("RLIMIT_DATA", "ulimit -d")):
            soft = resource.getrlimit(getattr(resource, name))[0]
            if soft != resource.RLIM_INFINITY and soft > 0:
                limits.append(MemoryLimit(int(soft), f"the process limit ({what})"))
    return min(limits, key=lambda m: m.bytes) if limits else None


def render_memory_bytes(width: int, height: int, aovs: int, bands: int) -> int:
    """Estimated peak memory of rendering one frame's film (``MEMORY_BYTES_PER_PIXEL``)."""
    per_pixel = MEMORY_BYTES_PER_PIXEL + MEMORY_BYTES_PER_PIXEL_PER_LAYER * (aovs + bands)
    return MEMORY_FIXED_BYTES + width * height * per_pixel


def geometry_memory_bytes(triangles: int) -> int:
    """Estimated peak memory of building ``triangles`` triangles into the BVH."""
    return MEMORY_BYTES_PER_TRIANGLE * int(triangles)


def usable_cores() -> int:
    """CPU cores this process may run on (affinity, e.g. a SLURM cpuset), at least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def max_threads() -> int:
    """The most render threads a job may ask for on this machine."""
    return MAX_THREADS_PER_CORE * usable_cores()
