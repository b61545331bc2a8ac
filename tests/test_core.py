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
