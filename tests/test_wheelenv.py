"""The wheel's venv built ahead (tests/wheelenv.py, scripts/test.sh): a session takes it only if
it was built from the files the checkout holds now, and only one session takes it."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import wheelenv


def _prebuilt(folder, built_from: str):
    (folder / "dist").mkdir(parents=True)
    (folder / "venv").mkdir()
    wheel = folder / "dist" / "mexone-0.1.0-py3-none-any.whl"
    wheel.write_bytes(b"PK")
    (folder / "times.json").write_text(json.dumps({"build mexone wheel": 1.5}))
    (folder / wheelenv.FOR).write_text(built_from)
    return wheel


def test_one_session_takes_a_venv_built_from_these_files(tmp_path, monkeypatch):
    monkeypatch.setattr(wheelenv, "_TAKEN", {})
    monkeypatch.setattr(wheelenv, "TIMES", {})
    wheel = _prebuilt(tmp_path, wheelenv.files_hash(wheelenv.ROOT, wheelenv.checkout_files()))
    monkeypatch.setenv(wheelenv.PREBUILT_ENV, str(tmp_path))
    assert wheelenv.take_prebuilt() == wheel
    assert list(wheelenv._TAKEN.items()) == [(wheel, tmp_path / "venv")]  # make_venv's, in place
    assert wheelenv.TIMES == {"build mexone wheel (ahead)": 1.5}
    assert wheelenv.take_prebuilt() is None  # taken: the next session builds its own
    assert (tmp_path / wheelenv.TAKEN).is_file() and not (tmp_path / wheelenv.FOR).exists()


def test_a_venv_built_from_other_files_is_not_taken(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(wheelenv, "_TAKEN", {})
    files = wheelenv.checkout_files()
    _prebuilt(tmp_path, wheelenv.files_hash(wheelenv.ROOT, files[1:]))  # one file fewer
    monkeypatch.setenv(wheelenv.PREBUILT_ENV, str(tmp_path))
    assert wheelenv.take_prebuilt() is None
    assert "built from other files" in capsys.readouterr().out
    assert (tmp_path / wheelenv.FOR).is_file() and not wheelenv._TAKEN
    monkeypatch.setenv(wheelenv.PREBUILT_ENV, "")  # none asked for
    assert wheelenv.take_prebuilt() is None


def test_the_hash_sees_a_byte_and_an_executable_bit(tmp_path):
    (tmp_path / "a.py").write_text("x = 1\n")
    first = wheelenv.files_hash(tmp_path, ["a.py"])
    (tmp_path / "a.py").chmod(0o755)
    second = wheelenv.files_hash(tmp_path, ["a.py"])
    (tmp_path / "a.py").write_text("x = 2\n")
    assert len({first, second, wheelenv.files_hash(tmp_path, ["a.py"])}) == 3


def test_the_class_gets_the_wheel_once_built_and_none_if_its_build_failed(tmp_path, monkeypatch):
    """tests/hub/classroom.py's wheel: the prebuild's, published whole (wheel.txt) before its venv."""
    monkeypatch.setenv(wheelenv.PREBUILT_ENV, str(tmp_path))
    assert wheelenv.prebuilt_wheel(timeout=0.3) is None  # not built (yet): the class builds one
    wheelenv._publish(tmp_path / wheelenv.WHEEL, str(tmp_path / "mexone-0.1.0-py3-none-any.whl"))
    assert wheelenv.prebuilt_wheel() == tmp_path / "mexone-0.1.0-py3-none-any.whl"
    assert not list(tmp_path.glob("*.part"))
    (tmp_path / wheelenv.WHEEL).unlink()
    (tmp_path / wheelenv.FAILED).write_text("AssertionError: pip wheel failed")
    assert wheelenv.prebuilt_wheel() is None  # at once, not after the timeout
    monkeypatch.setenv(wheelenv.PREBUILT_ENV, "")
    assert wheelenv.prebuilt_wheel() is None


def test_the_class_waits_no_longer_once_the_build_has_ended_without_a_wheel(tmp_path, monkeypatch):
    """Killed before it could say why (no failed.txt): its process is gone, so is the wait."""
    monkeypatch.setenv(wheelenv.PREBUILT_ENV, str(tmp_path))
    polls: list[float] = []
    monkeypatch.setattr(wheelenv.time, "sleep", polls.append)
    ended = subprocess.Popen([sys.executable, "-c", "pass"])
    ended.wait()
    (tmp_path / wheelenv.PID).write_text(str(ended.pid))
    assert wheelenv.prebuilt_wheel(timeout=600) is None
    assert polls == []  # seen at the first look, not after the timeout
    (tmp_path / wheelenv.PID).write_text(str(os.getpid()))  # running: its wheel when published
    wheelenv._publish(tmp_path / wheelenv.WHEEL, str(tmp_path / "w.whl"))
    assert wheelenv.prebuilt_wheel(timeout=600) == tmp_path / "w.whl"
