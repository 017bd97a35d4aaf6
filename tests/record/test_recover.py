"""Recovering killed recordings: every prefix of a bag (what a kill at that moment leaves) gives a
valid bag to both independent readers, with every message of the complete chunks in it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader

from mexone.lab import Lab
from mexone.record.bag import FLUSH_PERIOD, BagRecorder, active_path
from mexone.record.recover import is_complete, recover

SECONDS = 1.0


def mexone(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "mexone", *args], capture_output=True, text=True,
                          cwd=cwd, timeout=120)


@pytest.fixture(scope="module", params=[".mcap", ".bag"])
def bag(request, tmp_path_factory) -> tuple[Path, int]:
    path = tmp_path_factory.mktemp("complete") / f"run{request.param}"
    lab = Lab.create()
    recorder = BagRecorder(lab, path)
    lab.sim.run(SECONDS)
    recorder.close()
    return path, sum(recorder.counts.values())


def stamps(path: Path) -> list[int]:
    with AnyReader([path]) as reader:
        found = [stamp for _, stamp, _ in reader.messages()]
    if path.suffix == ".mcap":
        with path.open("rb") as handle:
            assert len(list(make_reader(handle).iter_messages())) == len(found)
    return found


def test_every_prefix_recovers_to_a_valid_bag(bag, tmp_path):
    path, total = bag
    data = path.read_bytes()
    counts = []
    for k, cut in enumerate(range(0, len(data), max(1, len(data) // 60))):
        prefix = tmp_path / f"cut{k}{path.suffix}.active"
        prefix.write_bytes(data[:cut] if cut else data[:16])
        out = tmp_path / f"out{k}{path.suffix}"
        found = recover(prefix, out)
        assert is_complete(out)
        got = stamps(out)
        assert found.messages == len(got)
        assert got == sorted(got) and (not got or got[0] <= 1_000_000)  # from the start, in order
        counts.append(found.messages)
    assert counts == sorted(counts)  # a longer prefix never recovers less
    assert counts[-1] > 0.8 * total  # the last cut loses at most the last chunk
    # a kill loses at most FLUSH_PERIOD of sim time: the final chunks are that long
    assert (total - counts[-1]) <= total * (FLUSH_PERIOD + 0.05) / SECONDS


def test_recover_cli_rebuilds_a_killed_recording(bag, tmp_path):
    path, total = bag
    data = path.read_bytes()
    killed = tmp_path / path.name
    active_path(killed).write_bytes(data[: len(data) * 3 // 4])
    out = mexone("record", "--recover", str(killed))
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("recovered ") and f"into {killed}" in out.stdout
    count = int(out.stdout.split()[1])
    assert 0 < count < total and len(stamps(killed)) == count
    assert not active_path(killed).exists()
    again = mexone("record", "--recover", str(killed))
    assert (again.returncode, again.stdout) == (0, f"{killed} is complete; nothing to recover\n")


def test_a_truncated_bag_is_repaired_in_place_keeping_the_original(bag, tmp_path):
    path, _ = bag
    data = path.read_bytes()
    cut = tmp_path / path.name
    cut.write_bytes(data[: len(data) // 2])
    plot = mexone("plot", str(cut), "-o", str(tmp_path / "p.csv"))
    assert plot.returncode == 0, plot.stderr
    note = plot.stderr.strip()
    assert note.startswith(f"mexone: warning: {cut}: an unfinished recording") and "\n" not in note
    assert f"mexone record --recover {cut}" in note
    out = mexone("record", "--recover", str(cut))
    assert out.returncode == 0, out.stderr
    backup = tmp_path / f"run.orig{path.suffix}"
    assert backup.read_bytes() == data[: len(data) // 2]
    assert int(out.stdout.split()[1]) == len(stamps(cut)) > 0
    refused = mexone("record", "--recover", str(tmp_path / "other") + path.suffix)
    assert refused.returncode == 2 and "no such file" in refused.stderr


def test_plot_reads_a_killed_recording_with_a_hint(bag, tmp_path):
    path, _ = bag
    killed = tmp_path / path.name
    active_path(killed).write_bytes(path.read_bytes()[: len(path.read_bytes()) * 3 // 4])
    out = mexone("plot", str(killed), "-o", str(tmp_path / "p.csv"))
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("wrote ") and "an unfinished recording" in out.stderr
    assert active_path(killed).exists() and not killed.exists()  # plot repairs nothing on disk


def test_force_replaces_an_old_bag_only_once_the_new_one_is_complete(tmp_path):
    path = tmp_path / "run.mcap"
    path.write_bytes(b"the user's old bag")
    lab = Lab.create()
    recorder = BagRecorder(lab, path, force=True)
    lab.sim.run(0.3)
    assert path.read_bytes() == b"the user's old bag"  # still there while recording
    assert active_path(path).exists()
    recorder.close()
    assert is_complete(path) and not active_path(path).exists()
