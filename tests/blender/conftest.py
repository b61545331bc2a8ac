"""tests/blender: the add-on's tests, run inside Blender.

The same test files run in two hosts, chosen by ``RELRAY_BLENDER_HOST``:

* ``bpy-module``: ``make test`` runs ``test_bpy_module.py`` in the ordinary pytest
  process; it builds the extension zip (without wheels: the venv has the
  dependencies) and runs these files in ONE child process that imports the bpy module
  (Blender as a module can be imported once per process, and a fresh
  ``BLENDER_USER_RESOURCES`` must be set before that).
* ``blender``: ``make test-blender`` runs them under a real ``blender -b`` binary
  (tests/blender/real_blender.sh, Debian trixie's Blender 4.3 in a chroot).

Without ``RELRAY_BLENDER_HOST`` only ``test_bpy_module.py`` is collected. With it, the
session fixture :func:`installed` installs ``RELRAY_TEST_ZIP`` into the user
repository of the fresh user directory with ``bpy.ops.extensions.package_install_files``
and enables it; every test gets an empty scene with the engine set.
"""

from __future__ import annotations

import os
import sys
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path

import pytest

HOST = os.environ.get("RELRAY_BLENDER_HOST", "")
HERE = Path(__file__).resolve().parent
RUNNER = "test_bpy_module.py"

if HOST:
    collect_ignore = [RUNNER]
else:
    collect_ignore = [p.name for p in HERE.glob("test_*.py") if p.name != RUNNER]

    def _runner_items(items: list) -> list:
        return [i for i in items if i.path.name == RUNNER]

    def pytest_collection_modifyitems(session, config, items):
        """The bpy-module runner's tests last (its child runs beside the others)."""
        late = _runner_items(items)
        items[:] = [i for i in items if i.path.name != RUNNER] + late

    def pytest_collection_finish(session):
        """Start the bpy-module child now when its tests are selected
        (``test_bpy_module.start_child``)."""
        if session.config.option.collectonly or not any(
                i.name.startswith(("test_under_bpy_module", "test_child_exit_code"))
                for i in _runner_items(session.items)):
            return
        runner = sys.modules.get(RUNNER[:-3])
        if runner is not None and runner.BPY_PYTHON:
            runner.start_child(session.config)

    def pytest_sessionfinish(session):
        runner = sys.modules.get(RUNNER[:-3])
        if runner is not None:
            runner.stop_child(session.config)

EXT_MODULE = "bl_ext.user_default.relray"


@dataclass
class Installed:
    """The installed extension."""

    module_name: str
    path: Path
    seconds: float
    user_dir: Path


def ext_module(name: str = ""):
    """A module of the installed extension: ``ext_module("relblend.engine")``."""
    import importlib

    return importlib.import_module(f"{EXT_MODULE}.{name}" if name else EXT_MODULE)


def _restore_mtimes(zip_path: Path, root: Path) -> None:
    """Give installed files the zip's timestamps (stable numba cache keys across runs)."""
    with zipfile.ZipFile(zip_path) as zf:
        for info in zf.infolist():
            target = root / info.filename
            if target.is_file():
                stamp = time.mktime((*info.date_time, 0, 0, -1))
                os.utime(target, (stamp, stamp))


if HOST:
    sys.path.insert(0, str(HERE))

    @pytest.fixture(scope="session")
    def installed() -> Installed:
        """Install and enable the extension zip in the fresh user directory, once."""
        import bpy

        zip_path = Path(os.environ["RELRAY_TEST_ZIP"])
        user_dir = Path(os.environ["BLENDER_USER_RESOURCES"])
        assert zip_path.is_file(), f"RELRAY_TEST_ZIP={zip_path} does not exist"
        ext_root = Path(bpy.utils.user_resource("EXTENSIONS"))
        assert ext_root.is_relative_to(user_dir), (ext_root, user_dir)
        target = ext_root / "user_default" / "relray"
        assert not target.exists(), f"the user directory is not fresh: {target} exists"
        t0 = time.perf_counter()
        result = bpy.ops.extensions.package_install_files(
            filepath=str(zip_path), repo="user_default", enable_on_install=False)
        assert result == {"FINISHED"}, result
        assert target.is_dir()
        _restore_mtimes(zip_path, target)  # before the first import
        assert bpy.ops.preferences.addon_enable(module=EXT_MODULE) == {"FINISHED"}
        seconds = time.perf_counter() - t0
        assert EXT_MODULE in bpy.context.preferences.addons.keys()
        return Installed(EXT_MODULE, target, seconds, user_dir)

    @pytest.fixture
    def ext(installed):
        """The enabled extension's top module (re-enabled if a test disabled it)."""
        import bpy

        if EXT_MODULE not in bpy.context.preferences.addons.keys():
            bpy.ops.preferences.addon_enable(module=EXT_MODULE)
        return ext_module()

    @pytest.fixture
    def engine(ext):
        """The engine module, its results cleared and kept for up to 8 frames."""
        mod = ext_module("relblend.engine")
        mod.RESULTS.clear()
        mod.RESULTS_KEPT = 8
        return mod

    @pytest.fixture
    def cornell(ext):
        """The Cornell box (48×48, 16 spp), engine RELRAY."""
        import scenes

        return scenes.build_cornell()
