"""A graded routine in its own process (routines.isolated / routines.remote) is in lockstep with
the simulation exactly as in-process: the same commands at the same sim times, the same
messages delivered when they are, so the robot moves identically and grading is repeatable."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mexone.exercises.isolate import run_trusted
from mexone.exercises.sim import Variation, simulate

FEEDBACK = '''"""Every rospy path a graded routine takes: a parameter, wait_for_message, a subscriber
whose messages steer the command, Rate and sleep, set_param, a log line, the time."""
from mexone import rospy
from mexone.msgs import Float64, JointState

rospy.init_node("feedback")
gain = rospy.get_param("~gain")  # _gain:=0.2, moved under the node's name (__name:=renamed)
if rospy.get_name() != "/renamed" or rospy.has_param("/feedback/gain"):
    raise RuntimeError(f"the node is {rospy.get_name()}, not /renamed")
first = rospy.wait_for_message("/mex_rb/joint_states", JointState, timeout=1.0)
seen = []
rospy.Subscriber("/mex_rb/joint_states", JointState,
                 lambda m: seen.append((rospy.get_time(), m.position[m.name.index("l_elbow")])))
elbow = rospy.Publisher("/mex_rb/l_elbow_position_controller/command", Float64, queue_size=1)
rate = rospy.Rate(100)
rospy.sleep(0.013)
while not rospy.is_shutdown() and rospy.get_time() < 0.6:
    last = seen[-1][1] if seen else 0.0
    elbow.publish(Float64(-0.8 + gain * last + 0.01 * len(seen)))
    rate.sleep()
rospy.set_param("~seen", len(seen))
rospy.loginfo("saw %d joint states, the first at %.3f s", len(seen), first.header.stamp.to_sec())
if rospy.get_param("~seen") != len(seen) or not rospy.has_param("/robot_description"):
    raise RuntimeError("the parameter server lost a value")
'''


@pytest.fixture(scope="module")
def feedback(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("routine") / "feedback.py"
    path.write_text(FEEDBACK)
    return path


def _run(path: Path, own_process: bool):
    """In the simulator (the routine in its jail), or all in this process (the simulator
    itself refuses to run a student's routine in its own process)."""
    call = run_trusted if own_process else (lambda f, *args, **kwargs: f(*args, **kwargs))
    return call(simulate, 0.7, routine=path, variation=Variation(mass=1.05),
                params={"_gain": 0.2, "__name": "renamed"}, own_process=own_process)


def test_own_process_moves_the_robot_exactly_as_in_process(feedback):
    inside = _run(feedback, own_process=False)
    apart, again = _run(feedback, own_process=True), _run(feedback, own_process=True)
    assert inside.error is None and apart.error is None
    setpoint, elbow = inside.joint("l_elbow")
    assert abs(elbow[-1] - elbow[0]) > 0.3  # the commands moved the elbow
    assert len(np.unique(setpoint)) > 20  # steered by the joint states it heard
    for run in (apart, again):
        np.testing.assert_array_equal(run.t, inside.t)
        np.testing.assert_array_equal(run.position, inside.position)
        np.testing.assert_array_equal(run.setpoint, inside.setpoint)


def test_a_routine_that_uses_the_lab_gets_one_clear_line(tmp_path):
    path = tmp_path / "uses_model.py"
    path.write_text("from mexone import rospy\nfrom mexone.routines import runtime\n"
                    "rospy.init_node('m')\nprint(runtime.current().lab.sim.model.nbody)\n")
    run = run_trusted(simulate, 0.05, routine=path, raise_routine_errors=False)
    assert "uses_model.py:4" in run.error and "not offered to a routine graded in its own " \
        "process" in run.error, run.error


def test_a_routine_sending_a_pickle_of_its_own_class_is_refused(tmp_path):
    """What the routine's process sends is read as JSON against the protocol's schema, never
    unpickled: a message holding an object of its own cannot be sent, and a pickle written on
    its socket past rospy is not JSON; neither runs anything in the simulator."""
    pwned = tmp_path / "pwned"
    evil = ("import os, pickle, struct\n"
            "class Evil:\n    def __reduce__(self):\n"
            f"        return (os.system, ('touch {pwned}',))\n")
    path = tmp_path / "evil.py"
    path.write_text(evil + "from mexone import rospy\nfrom mexone.msgs import Float64\n"
                    "rospy.init_node('e')\np = rospy.Publisher('/x', Float64, queue_size=1)\n"
                    "p.publish(Float64(Evil()))\nrospy.sleep(0.01)\n")
    run = run_trusted(simulate, 0.05, routine=path, raise_routine_errors=False)
    assert "evil.py:9: ProtocolError: Float64 cannot be sent to the simulator: cannot send a " \
        "Evil" in run.error, run.error
    raw = tmp_path / "raw.py"
    raw.write_text(evil + "import gc, socket\nfrom mexone import rospy\nrospy.init_node('r')\n"
                   "sock = next(o for o in gc.get_objects() if isinstance(o, socket.socket))\n"
                   "data = pickle.dumps(([], (Evil(),)))\n"
                   "sock.sendall(struct.pack('!I', len(data)) + data)\nrospy.sleep(1.0)\n")
    run = run_trusted(simulate, 0.3, routine=raw, raise_routine_errors=False)
    assert "the routine's process sent what mexone cannot read: message: not JSON" in run.error, \
        run.error
    assert not pwned.exists()


def test_a_routine_talking_past_rospy_on_its_socket_ends_with_one_line(tmp_path):
    path = tmp_path / "talker.py"
    path.write_text("import gc, socket\nfrom mexone import rospy\nfrom mexone.routines import remote\n"
                    "rospy.init_node('t')\n"
                    "sock = next(o for o in gc.get_objects() if isinstance(o, socket.socket))\n"
                    "remote.send(sock, ([], ('wait', 'soon')))\nrospy.sleep(1.0)\n")
    run = run_trusted(simulate, 0.3, routine=path, raise_routine_errors=False)
    assert "the routine's process sent a malformed request (ValueError" in run.error, run.error
