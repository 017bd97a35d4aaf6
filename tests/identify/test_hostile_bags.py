"""Hostile recordings (issue 30): a real Mex-One recording, mutated the way a broken driver, a
careless student or an attacker would -- NaN, inf and huge values, names dropped or repeated,
stamps and receive times running backwards, bytes cut or swapped -- through `mexone identify`,
`mexone plot` and `mexone record --recover`. Each gives one line naming the bag and exit 2, or a
fit with a note saying what was left out; never a traceback, a NaN fit or MuJoCo's warnings.

The found cases are fixed examples; the property tests draw mutations with hypothesis
(derandomized, bounded). A longer run: `pytest tests/identify/test_hostile_bags.py -m fuzz
--hypothesis-seed=N` with MEXONE_FUZZ_EXAMPLES=500 in the environment."""

from __future__ import annotations

import copy
import logging
import math
import os
import shutil
import subprocess
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from helpers import fuzz

sys.path.insert(0, str(Path(__file__).parent))
import bagtools  # noqa: E402
import hostile  # noqa: E402
from hostile import COMMAND, STATE, TF  # noqa: E402

from mexone import signals  # noqa: E402
from mexone.cli import main  # noqa: E402
from mexone.errors import MexoneError  # noqa: E402
from mexone.identify.session import Options, identify  # noqa: E402
from mexone.record.reader import read_bag, read_joint_series  # noqa: E402
from mexone.record.recover import bag_kind, recover  # noqa: E402

pytestmark = pytest.mark.fuzz
FIT = ["--params", "damping", "--joints", "l_elbow", "--max-iterations", "1", "--threads", "1"]


@pytest.fixture(scope="module")
def records(tmp_path_factory) -> list[hostile.Record]:
    """1 s of a Mex-One on a stand running the excitation routine, as editable records: every
    joint's state, three joints' commands (the others hold their start), the base's /tf."""
    folder = tmp_path_factory.mktemp("hostile")
    bag = bagtools.record(folder / "real.mcap", None, None, "fixed", 1.1)
    return hostile.records_of(bag, 1.0, commanded=("l_elbow", "l_knee", "waist_yaw"))


def _bag(records, folder: Path, name: str, mutate=None) -> Path:
    records = copy.deepcopy(records)
    if mutate is not None:
        mutate(records)
    return hostile.write(records, folder / name)


def _states(records):
    return [r for r in records if r.msgtype == STATE]


def run_cli(argv: list[str], capfd, monkeypatch) -> tuple[int, str, str]:
    """`mexone ...` in this process; stdout and stderr as the file descriptors saw them (MuJoCo
    prints its warnings from C)."""
    monkeypatch.setattr(signals, "stop_on_signals", lambda: None)  # pytest keeps its handlers
    logging.getLogger("mexone").handlers.clear()
    capfd.readouterr()
    code = main(argv)
    captured = capfd.readouterr()
    return code, captured.out, captured.err


def _refused(code: int, out: str, err: str, bag: Path, *expected: str) -> None:
    """One line naming the bag, exit 2, nothing of numpy's or MuJoCo's."""
    assert code == 2, (out, err)
    assert err.startswith(f"mexone: {bag}: ") and err.count("\n") == 1, err
    for text in expected:
        assert text in err, err
    for leak in ("Traceback", "WARNING", "np.float64", "gains too high", "RuntimeWarning"):
        assert leak not in out + err, out + err


def _identify(bag: Path, tmp_path: Path, capfd, monkeypatch, *extra: str):
    out = tmp_path / f"out-{bag.stem}"
    return run_cli(["identify", str(bag), *FIT, "-o", str(out), *extra], capfd, monkeypatch)


# ----- the found cases (each failed before issue 30) ---------------------------------------------

def _every_state(change):
    def mutate(records):
        for r in _states(records):
            change(r)
    return mutate


def _set(field, value):
    return lambda r: setattr(r, field, value(r) if callable(value) else value)


REFUSED = {
    "all_nan": (_every_state(_set("position", lambda r: [math.nan] * len(r.names))),
                "every joint position in the bag is NaN or inf"),
    "names_no_positions": (_every_state(lambda r: (setattr(r, "position", []),
                                                   setattr(r, "velocity", []),
                                                   setattr(r, "effort", []))),
                           "JointStates carry names but no positions"),
    "fewer_positions": (_every_state(_set("position", lambda r: r.position[:-1])),
                        "has 21 names but 20 position values"),
    "one_name_21_times": (_every_state(_set("names", lambda r: ["l_elbow"] * len(r.names))),
                          "names l_elbow 21 times"),
    "huge_positions": (_every_state(_set("position", lambda r: [1e300] * len(r.names))),
                       "message 1 on /mex_rb/joint_states", "position 1e+300"),
    "nan_translation": (lambda rs: [setattr(r, "xyz", [math.nan, 0.0, 0.9]) for r in rs
                                    if r.msgtype == TF], "/tf of pelvis", "translation (NaN"),
    "zero_quaternion": (lambda rs: [setattr(r, "quat", [0.0] * 4) for r in rs if r.msgtype == TF],
                        "/tf of pelvis", "rotation (0, 0, 0, 0) is not a quaternion"),
    "huge_quaternion": (lambda rs: [setattr(r, "quat", [1e300, 0.0, 0.0, 0.0]) for r in rs
                                    if r.msgtype == TF], "rotation (1e+300, 0, 0, 0)"),
    "stamps_backwards": (lambda rs: [setattr(r, "stamp", s) for r, s in
                                     zip(_states(rs), [r.stamp for r in _states(rs)][::-1],
                                         strict=True)],
                         "header stamps on /mex_rb/joint_states run backwards in the order the "
                         "bag received them: message 3 is stamped 0.96 s, after message 1 at 1 s"),
    "receive_times_backwards": (lambda rs: [setattr(r, "t", t) for r, t in
                                            zip(rs, [r.t for r in rs][::-1], strict=True)],
                                "header stamps on /mex_rb/joint_states run backwards in the order "
                                "the bag received them"),
    "commands_nan": (lambda rs: [setattr(r, "value", math.nan) for r in rs if r.msgtype == COMMAND],
                     "every command for the controllers is NaN or inf"),
    "commands_inf": (lambda rs: [setattr(r, "value", math.inf) for r in rs if r.msgtype == COMMAND],
                     "every command for the controllers is NaN or inf"),
    "elbow_beyond_limits": (_every_state(lambda r: r.position.__setitem__(
        r.names.index("l_elbow"), 100.0)), "l_elbow starts at 100, beyond its limits"),
    "one_stamp_far_ahead": (lambda rs: setattr(_states(rs)[-1], "stamp", 1e6),
                            "a gap of 999999 s in the joint states"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_found_case_is_one_line(records, tmp_path, capfd, monkeypatch, case):
    mutate, *expected = REFUSED[case]
    bag = _bag(records, tmp_path, f"{case}.bag", mutate)
    monkeypatch.chdir(tmp_path)  # MuJoCo would write MUJOCO_LOG.TXT here
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        _refused(*_identify(bag, tmp_path, capfd, monkeypatch), bag, *expected)
    assert not [w for w in caught if issubclass(w.category, RuntimeWarning)]
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()
    assert not (tmp_path / f"out-{bag.stem}").exists()


def test_one_joint_always_nan_fits_the_others_with_a_note(records, tmp_path, capfd, monkeypatch):
    bag = _bag(records, tmp_path, "elbow_nan.bag", _every_state(
        lambda r: r.position.__setitem__(r.names.index("l_elbow"), math.nan)))
    _refused(*_identify(bag, tmp_path, capfd, monkeypatch), bag,
             "no finite position of l_elbow (all NaN, inf or missing)")
    code, out, err = run_cli(["identify", str(bag), "--params", "damping", "--joints", "l_knee",
                              "--max-iterations", "1", "-o", str(tmp_path / "knee"), "--json"],
                             capfd, monkeypatch)
    assert code == 0, err
    assert "every position of l_elbow is NaN or inf; not compared" in err and "Traceback" not in err
    assert all(line.startswith("mexone: ") for line in err.splitlines()), err


def test_params_are_checked_before_the_bag(records, tmp_path, capfd, monkeypatch):
    bag = _bag(records, tmp_path, "fine.bag")
    for params, expected in (("bogus", "--params: unknown parameter bogus"),
                             (",", "--params names no parameter to fit")):
        code, out, err = run_cli(["identify", str(bag), "--params", params, "-o",
                                  str(tmp_path / "out")], capfd, monkeypatch)
        assert code == 2 and err.startswith("mexone: ") and err.count("\n") == 1, err
        assert expected in err and "choose from damping,frictionloss,armature" in err
        with pytest.raises(MexoneError, match="unknown parameter bogus"):  # the library too
            identify([bag], Options(params=("bogus",)))


def test_a_few_nan_samples_and_commands_fit_with_notes(records, tmp_path, capfd, monkeypatch):
    def mutate(rs):
        _states(rs)[5].position[3] = math.nan
        next(r for r in rs if r.msgtype == COMMAND and "l_elbow" in r.topic).value = math.inf
    bag = _bag(records, tmp_path, "glitch.mcap", mutate)
    code, out, err = _identify(bag, tmp_path, capfd, monkeypatch, "--json")
    assert code == 0, err
    assert "1 joint position(s) NaN or inf, left out (the first: l_hip_pitch in message 6" in err
    assert "1 command(s) with NaN or inf left out" in err
    import json

    assert len(json.loads(out)["notes"]) == 2


@pytest.mark.parametrize("content,name", [(".mcap", "mcap_named.bag"), (".bag", "bag_named.mcap")])
def test_a_misnamed_bag_is_read_by_what_it_is(records, tmp_path, capfd, monkeypatch, content, name):
    bag = tmp_path / name
    hostile.write(records, bag, ros1=content == ".bag")
    kind = {".mcap": "an MCAP file", ".bag": "a ROS 1 bag"}[content]
    code, out, err = _identify(bag, tmp_path, capfd, monkeypatch)
    assert code == 0, err
    assert f"{bag}: {kind} named {bag.suffix}; read as what it is (rename it " \
           f"{bag.stem}{content})" in err
    code, out, err = run_cli(["plot", str(bag), "-o", str(tmp_path / "p.csv")], capfd, monkeypatch)
    assert code == 0 and "rows for 3 joints" in out, err  # the commanded ones
    code, out, err = run_cli(["record", "--recover", str(bag)], capfd, monkeypatch)
    _refused(code, out, err, bag, f"is {kind} named {bag.suffix}", f"rename it {bag.stem}{content}")
    truncated = tmp_path / f"cut{bag.suffix}"  # a killed one, misnamed: read by content too
    truncated.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    assert len(read_bag(truncated).states) > 10


def test_not_a_bag_says_what_it_is(tmp_path, capfd, monkeypatch):
    empty, db3, text = tmp_path / "empty.bag", tmp_path / "ros2.mcap", tmp_path / "notes.bag"
    empty.write_bytes(b"")
    db3.write_bytes(b"SQLite format 3\x00" + bytes(100))
    text.write_text("hello")
    for bag, expected in ((empty, "an empty file"), (db3, "a ROS 2 SQLite bag (.db3)"),
                          (text, "not a bag (it starts with neither MCAP's magic bytes")):
        for argv in (["plot", str(bag), "-o", str(tmp_path / "p.csv")], ["identify", str(bag)],
                     ["record", "--recover", str(bag)]):
            _refused(*run_cli(argv, capfd, monkeypatch), bag, expected)


def test_plot_and_recover_on_the_found_cases(records, tmp_path, capfd, monkeypatch):
    """plot reads what it can (a NaN is a gap in a line), refuses malformed JointStates in one
    line; recover says a complete bag needs nothing."""
    for case in sorted(REFUSED):
        bag = _bag(records, tmp_path, f"{case}.bag", REFUSED[case][0])
        code, out, err = run_cli(["plot", str(bag), "-o", str(tmp_path / f"{case}.csv")],
                                 capfd, monkeypatch)
        if case in ("fewer_positions", "one_name_21_times"):
            _refused(code, out, err, bag, "every JointState message is malformed")
        else:
            assert code == 0 and "Traceback" not in err, (case, err)
        code, out, err = run_cli(["record", "--recover", str(bag)], capfd, monkeypatch)
        assert code == 0 and "is complete; nothing to recover" in out, (case, err)


def test_plot_finds_joints_by_name_in_shuffled_messages(records, tmp_path):
    def shuffle(rs):
        for k, r in enumerate(_states(rs)):
            order = np.roll(np.arange(len(r.names)), k)
            r.names = [r.names[i] for i in order]
            r.position = [r.position[i] for i in order]
            r.velocity = [r.velocity[i] for i in order]
            r.effort = [r.effort[i] for i in order]
    plain = read_joint_series(_bag(records, tmp_path, "plain.bag"))
    shuffled = read_joint_series(_bag(records, tmp_path, "shuffled.bag", shuffle))
    for name, series in plain.items():
        assert np.array_equal(series.position, shuffled[name].position), name


def test_the_command_line_in_its_own_process(records, tmp_path):
    """The installed entry point: a hostile bag through identify, plot and --recover."""
    bag = _bag(records, tmp_path, "hostile.bag", REFUSED["zero_quaternion"][0])
    garbage = tmp_path / "garbage.mcap"
    garbage.write_bytes(b"\x89MCAP0\r\n" + os.urandom(3000))
    for argv in (["identify", str(bag), *FIT, "-o", str(tmp_path / "o")],
                 ["plot", str(garbage), "-o", str(tmp_path / "g.csv")],
                 ["record", "--recover", str(bag.with_suffix(".mcap"))]):
        proc = subprocess.run([sys.executable, "-m", "mexone", *argv], capture_output=True,
                              text=True, timeout=120, cwd=tmp_path)
        assert proc.returncode in (0, 2) and "Traceback" not in proc.stderr, proc.stderr
        if proc.returncode == 2:
            assert proc.stderr.count("\n") == 1 and proc.stderr.startswith("mexone: "), proc.stderr
    assert not (tmp_path / "MUJOCO_LOG.TXT").exists()


# ----- property-based: drawn mutations ------------------------------------------------------------

BAD_VALUES = (math.nan, math.inf, -math.inf, 1e300, -1e300, 1e30, 1e5, 0.0)


@dataclass
class Mutation:
    """One change to the records; `lossy`: data identify uses is lost (a fit must say so)."""

    what: str
    apply: object
    lossy: bool = False

    def __repr__(self) -> str:
        return self.what


@st.composite
def value_mutations(draw) -> Mutation:
    field = draw(st.sampled_from(["position", "velocity", "effort", "command", "xyz", "quat"]))
    scope = draw(st.sampled_from(["one", "joint", "all"]))
    value = draw(st.sampled_from(BAD_VALUES))
    pick = draw(st.integers(0, 10_000))

    def apply(records):
        if field in ("position", "velocity", "effort"):
            states = _states(records)
            chosen = [states[pick % len(states)]] if scope == "one" else states
            for r in chosen:
                values = getattr(r, field)
                if not values:
                    continue
                for i in ([pick % len(values)] if scope != "all" else range(len(values))):
                    values[i] = value
        elif field == "command":
            commands = [r for r in records if r.msgtype == COMMAND]
            topics = sorted({r.topic for r in commands})
            topic = topics[pick % len(topics)]
            chosen = {"one": [commands[pick % len(commands)]],
                      "joint": [r for r in commands if r.topic == topic], "all": commands}[scope]
            for r in chosen:
                r.value = value
        else:
            tfs = [r for r in records if r.msgtype == TF]
            for r in [tfs[pick % len(tfs)]] if scope == "one" else tfs:
                getattr(r, field)[pick % len(getattr(r, field)) if scope != "all" else 0] = value
                if scope == "all":
                    getattr(r, field)[:] = [value] * len(getattr(r, field))

    lossy = not math.isfinite(value) and field in ("position", "command")
    return Mutation(f"{field}[{scope} {pick}] = {value}", apply, lossy)


@st.composite
def name_mutations(draw) -> Mutation:
    how = draw(st.sampled_from(["drop_name", "drop_position", "repeat_name", "same_name",
                                "no_positions", "ghost_name", "swap_names", "empty_message"]))
    scope = draw(st.sampled_from(["one", "all"]))
    pick = draw(st.integers(0, 10_000))

    def apply(records):
        states = _states(records)
        for r in [states[pick % len(states)]] if scope == "one" else states:
            if not r.names:  # emptied by an earlier mutation
                continue
            k = pick % len(r.names)
            if how == "drop_name":
                r.names.pop(k)
            elif how == "drop_position":
                del r.position[k:k + 1]
            elif how == "repeat_name":
                r.names[k] = r.names[(k + 1) % len(r.names)]
            elif how == "same_name":
                r.names = [r.names[k]] * len(r.names)
            elif how == "no_positions":
                r.position = []
            elif how == "ghost_name":
                r.names[k] = "ghost_joint"
            elif how == "swap_names":
                j = (k + 1) % len(r.names)
                r.names[k], r.names[j] = r.names[j], r.names[k]
            else:
                r.names, r.position, r.velocity, r.effort = [], [], [], []

    return Mutation(f"{how}[{scope} {pick}]", apply,
                    lossy=how not in ("ghost_name", "swap_names", "empty_message"))


@st.composite
def time_mutations(draw) -> Mutation:
    how = draw(st.sampled_from(["reverse_stamps", "swap_stamps", "zero_stamp", "far_stamp",
                                "reverse_receive", "late_commands", "early_commands",
                                "jitter", "duplicate_state"]))
    pick = draw(st.integers(0, 10_000))
    shift = draw(st.sampled_from([0.01, 0.5, 1e4]))

    def apply(records):
        states = _states(records)
        i, j = pick % len(states), (pick * 7 + 3) % len(states)
        if how == "reverse_stamps":
            for r, s in zip(states, [r.stamp for r in states][::-1], strict=True):
                r.stamp = s
        elif how == "swap_stamps":
            states[i].stamp, states[j].stamp = states[j].stamp, states[i].stamp
        elif how == "zero_stamp":
            states[i].stamp = 0.0
        elif how == "far_stamp":
            states[i].stamp += shift
        elif how == "reverse_receive":
            for r, t in zip(records, [r.t for r in records][::-1], strict=True):
                r.t = t
        elif how in ("late_commands", "early_commands"):
            for r in records:
                if r.msgtype == COMMAND:
                    r.t = max(0.0, r.t + (shift if how == "late_commands" else -shift))
        elif how == "jitter":
            for k, r in enumerate(states):
                r.stamp += 1e-3 * ((k * 7919) % 5 - 2)
        else:
            records.insert(records.index(states[i]), copy.deepcopy(states[i]))

    return Mutation(f"{how}[{pick} {shift}]", apply)


MUTATIONS = st.lists(st.one_of(value_mutations(), name_mutations(), time_mutations()),
                     min_size=1, max_size=3)


def _contract(call, bag: Path, capfd, caplog) -> str:
    """call() returns or raises a one-line MexoneError naming the bag; no warning from numpy or
    MuJoCo either way. Returns "refused" or "ok"."""
    logging.getLogger("mexone").handlers.clear()  # an earlier main()'s, on a closed stream
    capfd.readouterr()
    caplog.clear()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            call()
            outcome = "ok"
        except MexoneError as exc:
            text = str(exc)
            assert "\n" not in text and str(bag) in text, text
            assert "np.float64" not in text and "gains too high" not in text, text
            outcome = "refused"
    numeric = [w for w in caught if issubclass(w.category, RuntimeWarning)]
    assert not numeric, [str(w.message) for w in numeric]
    out, err = capfd.readouterr()
    assert "WARNING" not in out + err and "Traceback" not in out + err, out + err
    return outcome


@fuzz(10)
@given(mutations=MUTATIONS, ros1=st.booleans())
def test_fuzz_identify(records, tmp_path_factory, capfd, caplog, monkeypatch, mutations, ros1):
    folder = tmp_path_factory.mktemp("fuzz")
    monkeypatch.chdir(folder)
    bag = _bag(records, folder, "m.bag" if ros1 else "m.mcap",
               lambda rs: [m.apply(rs) for m in mutations])
    caplog.set_level(logging.WARNING, logger="mexone")
    result = []
    options = Options(params=("damping",), joints=("l_elbow",), max_iterations=1, threads=1)
    outcome = _contract(lambda: result.append(identify([bag], options)), bag, capfd, caplog)
    assert not (folder / "MUJOCO_LOG.TXT").exists()
    if outcome == "ok":
        fit = result[0]
        assert np.isfinite([fit.rms_before, fit.rms_after]).all()
        assert np.isfinite(fit.fit.values).all()
        # a fit from damaged data says what it left out (an emptied message -- legal, and
        # harmless -- may have replaced the damage done to it by an earlier mutation)
        if any(m.lossy for m in mutations) and not any("empty_message" in m.what
                                                       for m in mutations):
            assert fit.notes or caplog.records, mutations


@fuzz(25)
@given(mutations=MUTATIONS, ros1=st.booleans())
def test_fuzz_plot_reader(records, tmp_path_factory, capfd, caplog, mutations, ros1):
    folder = tmp_path_factory.mktemp("fuzz")
    bag = _bag(records, folder, "m.bag" if ros1 else "m.mcap",
               lambda rs: [m.apply(rs) for m in mutations])
    from mexone.record.plot import pick_joints, write_csv

    _contract(lambda: write_csv(pick_joints(read_joint_series(bag), None), folder / "p.csv"),
              bag, capfd, caplog)


@st.composite
def byte_mutations(draw):
    how = draw(st.sampled_from(["truncate", "flip", "misname", "garbage_tail", "zero_run"]))
    where = draw(st.floats(0.0, 1.0))
    size = draw(st.integers(1, 64))

    def apply(data: bytes) -> bytes:
        at = int(where * len(data))
        if how == "truncate":
            return data[:at]
        if how == "flip":
            return data[:at] + bytes(b ^ 0xA5 for b in data[at:at + size]) + data[at + size:]
        if how == "zero_run":
            return data[:at] + bytes(size * 16) + data[at + size * 16:]
        if how == "garbage_tail":
            return data[:at] + bytes((i * 37 + size) % 256 for i in range(size * 8))
        return data

    return how, where, size, apply


@fuzz(25)
@given(mutation=byte_mutations(), ros1=st.booleans())
def test_fuzz_bytes(records, tmp_path_factory, capfd, caplog, mutation, ros1):
    """Cut, flipped or misnamed bytes: the reader, plot and recovery each give one line or a
    result (a cut bag is recovered from what is left)."""
    how, _, _, apply = mutation
    folder = tmp_path_factory.mktemp("bytes")
    clean = hostile.write(records[: len(records) // 3], folder / ("c.bag" if ros1 else "c.mcap"))
    name = ("m.mcap" if ros1 else "m.bag") if how == "misname" else f"m{clean.suffix}"
    bag = folder / name
    bag.write_bytes(apply(clean.read_bytes()))
    _contract(lambda: read_bag(bag, frames=("pelvis",)), bag, capfd, caplog)
    _contract(lambda: read_joint_series(bag), bag, capfd, caplog)
    target = folder / ("r" + (bag_kind(bag) or bag.suffix))
    _contract(lambda: recover(bag, target), bag, capfd, caplog)
    shutil.rmtree(folder)


def test_a_damaged_record_name_ends_recovery_without_a_traceback(records, tmp_path):
    """(found by test_fuzz_bytes) a cut ROS 1 bag whose first connection's field names are not
    UTF-8: what comes before it is recovered, the rest is one line."""
    clean = hostile.write(records, tmp_path / "clean.bag")
    data = clean.read_bytes()
    at = data.index(b"topic=", len(b"#ROSBAG V2.0\n") + 200)  # inside the first chunk
    damaged = tmp_path / "damaged.bag"
    damaged.write_bytes(data[:at] + b"\xca\xa5" + data[at + 2:len(data) // 2])
    assert recover(damaged, tmp_path / "out.bag").messages == 0  # was: UnicodeDecodeError
    with pytest.raises(MexoneError) as refused:
        read_bag(damaged)
    assert "\n" not in str(refused.value) and str(damaged) in str(refused.value)
    assert "not one message can be read" in str(refused.value)
