"""The ROS 1 interfaces mexone serves that Debian does not package: controller_manager_msgs,
control_msgs and gazebo_msgs, plus the `controller_manager` package with its `spawner`.

`share/` is a ROS package path (put it on ROS_PACKAGE_PATH): each package's .msg/.srv/.action
files reproduce the official definitions field for field, so their md5sums equal ROS's and
clients built against ROS's own packages interoperate. Their Python classes are generated
from those files by Debian's genpy on first use (half a second) into mexone's cache, one folder
per digest of the definitions, and reused after (`generated()`); `mexone ros-env` puts that
folder on PYTHONPATH for rostopic, rosservice and rospy nodes outside mexone. Actions are
expanded as actionlib's genaction does.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sys
import tempfile
from pathlib import Path

from mexone import files
from mexone.errors import MexoneError

__all__ = ["SHARE", "PACKAGES", "generate", "generated", "use_generated", "environment",
           "expand_action"]

HERE = Path(__file__).resolve().parent
SHARE = HERE / "share"  # a ROS package path
_FORMAT = "1"  # bumped when what generate() writes changes for the same definitions
PACKAGES = ("controller_manager_msgs", "control_msgs", "gazebo_msgs")
_SYSTEM_SHARE = Path("/usr/share")  # Debian's message definitions (std_msgs, geometry_msgs, ...)
_DEPENDS = ("std_msgs", "geometry_msgs", "trajectory_msgs", "actionlib_msgs", "sensor_msgs")
_DEBIAN_SITE = "/usr/lib/python3/dist-packages"


def _digest() -> str:
    """What the generated code depends on: every definition file of PACKAGES, and the format."""
    sha = hashlib.sha256(_FORMAT.encode())
    for pkg in PACKAGES:
        for path in sorted((SHARE / pkg).rglob("*")):
            if path.suffix in (".msg", ".srv", ".action"):
                sha.update(str(path.relative_to(SHARE)).encode() + b"\0" + path.read_bytes())
    return sha.hexdigest()[:16]


def generated() -> Path:
    """The folder holding the generated Python packages (one top-level package per ROS
    package), generated now if this version of the definitions has none yet. Safe when several
    processes start at once: each generates into a folder of its own and one rename wins."""
    target = files.cache_dir("ros1-msgs") / _digest()
    if (target / PACKAGES[-1] / "__init__.py").is_file():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{target.name}-", dir=target.parent))
    try:
        generate(work)
        try:
            os.rename(work, target)
        except OSError:  # another process was first (its folder is complete: it renamed last)
            if not (target / PACKAGES[-1] / "__init__.py").is_file():
                raise
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return target


def use_generated() -> None:
    """Make the generated packages importable as `gazebo_msgs`, `control_msgs`, ... (their code
    imports each other by those names, as every genpy package does)."""
    path = str(generated())
    if path not in sys.path:
        sys.path.append(path)


def environment(env: dict[str, str] | None = None) -> dict[str, str]:
    """`env` (default: this process's) with mexone's ROS packages on ROS_PACKAGE_PATH (the
    message packages, controller_manager with its spawner, and the robot package mex_rb) and
    their Python on PYTHONPATH, appended once: what rosservice, rostopic, roslaunch and the
    spawner need. `mexone ros-env` prints it as shell exports."""
    from mexone.robots import mex_one

    env = dict(os.environ if env is None else env)
    for key, paths in (("ROS_PACKAGE_PATH", (SHARE, mex_one.package_dir().parent)),
                       ("PYTHONPATH", (generated(),))):
        value = env.get(key, "")  # kept as it is (an empty PYTHONPATH entry means the cwd)
        missing = [str(path) for path in paths if str(path) not in value.split(os.pathsep)]
        env[key] = os.pathsep.join([value, *missing] if value else missing)
    return env


def expand_action(action: Path, out: Path) -> list[Path]:
    """The seven messages of an .action file, as actionlib_msgs' genaction writes them."""
    name = action.stem
    goal, result, feedback = (part.strip("\n") for part in action.read_text().split("\n---"))
    texts = {
        f"{name}Goal": goal,
        f"{name}Result": result,
        f"{name}Feedback": feedback,
        f"{name}ActionGoal": f"Header header\nactionlib_msgs/GoalID goal_id\n{name}Goal goal",
        f"{name}ActionResult": f"Header header\nactionlib_msgs/GoalStatus status\n{name}Result result",
        f"{name}ActionFeedback": (f"Header header\nactionlib_msgs/GoalStatus status\n"
                                  f"{name}Feedback feedback"),
        f"{name}Action": (f"{name}ActionGoal action_goal\n{name}ActionResult action_result\n"
                          f"{name}ActionFeedback action_feedback"),
    }
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for msg, text in texts.items():
        path = out / f"{msg}.msg"
        path.write_text("# generated from " + action.name + " as genaction does\n" + text + "\n")
        paths.append(path)
    return paths


def _debian_tools():
    if _DEBIAN_SITE not in sys.path:
        sys.path.append(_DEBIAN_SITE)  # appended: pip's packages keep precedence
    try:
        import genmsg.command_line  # noqa: F401 - Debian's python3-genmsg
        import genpy.generate_initpy
        import genpy.generator
    except ImportError:
        raise MexoneError("ROS 1's message generator (genpy) is not installed: mexone generates "
                          "its ROS 1 message classes with it",
                          hint="install it with: apt-get install python3-genpy python3-genmsg "
                               "(ROS 1's rospy brings both)") from None

    return genpy


def message_dirs(work: Path) -> dict[str, list[str]]:
    """genmsg's search path: each package's msg folders (actions expanded into `work`)."""
    search = {pkg: [str(_SYSTEM_SHARE / pkg / "msg")] for pkg in _DEPENDS}
    for pkg in PACKAGES:
        dirs = [str(SHARE / pkg / "msg")]
        actions = sorted((SHARE / pkg / "action").glob("*.action"))
        if actions:
            for action in actions:
                expand_action(action, work / pkg / "msg")
            dirs.append(str(work / pkg / "msg"))
        search[pkg] = dirs
    return search


def generate(out: Path) -> None:
    """Generate the Python classes of every package into `out` (replacing what was there)."""
    genpy = _debian_tools()
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        search = message_dirs(work)
        for pkg in PACKAGES:
            target = out / pkg
            if target.exists():
                shutil.rmtree(target)
            msgs = sorted(str(p) for d in search[pkg] for p in Path(d).glob("*.msg"))
            srvs = sorted(str(p) for p in (SHARE / pkg / "srv").glob("*.srv"))
            for files, generator, kind in ((msgs, genpy.generator.MsgGenerator(), "msg"),
                                           (srvs, genpy.generator.SrvGenerator(), "srv")):
                if not files:
                    continue
                code = generator.generate_messages(pkg, files, str(target / kind), search)
                if code:
                    raise RuntimeError(f"genpy failed on {pkg}/{kind}")
                genpy.generate_initpy.write_modules(str(target / kind))
            (target / "__init__.py").write_text("")
    for stale in out.rglob("__pycache__"):
        shutil.rmtree(stale, ignore_errors=True)
