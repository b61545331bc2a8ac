"""The render kernels compiled in a child process when the add-on is enabled."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from conftest import ext_module

#: Renders the warm-up frame in a fresh process and counts numba's cache hits and misses
#: over every kernel of the core (a miss is a kernel compiled instead of loaded).
PROBE = """
import json
warmup.warm()
from numba.core.registry import CPUDispatcher
hits = misses = 0
for mod in [m for k, m in list(sys.modules.items()) if k.startswith({name!r} + ".core")]:
    for obj in vars(mod).values():
        if isinstance(obj, CPUDispatcher):
            hits += sum(obj.stats.cache_hits.values())
            misses += sum(obj.stats.cache_misses.values())
print(json.dumps({{"hits": hits, "misses": misses}}))
"""


def test_the_warm_up_fills_the_kernel_cache_a_render_reads(ext, tmp_path, monkeypatch):
    """Started against an empty kernel cache, the child compiles every kernel into it; a
    new process importing the core under Blender's package name (whose kernel types the
    cache is keyed by) and rendering a frame then loads them all and compiles none."""
    warmup = ext_module("relblend.warmup")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path / "numba"))
    assert warmup.start(force=True)
    assert warmup.running() and not warmup.start(force=True)  # one at a time
    assert warmup.wait()
    code, seconds = warmup.result()
    assert code == 0 and seconds > 0.0
    assert list((tmp_path / "numba").rglob("*.nbi")), "no kernel was cached"
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(p for p in sys.path if p))
    probe = subprocess.run(
        [warmup.python_executable(), "-c",
         warmup.import_code() + PROBE.format(name=warmup.PACKAGE)],
        env=env, capture_output=True, text=True, timeout=600)
    assert probe.returncode == 0, probe.stderr[-2000:]
    stats = json.loads(probe.stdout.strip().splitlines()[-1])
    assert stats["hits"] > 0 and stats["misses"] == 0, stats


def test_a_failing_warm_up_is_reported_not_raised(ext, monkeypatch, capsys):
    warmup = ext_module("relblend.warmup")
    monkeypatch.setattr(warmup, "command", lambda: [warmup.python_executable(), "-c",
                                                    "import sys; sys.exit('no numpy here')"])
    assert warmup.start(force=True)
    assert warmup.wait()
    assert warmup.result()[0] == 1
    assert "the kernel warm-up failed (exit 1)" in capsys.readouterr().out
