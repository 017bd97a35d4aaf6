"""Output files: replaced only with --force, never half-written, no stale results left behind."""

from __future__ import annotations

import json

import pytest

from mexone.cli.sweep import OUTPUTS, _prepare
from mexone.errors import InputError, OutputExistsError
from mexone.files import move_into_place, replacing, temporary_path, write_text


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "out.csv"
    path.write_text("old")
    with pytest.raises(RuntimeError), replacing(path, True) as temporary:
        temporary.write_text("half")
        raise RuntimeError("the plot failed")
    assert path.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.csv"]


def test_replacing_keeps_the_extension_writers_pick_the_format_by(tmp_path):
    with replacing(tmp_path / "video.mp4", False) as temporary:
        assert temporary.suffix == ".mp4" and temporary.parent == tmp_path
        temporary.write_bytes(b"frames")
    assert (tmp_path / "video.mp4").read_bytes() == b"frames"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["video.mp4"]


def test_a_file_that_appears_meanwhile_is_not_replaced_without_force(tmp_path):
    path = tmp_path / "out.png"
    temporary = temporary_path(path)
    temporary.write_text("new")
    path.write_text("someone else's")
    with pytest.raises(OutputExistsError):
        move_into_place(temporary, path, False)
    assert path.read_text() == "someone else's" and temporary.read_text() == "new"
    move_into_place(temporary, path, True)
    assert path.read_text() == "new" and not temporary.exists()


def test_refusals_come_before_any_work(tmp_path):
    (tmp_path / "folder.yaml").mkdir()
    with pytest.raises(InputError, match="is a folder"):
        write_text(tmp_path / "folder.yaml", "x", True)
    with pytest.raises(InputError, match="output folder does not exist"):
        write_text(tmp_path / "nowhere" / "x.yaml", "x", True)
    (tmp_path / "mine.yaml").write_text("mine")
    with pytest.raises(OutputExistsError, match="pass --force"):
        write_text(tmp_path / "mine.yaml", "x", False)
    assert (tmp_path / "mine.yaml").read_text() == "mine"


DEFINITION = {"spec": {"joints": ["l_elbow"]}, "ranges": {"p": [10.0]}, "random": None, "seed": 0}


@pytest.mark.parametrize("name", OUTPUTS)
def test_sweep_refuses_a_folder_holding_any_of_its_files(tmp_path, name):
    (tmp_path / name).write_text("mine")
    with pytest.raises(OutputExistsError, match=f"holds a sweep already \\({name}\\)"):
        _prepare(tmp_path, DEFINITION, resume=False, force=False)
    assert (tmp_path / name).read_text() == "mine"


def test_sweep_force_starts_over_without_stale_results(tmp_path):
    for name in OUTPUTS:
        (tmp_path / name).write_text("old")
    _prepare(tmp_path, DEFINITION, resume=False, force=True)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sweep.json"]
    assert json.loads((tmp_path / "sweep.json").read_text()) == DEFINITION


def test_sweep_resume_needs_the_same_definition(tmp_path):
    _prepare(tmp_path, DEFINITION, resume=False, force=False)
    (tmp_path / "sweep.csv").write_text("index,p\n0,10\n")
    _prepare(tmp_path, DEFINITION, resume=True, force=False)  # same sweep: continues
    assert (tmp_path / "sweep.csv").read_text() == "index,p\n0,10\n"
    (tmp_path / "sweep.json").write_text("{not json")
    with pytest.raises(InputError, match="defined differently"):
        _prepare(tmp_path, DEFINITION, resume=True, force=False)
