"""The interfaces mexone serves are ROS's: md5sums equal to the official packages' (the literals
below are what genmsg computes from the official controller_manager_msgs and gazebo_msgs of
Noetic and control_msgs 1.5), and their Python is generated from mexone/ros1/share by
Debian's genpy into mexone's cache once per version of the definitions."""

from __future__ import annotations

import importlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from mexone.ros1 import interfaces

OFFICIAL_MD5 = {
    "controller_manager_msgs/ListControllers": "1341feb2e63fa791f855565d0da950d8",
    "controller_manager_msgs/ListControllerTypes": "c1d4cd11aefa9f97ba4aeb5b33987f4e",
    "controller_manager_msgs/LoadController": "647e5c54b8d6468952d8d31f1efe96c0",
    "controller_manager_msgs/UnloadController": "647e5c54b8d6468952d8d31f1efe96c0",
    "controller_manager_msgs/SwitchController": "b29a7abc673b2c54c14b54e50f8d06a5",
    "controller_manager_msgs/ReloadControllerLibraries": "40e8c411fd1797d2e2c486018f846040",
    "gazebo_msgs/GetModelState": "4c515e936d3319c9610c559c60bfc3d4",
    "gazebo_msgs/SetModelState": "5b3ab0281d4f5445def017e3a2e4a07b",
    "gazebo_msgs/GetLinkState": "09d6c98cce97b35f7ab9bd70300657ab",
    "gazebo_msgs/SetLinkState": "8a5146eb66ae4d26b0860b08f3f271be",
    "gazebo_msgs/ApplyBodyWrench": "585b9f9618aa0581b207e2f2d90866bc",
    "gazebo_msgs/BodyRequest": "5eade9afe7f232d78005bd0cafeab755",
    "gazebo_msgs/ApplyJointEffort": "c0039811b8cc919490b3cff748cdf46b",
    "gazebo_msgs/JointRequest": "0be1351618e1dc030eb7959d9a4902de",
    "gazebo_msgs/GetWorldProperties": "36bb0f2eccf4d8be971410c22818ba3f",
    "gazebo_msgs/GetModelProperties": "5717f7bd34ed990fa80e28b3015027a3",
    "gazebo_msgs/GetPhysicsProperties": "575a5e74786981b7df2e3afc567693a6",
    "gazebo_msgs/SetPhysicsProperties": "97e2057080558ce4730434b5fae75c91",
    "gazebo_msgs/SetModelConfiguration": "10e3139d3b669c40afc057d38956fff7",
    "gazebo_msgs/SpawnModel": "9ed9c82c96abe1a00c3e8cdaeee24413",
    "gazebo_msgs/DeleteModel": "9ce56b4e9e54616de25d796dc972a262",
    "gazebo_msgs/ModelStates": "48c080191eb15c41858319b4d8a609c2",
    "gazebo_msgs/LinkStates": "48c080191eb15c41858319b4d8a609c2",
    "gazebo_msgs/ModelState": "9330fd35f2fcd82d457e54bd54e10593",
    "gazebo_msgs/ContactsState": "acbcb1601a8e525bf72509f18e6f668d",
    "control_msgs/JointControllerState": "987ad85e4756f3aef7f1e5e7fe0595d1",
    "control_msgs/FollowJointTrajectoryAction": "bc4f9b743838566551c0390c65f1a248",
    "control_msgs/FollowJointTrajectoryGoal": "69636787b6ecbde4d61d711979bc7ecb",
    "control_msgs/JointTrajectoryControllerState": "10817c60c2486ef6b33e97dcd87f4474",
    "control_msgs/QueryTrajectoryState": "ec93cdecbd8062d761aa52b7c90cd44b",
}


def _debian_genpy() -> None:
    if not Path("/usr/lib/python3/dist-packages/genpy").is_dir():
        pytest.skip("Debian's python3-genpy is not installed")


@pytest.mark.parametrize("ros_type", sorted(OFFICIAL_MD5))
def test_md5sum_equals_the_official_one(ros_type):
    _debian_genpy()
    from mexone.ros1.bridge import import_rospy

    import_rospy()  # genpy, which the generated classes import, is Debian's
    interfaces.use_generated()
    pkg, name = ros_type.split("/")
    kind = "srv" if (interfaces.SHARE / pkg / "srv" / f"{name}.srv").exists() else "msg"
    cls = getattr(importlib.import_module(f"{pkg}.{kind}"), name)
    assert cls._md5sum == OFFICIAL_MD5[ros_type]
    assert cls._type == ros_type


def test_generated_once_per_version_of_the_definitions(tmp_path, monkeypatch):
    """The first use generates into the cache; later ones (other processes too) reuse it; a
    changed definition gets a folder of its own."""
    _debian_genpy()
    monkeypatch.setenv("MEXONE_CACHE", str(tmp_path / "cache"))
    first = interfaces.generated()
    assert first.parent == tmp_path / "cache" / "ros1-msgs"
    for pkg in interfaces.PACKAGES:
        assert (first / pkg / "__init__.py").is_file()
    assert (first / "controller_manager_msgs" / "srv" / "_SwitchController.py").is_file()
    assert (first / "control_msgs" / "msg" / "_FollowJointTrajectoryActionGoal.py").is_file()
    stamp = (first / "gazebo_msgs" / "__init__.py").stat().st_mtime_ns
    again = subprocess.run([sys.executable, "-c", "from mexone.ros1 import interfaces; "
                            "print(interfaces.generated())"], capture_output=True, text=True,
                           env={**os.environ, "MEXONE_CACHE": str(tmp_path / "cache")})
    assert again.returncode == 0, again.stderr
    assert again.stdout.strip() == str(first)
    assert (first / "gazebo_msgs" / "__init__.py").stat().st_mtime_ns == stamp
    assert [p.name for p in first.parent.iterdir()] == [first.name]  # no work folder left

    share = tmp_path / "share"
    shutil.copytree(interfaces.SHARE, share)
    monkeypatch.setattr(interfaces, "SHARE", share)
    with (share / "gazebo_msgs" / "msg" / "ContactsState.msg").open("a") as f:
        f.write("# a comment changes the digest, not the md5sum\n")
    changed = interfaces.generated()
    assert changed != first and changed.parent == first.parent


def test_without_genpy_one_line_says_what_to_install(tmp_path, monkeypatch):
    monkeypatch.setenv("MEXONE_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(interfaces, "_DEBIAN_SITE", str(tmp_path / "nowhere"))
    for name in [m for m in sys.modules if m.split(".")[0] in ("genpy", "genmsg")]:
        monkeypatch.delitem(sys.modules, name)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if "dist-packages" not in p])
    from mexone.errors import MexoneError

    with pytest.raises(MexoneError, match="genpy") as caught:
        interfaces.generated()
    assert "apt-get install" in str(caught.value)
    assert not (tmp_path / "cache" / "ros1-msgs").exists() or not any(
        (tmp_path / "cache" / "ros1-msgs").iterdir())


def test_an_action_expands_as_genaction_does(tmp_path):
    action = tmp_path / "Move.action"
    action.write_text("float64 target\n---\nint32 code\n---\nfloat64 progress\n")
    paths = {p.stem: p.read_text() for p in interfaces.expand_action(action, tmp_path / "msg")}
    assert set(paths) == {"MoveGoal", "MoveResult", "MoveFeedback", "MoveActionGoal",
                          "MoveActionResult", "MoveActionFeedback", "MoveAction"}
    assert "actionlib_msgs/GoalID goal_id\nMoveGoal goal" in paths["MoveActionGoal"]
    assert paths["MoveGoal"].endswith("float64 target\n")
