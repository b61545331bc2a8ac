"""Runs tests/blender under the bpy module, in one child process (``make test``).

Blender as a Python module can be imported once per process and must see a fresh
``BLENDER_USER_RESOURCES`` before it is imported, so the add-on tests run in a child
``python -m pytest tests/blender`` with ``RELRAY_BLENDER_HOST=bpy-module``. This file
reports each of the child's tests as one test here (names found by reading the test
files), with the child's failure text, so ``make test`` shows them one by one. The child
starts as soon as the suite is collected and these tests run last (conftest.py), so it
runs beside the rest of the suite: the two cores are both busy.

The extension zip is built first with Blender's extension CLI (from the bpy module),
without wheels: the child imports the core's dependencies from this venv. The user
directory lives under ``.cache/blender-test-user`` (wiped every run; a fixed path keeps
numba's compile cache valid between runs).
"""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent
REPO = HERE.parent.parent
RUNNER = Path(__file__).name

#: bpy 5.0.1 exists for CPython 3.11 only; there it is a dev dependency and must be present.
BPY_PYTHON = sys.version_info[:2] == (3, 11)


def inner_tests() -> list[str]:
    """'file::test' ids of the add-on tests (top-level test functions)."""
    ids = []
    for path in sorted(HERE.glob("test_*.py")):
        if path.name == RUNNER:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        ids += [f"{path.name}::{node.name}" for node in tree.body
                if isinstance(node, ast.FunctionDef) and node.name.startswith("test_")]
    return ids


#: The child's record in the session's stash (:func:`start_child`).
CHILD = pytest.StashKey[dict]()

#: The child's time limit, from its start.
CHILD_TIMEOUT_S = 3600


def start_child(config: pytest.Config) -> dict:
    """Build the zip and start the bpy-module child, once per session: conftest.py's
    ``pytest_collection_finish`` calls this as soon as the tests are collected, and puts
    this file's tests last, so the child (one core, mostly compiling) runs beside the
    rest of the suite; :func:`child_run` waits for it. The record's ``error`` says why
    no child could start."""
    if CHILD in config.stash:
        return config.stash[CHILD]
    import importlib.util

    record: dict = {"error": None, "proc": None}
    config.stash[CHILD] = record
    if importlib.util.find_spec("bpy") is None:
        record["error"] = ("the bpy module is missing: it is a dev dependency on Python 3.11 "
                           "(pip install -e '.[dev]', or make venv)")
        return record
    from relray.relblend import packaging as relray_packaging  # no bpy needed here

    work = Path(tempfile.mkdtemp(prefix="relray-bpy-child-"))
    zip_path = relray_packaging.build_test_zip(work / "relray-test.zip")
    user = REPO / ".cache" / "blender-test-user"
    shutil.rmtree(user, ignore_errors=True)
    user.mkdir(parents=True)
    env = dict(os.environ, RELRAY_BLENDER_HOST="bpy-module", RELRAY_TEST_ZIP=str(zip_path),
               BLENDER_USER_RESOURCES=str(user))
    env.setdefault("NUMBA_CACHE_DIR", str(REPO / ".cache" / "numba"))
    record.update(junit=work / "junit.xml", log=work / "child.log", started=time.monotonic())
    with open(record["log"], "w", encoding="utf-8") as out:
        record["proc"] = subprocess.Popen(
            [sys.executable, "-m", "pytest", str(HERE), "-q", "-rA", "-p", "no:cacheprovider",
             f"--junitxml={record['junit']}", "-o", "junit_family=xunit2", "-s"],
            cwd=REPO, env=env, stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT)
    return record


def stop_child(config: pytest.Config) -> None:
    """Kill a child still running when the session ends (``-x``, an interrupt)."""
    record = config.stash.get(CHILD, None)
    if record and record["proc"] is not None and record["proc"].poll() is None:
        record["proc"].kill()
        record["proc"].wait()


@pytest.fixture(scope="session")
def child_run(request) -> dict[str, tuple[str, str]]:
    """The add-on tests' results by id, from the bpy-module child (:func:`start_child`)."""
    record = start_child(request.config)
    if record["error"]:
        pytest.fail(record["error"])
    proc = record["proc"]
    try:
        proc.wait(timeout=max(1.0, CHILD_TIMEOUT_S - (time.monotonic() - record["started"])))
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    log = record["log"]
    text = log.read_text(encoding="utf-8", errors="replace")
    print(text[-6000:])
    junit = record["junit"]
    results: dict[str, tuple[str, str]] = {}
    if junit.exists():
        for case in ET.parse(junit).getroot().iter("testcase"):
            key = f"{Path(case.get('file') or case.get('classname').replace('.', '/')).stem}" \
                  f".py::{case.get('name')}"
            status, text_ = "passed", ""
            for tag in ("failure", "error", "skipped"):
                el = case.find(tag)
                if el is not None:
                    status = "skipped" if tag == "skipped" else "failed"
                    text_ = (el.get("message") or "") + "\n" + (el.text or "")
            results[key] = (status, text_)
    results["__exit__"] = (str(proc.returncode), f"child log: {log}\n" + text[-4000:])
    return results


@pytest.mark.skipif(not BPY_PYTHON, reason="bpy 5.0.1 is built for Python 3.11 only")
@pytest.mark.parametrize("test_id", inner_tests())
def test_under_bpy_module(child_run, test_id):
    cases = {k: v for k, v in child_run.items() if k == test_id or k.startswith(test_id + "[")}
    if not cases:
        pytest.fail(f"{test_id} did not run in the bpy-module child "
                    f"(exit {child_run['__exit__'][0]}):\n{child_run['__exit__'][1]}")
    failed = {k: text for k, (status, text) in cases.items() if status == "failed"}
    assert not failed, "\n\n".join(f"{k}:\n{text}" for k, text in failed.items())
    if all(status == "skipped" for status, _ in cases.values()):
        text = next(iter(cases.values()))[1].strip()
        pytest.skip(text.splitlines()[0] if text else "skipped")


@pytest.mark.skipif(not BPY_PYTHON, reason="bpy 5.0.1 is built for Python 3.11 only")
def test_child_exit_code(child_run):
    code, text = child_run["__exit__"]
    assert code == "0", text


#: bpy and what bpy itself imports: the only packages the platform-zip check may see.
BPY_ONLY = ("bpy", "numpy", "numpy.libs", "requests", "urllib3", "idna", "charset_normalizer",
            "certifi", "zstandard", "cython", "Cython")


@pytest.mark.skipif(not BPY_PYTHON, reason="bpy 5.0.1 is built for Python 3.11 only")
def test_platform_zip_renders_with_its_own_wheels(tmp_path):
    """`make extension`'s linux-x64 zip installs into a fresh user directory and renders
    with the wheels it bundles (the core's dependencies are hidden from the process)."""
    import importlib.util

    zips = sorted((REPO / "dist").glob("relray-*-linux_x64.zip"))
    if not zips:
        pytest.skip("dist/relray-*-linux_x64.zip not built: run `make extension` first "
                    "(.ci/run does)")
    spec = importlib.util.find_spec("bpy")
    site = Path(spec.origin).parent.parent
    only = tmp_path / "site"
    only.mkdir()
    for name in BPY_ONLY:
        if (site / name).exists():
            (only / name).symlink_to(site / name)
    user = REPO / ".cache" / "blender-zip-user"
    shutil.rmtree(user, ignore_errors=True)
    user.mkdir(parents=True)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user))
    env.pop("PYTHONPATH", None)
    env.setdefault("NUMBA_CACHE_DIR", str(REPO / ".cache" / "numba"))
    proc = subprocess.run([sys.executable, "-S", str(HERE / "platform_zip_check.py"),
                           str(zips[-1]), str(only)], capture_output=True, text=True,
                          env=env, timeout=900)
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]
    report = json.loads(proc.stdout.strip().splitlines()[-1])
    assert report["numba"].startswith(str(user)), report  # the zip's own numba
    assert report["shape"] == [32, 32, 4] and report["mean"] > 0.01
    print(f"platform zip: install {report['install_seconds']:.1f} s, "
          f"render {report['render_seconds']:.1f} s")
