"""Input files: regular files only, never a hang, one UserError naming key and job file."""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path

import pytest

from relray.core import files
from relray.core.errors import UserError

JOB = Path("/jobs/job.toml")


def refused(path: Path, match: str, **kw) -> UserError:
    t0 = time.perf_counter()
    with pytest.raises(UserError, match=match) as err:
        files.read_input(path, "scene.file", JOB, **kw)
    assert time.perf_counter() - t0 < 5.0  # refused, not waited on
    assert err.value.key == "scene.file" and err.value.file == str(JOB)
    return err.value


def test_regular_file_is_read(tmp_path: Path) -> None:
    (tmp_path / "a.bin").write_bytes(b"abc")
    assert files.read_input(tmp_path / "a.bin", "k", JOB) == b"abc"
    assert files.is_regular_file(tmp_path / "a.bin")


def test_fifo_is_refused_without_waiting_for_a_writer(tmp_path: Path) -> None:
    os.mkfifo(tmp_path / "p")
    refused(tmp_path / "p", "not a regular file")
    assert not files.is_regular_file(tmp_path / "p")


def test_devices_sockets_and_directories_are_refused(tmp_path: Path) -> None:
    refused(Path("/dev/zero"), "not a regular file")
    refused(Path("/dev/null"), "not a regular file")
    refused(tmp_path, "directory")
    sock = socket.socket(socket.AF_UNIX)
    try:
        sock.bind(str(tmp_path / "s"))
        refused(tmp_path / "s", "cannot read|not a regular file")
    finally:
        sock.close()


def test_missing_file_symlink_loop_and_nul_byte(tmp_path: Path) -> None:
    refused(tmp_path / "absent", "file not found")
    os.symlink(tmp_path / "b", tmp_path / "a")
    os.symlink(tmp_path / "a", tmp_path / "b")
    refused(tmp_path / "a", "symlink loop")
    with pytest.raises(UserError, match="symlink loop"):
        files.resolve_path("a", tmp_path, "scene.file", JOB)
    with pytest.raises(UserError, match="NUL byte") as err:
        files.resolve_path("x\0y.glb", tmp_path, "scene.file", JOB)
    assert err.value.key == "scene.file"
    refused(tmp_path / "x\0y", "NUL byte")


def test_size_limit(tmp_path: Path) -> None:
    (tmp_path / "big").write_bytes(b"x" * 101)
    refused(tmp_path / "big", "too large", limit=100)
    assert files.read_input(tmp_path / "big", "k", JOB, limit=101) == b"x" * 101


def test_unreadable_file_names_the_reason(tmp_path: Path, monkeypatch) -> None:
    target = tmp_path / "secret"
    target.write_bytes(b"x")
    real_open = os.open

    def deny(path, *a, **k):
        if Path(path) == target:
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, *a, **k)

    monkeypatch.setattr(os, "open", deny)
    refused(target, "Permission denied")
