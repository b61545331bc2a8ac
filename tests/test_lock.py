"""The lock file: every machine installs exactly what CI tested (README, "Installs").

``requirements.lock`` pins every distribution of the runtime, the dev extra and the
build tools, with the hashes of their files; ``make venv`` installs it with
``--require-hashes --no-deps`` and then relray itself without dependencies.
"""

from __future__ import annotations

import re
import tomllib
from importlib import metadata
from pathlib import Path

from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

ROOT = Path(__file__).resolve().parents[1]
LOCK = ROOT / "requirements.lock"


def locked() -> dict[str, tuple[str, list[str]]]:
    """name -> (version, hashes) from requirements.lock."""
    pins: dict[str, tuple[str, list[str]]] = {}
    for block in re.split(r"\n(?=[A-Za-z0-9])", LOCK.read_text()):
        m = re.match(r"([A-Za-z0-9_.\-\[\]]+)==([^\s\\;]+)", block)
        if m:
            name = canonicalize_name(m.group(1).split("[")[0])
            pins[name] = (m.group(2), re.findall(r"--hash=sha256:([0-9a-f]{64})", block))
    return pins


def declared() -> list[Requirement]:
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    reqs = [Requirement(r) for r in project["dependencies"]]
    reqs += [Requirement(r) for r in project["optional-dependencies"]["dev"]]
    build = (ROOT / "requirements-build.in").read_text().splitlines()
    reqs += [Requirement(r) for r in build if r.strip() and not r.startswith("#")]
    return [r for r in reqs if r.marker is None or r.marker.evaluate({"python_version": "3.11"})]


def test_lock_parses_and_every_pin_has_hashes():
    pins = locked()
    assert len(pins) >= 40, "the lock lists the whole environment, dependencies included"
    for name, (_, hashes) in pins.items():
        assert hashes, f"{name} has no --hash in requirements.lock"


def test_every_declared_requirement_is_locked_within_its_range():
    pins = locked()
    for req in declared():
        name = canonicalize_name(req.name)
        assert name in pins, f"{req} (pyproject.toml) is missing from the lock: run make lock"
        version = pins[name][0]
        assert req.specifier.contains(version, prereleases=True), (
            f"the lock pins {name}=={version}, outside {req}: run make lock")


def test_this_environment_is_the_lock():
    """The venv running the tests holds exactly the locked versions (make venv did it)."""
    wrong = []
    for name, (version, _) in locked().items():
        try:
            have = metadata.version(name)
        except metadata.PackageNotFoundError:
            wrong.append(f"{name} not installed (locked {version})")
            continue
        if canonicalize_name(have) != canonicalize_name(version) and have != version:
            wrong.append(f"{name} {have} installed, {version} locked")
    assert not wrong, "; ".join(wrong)


def test_make_installs_from_the_lock_with_hashes():
    make = (ROOT / "Makefile").read_text()
    assert "--require-hashes --no-deps -r requirements.lock" in make
    assert "--no-deps --no-build-isolation -e ." in make
