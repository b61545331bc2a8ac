"""The memory limit a render is checked against, the geometry estimate, the thread cap."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from relray.core import resources
from relray.core.errors import UserError
from relray.core.resources import MemoryLimit
from relray.core.scene import job, shapes


def test_cgroup_limit_wins_when_smaller(tmp_path: Path) -> None:
    v2 = tmp_path / "memory.max"
    v2.write_text("1073741824\n")
    limit = resources.memory_limit((v2,))
    assert limit == MemoryLimit(2**30, f"the cgroup limit ({v2})")


@pytest.mark.parametrize("text", ["max\n", "9223372036854771712\n", "garbage", ""])
def test_unlimited_or_unreadable_cgroup_is_ignored(tmp_path: Path, text: str) -> None:
    v1 = tmp_path / "memory.limit_in_bytes"
    v1.write_text(text)
    limit = resources.memory_limit((v1, tmp_path / "absent"))
    assert limit is not None and "cgroup" not in limit.source


def test_rlimit_is_seen_by_a_process_started_under_ulimit() -> None:
    """``ulimit -v`` (RLIMIT_AS) below physical memory is the effective limit."""
    code = ("import resource; resource.setrlimit(resource.RLIMIT_AS, (2**33, 2**33)); "
            "from relray.core import resources; m = resources.memory_limit(()); "
            "print(m.bytes, m.source)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True).stdout.split(maxsplit=1)
    physical = resources.memory_limit(())
    assert physical is not None
    if physical.bytes <= 2**33:
        pytest.skip("this machine has less memory than the rlimit under test")
    assert int(out[0]) == 2**33 and "ulimit -v" in out[1]


def test_triangle_count_matches_tessellation() -> None:
    import numpy as np

    for s in range(4):
        tris, _ = shapes.sphere(np.zeros(3), 1.0, s)
        assert shapes.triangle_count("sphere", {"subdivisions": s}) == len(tris)
    assert shapes.triangle_count("box", {}) == len(shapes.box(np.zeros(3), 1.0, 0.0))


FORTY_SPHERES = "[[materials]]\nname = \"m\"\n" + "".join(
    f"[[objects]]\nshape = \"sphere\"\ncenter = [{3 * i}, 0, 0]\nradius = 1\n"
    f"subdivisions = {8 if i == 7 else 6}\nmaterial = \"m\"\n" for i in range(40))


def test_geometry_counts_against_the_limit(tmp_path: Path, monkeypatch) -> None:
    """2 kB of TOML asking for gigabytes of triangles is refused before tessellation,
    naming the object that asks for the most."""
    monkeypatch.setattr(resources, "memory_limit", lambda: MemoryLimit(2 * 2**30, "limit X"))
    path = tmp_path / "job.toml"
    path.write_text(FORTY_SPHERES)
    with pytest.raises(UserError) as err:
        job.load_job(path)
    assert err.value.key == "objects[7].subdivisions"
    assert "triangles" in str(err.value) and "limit X" in str(err.value)
    monkeypatch.setattr(resources, "memory_limit", lambda: MemoryLimit(64 * 2**30, "big"))
    assert len(job.load_job(path).scene.objects) == 40


def test_threads_capped_per_core(tmp_path: Path) -> None:
    most = resources.max_threads()
    assert most == resources.MAX_THREADS_PER_CORE * resources.usable_cores()
    path = tmp_path / "job.toml"
    for threads, ok in ((0, True), (most, True), (most + 1, False), (4000, False)):
        path.write_text(f"[render]\nthreads = {threads}\n[[materials]]\nname = \"m\"\n"
                        "[[objects]]\nshape = \"box\"\ncenter = [0, 0, 0]\nsize = 1\n"
                        "material = \"m\"\n")
        if ok:
            assert job.load_job(path).render.threads == threads
            continue
        with pytest.raises(UserError, match="per core") as err:
            job.load_job(path)
        assert err.value.key == "render.threads"
        with pytest.raises(UserError) as err:
            job.with_overrides(_ok_job(tmp_path), threads=threads)
        assert err.value.key == "--threads"


def _ok_job(tmp_path: Path) -> job.Job:
    path = tmp_path / "ok.toml"
    path.write_text("[[materials]]\nname = \"m\"\n[[objects]]\nshape = \"box\"\n"
                    "center = [0, 0, 0]\nsize = 1\nmaterial = \"m\"\n")
    return job.load_job(path)


def test_loaded_meshes_count_against_the_limit(tmp_path: Path, monkeypatch) -> None:
    """A mesh's triangles are unknown until its file is read: they are checked then,
    before the accelerator is built, naming the file's key."""
    from relray.core.scene.geometry import build_scene

    obj = "".join(f"v {i} {i * i % 7} {i % 3}\n" for i in range(30))
    obj += "".join(f"f {i + 1} {i + 2} {i + 3}\n" for i in range(28))
    (tmp_path / "m.obj").write_text(obj)
    path = tmp_path / "job.toml"
    path.write_text('[render]\nwidth = 8\nheight = 8\n[[materials]]\nname = "m"\n'
                    '[[objects]]\nshape = "mesh"\nfile = "m.obj"\nmaterial = "m"\n')
    film = 1000  # a tiny film (as if the fixed cost were not there): the mesh dominates
    monkeypatch.setattr(resources, "render_memory_bytes", lambda *a: film)
    monkeypatch.setattr(resources, "memory_limit",
                        lambda: MemoryLimit(film + resources.geometry_memory_bytes(10), "X"))
    j = job.load_job(path)  # the film fits, the mesh is not counted yet
    with pytest.raises(UserError, match="28 triangles.*more than X") as err:
        build_scene(j)
    assert err.value.key == "objects[0].file"
    monkeypatch.setattr(resources, "memory_limit",
                        lambda: MemoryLimit(film + resources.geometry_memory_bytes(28), "X"))
    assert len(build_scene(j).triangles) > 0
