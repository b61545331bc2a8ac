"""The standalone render core: numpy, Embree (the embreex wheel's libembree4, through its C
API) and numba, never bpy.

Packages follow the data flow, and each imports only those before it (the layering that
``tests/test_layout.py`` enforces, with no import cycle anywhere)::

    errors                     UserError: one line naming the key and the file
    files                      reading input files: regular files only, bounded, no hang
    resources                  memory limit (physical, cgroup, rlimit), thread cap
    physics/    relativity, spectrum, sigmoid, cie_tables
    scene/      description ◄── job (TOML), gltf, shapes;  geometry, motion, footprint, names
    render/     camera, embree, accel, rest_frames, sampling, bsdf, lights, materials,
                integrator, film, frames
    output/     imageio, digest, frame_files (names, metadata, resume), contact
    progress    tqdm bar, JSON lines (the subprocess contract)
    runner      a job's frames in this process
    farm        a job's frames on Dask
    cli         the ``relray`` command

The core runs its own worker threads (one per core), so BLAS thread pools would only
oversubscribe the machine: unless the environment says otherwise, BLAS and OpenMP are
pinned to one thread here, before numpy is first imported. No kernel calls BLAS either,
so numba's probe for it, which imports scipy.linalg, is answered "none" (:class:`_NoBlasProbe`).
"""

import atexit
import hashlib
import importlib.abc
import logging
import os
import shutil
import sys
import tempfile
from pathlib import Path

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")


def user_cache_dir(environ=os.environ) -> str:
    """relray's folder in the user's cache: ``%LOCALAPPDATA%``, ``$XDG_CACHE_HOME`` or
    ``~/.cache``, then ``relray`` (kernels, fitted spectra)."""
    root = environ.get("LOCALAPPDATA" if os.name == "nt" else "XDG_CACHE_HOME")
    return os.path.join(root or os.path.join(os.path.expanduser("~"), ".cache"), "relray")


def kernel_source_digest(folder) -> str:
    """SHA-1 over the paths (relative to ``folder``) and bytes of the modules under
    ``folder`` that define numba kernels (those whose source mentions ``njit``), in path
    order."""
    digest = hashlib.sha1()
    root = Path(folder)
    for path in sorted(root.rglob("*.py")):
        source = path.read_bytes()
        if b"njit" in source:
            digest.update(path.relative_to(root).as_posix().encode())
            digest.update(source)
    return digest.hexdigest()


def kernel_cache_dir(environ=os.environ) -> str:
    """Where numba keeps the core's compiled kernels: ``<base>/relray-<digest>``.

    numba re-checks only the timestamp of the file that defines a cached kernel, not the
    modules whose functions the kernel inlined (``sampling``, ``bsdf``, ``spectrum`` ...),
    so a kernel compiled against an older sampler would be reused after an update; the
    folder is therefore keyed by :func:`kernel_source_digest` of this package. ``<base>``
    is ``NUMBA_CACHE_DIR`` from the environment, else :func:`user_cache_dir`/numba.
    """
    base = environ.get("NUMBA_CACHE_DIR") or os.path.join(user_cache_dir(environ), "numba")
    digest = kernel_source_digest(os.path.dirname(os.path.abspath(__file__)))
    return os.path.join(base, "relray-" + digest[:16])


def writable_dir(path: str) -> str | None:
    """Why ``path`` cannot hold cache files (it is created if missing), or None."""
    try:
        os.makedirs(path, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=path, prefix=".relray-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        return e.strerror or str(e)
    return None


def cache_fallback(path: str, what: str) -> str:
    """``path`` if it can hold cache files; else a fresh temporary folder (deleted at
    exit: no cache across runs), with one warning naming the folder and the reason."""
    why = writable_dir(path)
    if why is None:
        return path
    logging.getLogger("relray").warning(  # at import: before any logging set-up, hence
        "relray: warning: cannot use the cache folder %s (%s): %s without a cache "
        "(set XDG_CACHE_HOME or NUMBA_CACHE_DIR to a writable folder)", path, why, what)
    tmp = tempfile.mkdtemp(prefix="relray-cache-")
    atexit.register(shutil.rmtree, tmp, True)
    return tmp


class _NoBlasProbe(importlib.abc.MetaPathFinder):
    """Answers numba's probe for BLAS with "none", without importing scipy.linalg.

    numba loads its NumPy support at the first compile or cache load, and on the way
    (``numba.np.arraymath._check_blas``) imports ``scipy.linalg.cython_blas`` to learn
    whether ``np.dot`` and the like may call BLAS: 0.13 s of the first image's second
    (issue 12), for no use, since no relray kernel calls BLAS (the probe's answer only
    picks np.convolve's inner product in compiled code). This finder refuses ``scipy``
    (or ``scipy.linalg``) to that one caller, once; any other import, and numba's own
    later ``ensure_blas`` when a kernel does call BLAS, goes through as usual. Where
    scipy.linalg is already loaded, the probe finds it and nothing changes."""

    def find_spec(self, name, path=None, target=None):  # noqa: ARG002 - finder protocol
        if name not in ("scipy", "scipy.linalg"):
            return None
        frame = sys._getframe(1)
        while frame is not None:
            code = frame.f_code
            if code.co_name == "_check_blas" and code.co_filename.endswith(
                    os.path.join("numba", "np", "arraymath.py")):
                if self in sys.meta_path:
                    sys.meta_path.remove(self)
                raise ImportError("relray: numba's BLAS probe answered 'none' (no kernel "
                                  "calls BLAS)")
            frame = frame.f_back
        return None


def _use_kernel_cache() -> None:
    import numba

    numba.config.CACHE_DIR = cache_fallback(kernel_cache_dir(), "kernels are compiled")
    if "numba.np.arraymath" not in sys.modules:
        sys.meta_path.insert(0, _NoBlasProbe())


_use_kernel_cache()
