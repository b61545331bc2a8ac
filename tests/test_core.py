"""The core package's set-up: the numba kernel cache keyed by the kernels' source."""

from pathlib import Path

import numba

import relray.core as core


def test_kernel_digest_follows_kernel_modules_only(tmp_path):
    (tmp_path / "a.py").write_text("from numba import njit\n")
    (tmp_path / "b.py").write_text("x = 1\n")
    d0 = core.kernel_source_digest(tmp_path)
    (tmp_path / "b.py").write_text("x = 2\n")          # no kernels: same cache
    assert core.kernel_source_digest(tmp_path) == d0
    (tmp_path / "a.py").write_text("from numba import njit  # changed\n")
    assert core.kernel_source_digest(tmp_path) != d0


def test_kernel_cache_dir_is_keyed_and_used():
    here = Path(core.__file__).parent
    key = "relray-" + core.kernel_source_digest(here)[:16]
    assert core.kernel_cache_dir({"NUMBA_CACHE_DIR": "/x/y"}) == str(Path("/x/y", key))
    home = core.kernel_cache_dir({"XDG_CACHE_HOME": "/c"})
    assert home == str(Path("/c", "relray", "numba", key))
    assert Path(numba.config.CACHE_DIR).name == key


def test_an_unusable_cache_folder_falls_back_with_a_warning(tmp_path, caplog):
    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    assert core.writable_dir(str(tmp_path / "new" / "dir")) is None  # created
    assert core.writable_dir(str(blocker / "sub")) is not None
    with caplog.at_level("WARNING", logger="relray"):
        got = core.cache_fallback(str(blocker / "sub"), "kernels are compiled")
    assert got != str(blocker / "sub") and core.writable_dir(got) is None
    assert "cannot use the cache folder" in caplog.text and str(blocker) in caplog.text
    assert core.cache_fallback(str(tmp_path / "ok"), "x") == str(tmp_path / "ok")


def test_the_command_runs_with_an_unusable_cache_folder(tmp_path):
    """XDG_CACHE_HOME under a file (so even root cannot create it): one warning line,
    then the command works (exit 0), without a traceback. (``info``: a render would
    compile every kernel without a cache, ~10 s.)"""
    import os
    import subprocess
    import sys

    blocker = tmp_path / "a-file"
    blocker.write_text("x")
    job = tmp_path / "job.toml"
    job.write_text('[render]\nwidth = 8\nheight = 6\nspp = 1\n[[materials]]\nname = "m"\n'
                   'base_color = [0.5, 0.2, 0.1]\n[[objects]]\nshape = "box"\n'
                   'center = [0, 0, 1]\nsize = 1\nmaterial = "m"\n')
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_CACHE_DIR"}
    env.update(XDG_CACHE_HOME=str(blocker), RELRAY_DISK_CACHE="1")
    r = subprocess.run([sys.executable, "-m", "relray", "info", str(job)],
                       capture_output=True, text=True, timeout=600, env=env)
    assert r.returncode == 0, r.stderr
    assert "Traceback" not in r.stderr
    warnings = [line for line in r.stderr.splitlines() if "warning" in line]
    assert any("cannot use the cache folder" in w for w in warnings), r.stderr
    assert all(w.startswith("relray: warning: ") for w in warnings), r.stderr


_PROBE = """
import sys
{before}
import numpy as np
import relray.core
from numba import njit

@njit
def twice(a):
    return 2.0 * a

twice(1.0)  # numba loads its NumPy support (and probes for BLAS) here
import numba.np.arraymath as am
loaded = "scipy.linalg" in sys.modules

@njit
def dot(a, b):
    return np.dot(a, b)

import scipy.linalg
print(loaded, am._HAVE_BLAS, dot(np.arange(3.0), np.ones(3)), scipy.linalg.norm([3.0, 4.0]))
"""


def _probe(before: str) -> str:
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _PROBE.format(before=before)],
                         capture_output=True, text=True, check=True, timeout=600)
    return out.stdout.split()


def test_numbas_blas_probe_does_not_import_scipy_and_blas_still_works():
    """numba's first load probes for BLAS by importing scipy.linalg (0.13 s of the first
    image): relray answers it "none" without the import; a kernel that calls BLAS
    (np.dot) still compiles and runs, and scipy.linalg imports as usual afterwards."""
    assert _probe("") == ["False", "False", "3.0", "5.0"]


def test_the_probe_is_left_alone_where_scipy_linalg_is_already_loaded():
    assert _probe("import scipy.linalg") == ["True", "True", "3.0", "5.0"]
