"""Whole-body motion from a routine, in the rospy style::

    from mexone import rospy
    from mexone.motion import reach, look_at, push

    rospy.init_node("wave")
    reach("l_hand", (0.25, 0.15, 0.75))            # world metres; orientation left free
    reach("r_hand", (0.2, -0.2, 0.6), rpy=(0, -1.57, 0), duration=3.0)
    look_at((1.0, 0.0, 0.3))
    push("torso", (5.0, 0.0, 0.0))                 # 5 N s forward, over 0.1 s

reach plans with whole-body IK (mexone.motion.ik: feet held, COM over them) and sends joint
positions over `duration` through the robot's position-controller topics, as a student's own
loop would; the controllers do the rest. Then it holds the pose and trims each command by the
error the joint's PD leaves under gravity (an integral action at the routine's rate) until the
joints settle. The IK never touches the simulation's data: it starts from a snapshot the
simulation thread takes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mink
import numpy as np

from mexone import rospy
from mexone.errors import InputError
from mexone.motion.ik import REACHED, FrameError, WholeBodyIK
from mexone.motion.push import PUSH_SECONDS, apply_wrench
from mexone.motion.walk import (
    GAIT_YAML,
    Gait,
    Measured,
    WalkPlan,
    bent_knees,
    course_steps,
    parse_course,
    plan_phases,
    walk_ticks,
)
from mexone.msgs import (
    Float64,
    Header,
    Imu,
    JointState,
    Path,
    Point,
    Pose,
    PoseArray,
    PoseStamped,
    Quaternion,
    Twist,
)
from mexone.routines.runtime import RoutineContext, busy, current

__all__ = ["reach", "look_at", "push", "walk", "walk_cmd_vel", "follow_goals", "GOAL_FRAMES",
           "walk_seconds", "step_from_twist", "joint_targets", "RATE", "REACHED"]

RATE = 50.0  # Hz: how often reach sends joint commands (the IK steps at the same period)
_SETTLE = 1.0  # s at most holding the pose after the motion, trimming the commands
_TRIM_GAIN = 0.3  # share of the joint error added to its command each tick while holding
_SETTLED = 2e-4  # rad: the joints count as settled when all are this close
_CORRECTIONS = 2  # passes re-planned from the measured pose after the motion
_CORRECT_ABOVE = 0.002  # m: a measured error this small is left alone
BEND_SECONDS = 1.0  # s to bend the knees into the walking stance before the first step
CMD_VEL_TIMEOUT = 0.5  # s: a cmd_vel older than this stops the walk (its sender is gone)
_SWING_SPEED = 1.5  # rad/s: the fastest a joint turns moving to a restarted IK's solution
_MIN_JERK_PEAK = 1.875  # a minimum-jerk move's peak speed over its mean speed
_MAX_TRIM = 0.2  # rad: a joint held off its target by more (a collision) is not chased further


@dataclass
class _Mover:
    """One routine's IK and its joint command topics (made on first use)."""

    context: RoutineContext
    ik: WholeBodyIK
    publishers: dict[str, rospy.Publisher]
    measured: dict[str, float] = field(default_factory=dict)
    velocities: dict[str, float] = field(default_factory=dict)
    trim: dict[str, float] = field(default_factory=dict)  # added to each command while holding
    trimmed: set[str] = field(default_factory=set)  # joints trimmed: not the legs that stand

    def snapshot(self) -> np.ndarray:
        sim = self.context.lab.sim
        return sim.work.call(lambda: sim.data.qpos.copy())

    def send(self, joints: dict[str, float]) -> None:
        for name, value in joints.items():
            pub = self.publishers.get(name)
            if pub is not None:
                low, high = self.ik.joint_range(name)
                pub.publish(Float64(float(np.clip(value + self.trim.get(name, 0.0), low, high))))

    def hold(self, joints: dict[str, float], rate: rospy.Rate) -> None:
        """Keep sending `joints`, trimming each by what its PD leaves, until they settle."""
        ticks = int(_SETTLE * RATE)
        for _ in range(ticks):
            errors = {n: joints[n] - self.measured[n] for n in self.trimmed if n in self.measured}
            for name, error in errors.items():
                trim = self.trim.get(name, 0.0) + _TRIM_GAIN * error
                self.trim[name] = float(np.clip(trim, -_MAX_TRIM, _MAX_TRIM))
            self.send(joints)
            rate.sleep()
            if errors and max(abs(e) for e in errors.values()) < _SETTLED:
                break


def _mover() -> _Mover:
    """The routine's own mover (kept in its context: it ends with the routine)."""
    context = current()
    mover = context.kept.get(__name__)
    if isinstance(mover, _Mover):
        return mover
    lab = context.lab
    if lab.manager is None:
        raise InputError("this robot has no controllers to move it",
                         hint="run with the robot's controller YAML (--controllers)")
    manager = lab.manager
    publishers = {}
    for ctrl in list(manager.controllers.values()):  # one position setpoint topic per joint
        if ctrl.holds_position and ctrl.msg_type is Float64:
            publishers[ctrl.joints[0]] = rospy.Publisher(manager.topic(ctrl.name), Float64,
                                                         queue_size=1)
    with busy("the IK's set-up"):
        ik = WholeBodyIK.for_sim(lab.sim)
    mover = _Mover(context, ik, publishers, trimmed=set(publishers) - ik.support_joints())

    def on_state(msg: JointState) -> None:
        mover.measured.update(zip(msg.name, msg.position, strict=False))
        mover.velocities.update(zip(msg.name, msg.velocity, strict=False))

    rospy.Subscriber(f"{lab.namespace}/joint_states", JointState, on_state)
    context.kept[__name__] = mover
    return mover


def _min_jerk(s: float) -> float:
    return s * s * s * (10 - 15 * s + 6 * s * s)


def reach(frame: str, xyz, rpy=None, duration: float = 2.0) -> FrameError:
    """Move `frame` ("l_hand", "r_hand", "l_foot", "head", any link) to world xyz (m) and, if
    given, roll-pitch-yaw (rad), over `duration` s, feet planted. Returns the remaining error,
    measured; an unreachable target ends at the closest pose with a one-line warning, as does a
    frame the body could not carry to a reachable one. A target the straight path cannot
    reach from here (another local minimum of the IK) is solved with restarts and reached by a
    move in joint space, at most _SWING_SPEED per joint."""
    if not (duration > 0 and math.isfinite(duration)):
        raise InputError(f"reach: duration {duration} must be a finite number > 0 s")
    with busy("reach's IK"):  # the plan and its restarts: seconds on a loaded machine
        mover = _mover()
        ik = mover.ik
        snapshot = mover.snapshot()
        ik.reset(snapshot)
        initial = ik.joint_positions()
        start, rotation0 = ik.pose(frame)
        goal = np.asarray(xyz, dtype=float)
        ik.set_rpy_target(frame, goal, rpy)  # checks the target before anything moves
        rotation = None if rpy is None else ik.targets[frame].transform_target_to_world.rotation()
        ticks = max(1, round(duration * RATE))
        path = []  # planned whole before anything moves: the joints at each tick
        for k in range(1, ticks + 1):
            s = _min_jerk(k / ticks)
            if rotation is None:
                ik.set_target(frame, start + s * (goal - start))
            else:
                between = mink.SO3.from_matrix(rotation0).interpolate(rotation, s)
                ik.set_target(frame, start + s * (goal - start), between.as_matrix())
            ik.step(1.0 / RATE)
            path.append(ik.joint_positions())
        ik.converge()
        if not ik.error(frame).reached:  # the straight path ends in another local minimum
            ik.reset(snapshot)
            ik.set_rpy_target(frame, goal, rpy)
            ik.solve(frame)  # fresh starts of the arm: the closest pose there is
            after = ik.joint_positions()
            # there in joint space (no collision check: see README), slowly enough not to throw the
            # body: a restart can flip a shoulder by 4 rad
            swing = max(abs(after[n] - initial[n]) for n in after)
            moves = max(ticks, round(_MIN_JERK_PEAK * swing / _SWING_SPEED * RATE))
            path = [{n: initial[n] + _min_jerk(k / moves) * (after[n] - initial[n]) for n in after}
                    for k in range(1, moves + 1)]
    rate = rospy.Rate(RATE)
    for joints in path:
        mover.send(joints)
        rate.sleep()
    mover.hold(ik.joint_positions(), rate)
    error = ik.error(frame)
    for _ in range(_CORRECTIONS):  # close the loop on where the frame really is
        with busy("reach's IK"):
            ik.reset(mover.snapshot())
            ik.set_rpy_target(frame, goal, rpy)
            if ik.error(frame).position < _CORRECT_ABOVE:
                break
            ik.converge()
        mover.hold(ik.joint_positions(), rate)
        error = ik.error(frame)
    planned = error
    with busy("reach's IK"):
        ik.reset(mover.snapshot())
        ik.set_rpy_target(frame, goal, rpy)
        error = ik.error(frame)  # where the frame really is
    if not error.reached and planned.reached:
        rospy.logwarn("reach %s: stopped %s short of (%.3f, %.3f, %.3f): the body did not follow "
                      "the IK (a collision, a foot slipping or tipping, a joint at its effort "
                      "limit)", frame, error, *goal)
    elif not error.reached:
        rospy.logwarn("reach %s: (%.3f, %.3f, %.3f) is out of reach; stopped at the closest pose, "
                      "%s away", frame, *goal, error)
    return error


GOAL_FRAMES = ("l_hand", "r_hand", "l_foot", "r_foot", "head")
WORLD_FRAMES = ("", "world", "map", "odom")  # frame_ids a goal may be given in (all the world)


def follow_goals(frames=GOAL_FRAMES, duration: float = 1.0) -> None:
    """Reach each geometry_msgs/PoseStamped arriving on /<ns>/<frame>/goal (world frame; a zero
    quaternion, rospy's default, leaves the orientation free), one after another, each over
    `duration` s. Returns never (until the routine is stopped)."""
    ns = current().lab.namespace
    pending: list[tuple[str, PoseStamped]] = []
    for frame in frames:
        rospy.Subscriber(f"{ns}/{frame}/goal", PoseStamped,
                         lambda msg, f=frame: pending.append((f, msg)))
    while not rospy.is_shutdown():
        if not pending:
            rospy.sleep(1.0 / RATE)
            continue
        frame, msg = pending.pop(0)
        if msg.header.frame_id.lstrip("/") not in WORLD_FRAMES:
            rospy.logwarn("goal for %s in frame '%s' ignored: give it in the world frame "
                          "(frame_id '' or 'world')", frame, msg.header.frame_id)
            continue
        p, q = msg.pose.position, msg.pose.orientation
        norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
        rpy = None
        if norm > 1e-9:
            x, y, z, w = q.x / norm, q.y / norm, q.z / norm, q.w / norm
            rpy = (math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)),
                   math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x)))),
                   math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z)))
        try:
            reach(frame, (p.x, p.y, p.z), rpy, duration)
        except InputError as exc:
            rospy.logwarn("goal for %s ignored: %s", frame, exc.what)


def look_at(xyz, duration: float = 1.0) -> None:
    """Turn the head so the camera looks at world point xyz (m), the rest of the body still."""
    mover = _mover()
    ik = mover.ik
    ik.reset(mover.snapshot())
    ik.look_at(xyz)
    rate = rospy.Rate(RATE)
    for _ in range(max(1, round(duration * RATE))):
        ik.step(1.0 / RATE)
        mover.send(ik.joint_positions())
        rate.sleep()


def joint_targets() -> dict[str, float]:
    """The joint positions the last motion commanded (before trimming)."""
    return _mover().ik.joint_positions()


def push(link: str, impulse_xyz, duration: float = PUSH_SECONDS) -> None:
    """Push `link` with a world-frame impulse (N s), spread evenly over `duration` s from now
    (force = impulse / duration at its centre of mass). Returns at once; the push goes on."""
    impulse = np.asarray(impulse_xyz, dtype=float)
    if impulse.shape != (3,) or not np.isfinite(impulse).all():
        raise InputError(f"push on '{link}': the impulse must be three finite numbers (N s)")
    if not (duration > 0 and math.isfinite(duration)):
        raise InputError(f"push on '{link}': duration {duration} must be a finite number > 0 s")
    sim = current().lab.sim
    force = impulse / duration
    sim.work.call(lambda: apply_wrench(sim, link, force, duration=duration))


def _walking_course(course, gait: Gait) -> tuple:
    if course is None:
        return gait.course
    if isinstance(course, int | float) and not isinstance(course, bool):
        if not (course > 0 and math.isfinite(course)):
            raise InputError(f"walk: distance {course} must be a finite number > 0 m")
        return (("forward", float(course)),)
    return parse_course(course, "walk")


def walk_seconds(course=None, gait: Gait | str | None = None) -> float:
    """How long walk(course, gait) takes (s of sim time): it is planned, so known beforehand."""
    gait = gait if isinstance(gait, Gait) else Gait.load(gait or GAIT_YAML)
    seconds, _ = plan_phases(gait, course_steps(gait, _walking_course(course, gait)))
    return BEND_SECONDS + seconds


def walk(course=None, gait: Gait | str | None = None) -> None:
    """Walk a course: a distance (m straight ahead) or legs [["forward", 3.0], ["turn", 90],
    ["sideways", -1.0]] (m, degrees, m; left positive), default the gait's (walk.yaml:
    3 m, a quarter turn left, 1 m to the right). mexone.motion.walk plans it: footsteps, ZMP
    preview control, IK. Returns standing, knees bent. The legs' times go to the ~phases
    parameter, so `mexone run` reports each."""
    gait = gait if isinstance(gait, Gait) else Gait.load(gait or GAIT_YAML)
    legs = _walking_course(course, gait)
    _, phases = plan_phases(gait, course_steps(gait, legs))
    start = rospy.get_time() + BEND_SECONDS
    rospy.set_param("~phases", [[leg, round(start + a, 6), round(start + b, 6)] for leg, a, b in phases])
    _walk(course_steps(gait, legs), gait)


def walk_cmd_vel(gait: Gait | str | None = None, topic: str | None = None) -> None:
    """Walk as geometry_msgs/Twist on `topic` (default /<ns>/cmd_vel) says: linear.x forward,
    linear.y left (m/s), angular.z turn left (rad/s), each step as long as the gait allows; a
    zero Twist (or none for 0.5 s) stands. Returns never (until the routine is stopped). A
    command takes effect when the plan reaches it: `preview` s (walk.yaml) later."""
    gait = gait if isinstance(gait, Gait) else Gait.load(gait or GAIT_YAML)
    last = {"msg": Twist(), "stamp": -math.inf}

    def on_twist(msg: Twist) -> None:
        last["msg"], last["stamp"] = msg, rospy.get_time()

    rospy.Subscriber(topic or f"{current().lab.namespace}/cmd_vel", Twist, on_twist)

    def steps():
        while True:
            msg = last["msg"] if rospy.get_time() - last["stamp"] < CMD_VEL_TIMEOUT else Twist()
            yield step_from_twist(gait, msg.linear.x, msg.linear.y, msg.angular.z)

    _walk(steps(), gait)


def step_from_twist(gait: Gait, vx: float, vy: float, wz: float):
    """One step's body motion (leg, (dx, dy, dyaw)) for a velocity command, each part clipped
    to the gait's largest step; None (stand) for a command too small to step."""
    motion = np.array([vx, vy, wz], dtype=float) * gait.period
    if not np.isfinite(motion).all():
        return None
    motion = np.clip(motion, -np.array([gait.step_length, gait.side_step, gait.turn_step]),
                     np.array([gait.step_length, gait.side_step, gait.turn_step]))
    if np.all(np.abs(motion) < 1e-3):
        return None
    leg = ("forward", "sideways", "turn")[int(np.argmax(np.abs(motion) / np.array(
        [gait.step_length, gait.side_step, gait.turn_step])))]
    return leg, motion


PLAN_TOPICS = {"footsteps": PoseArray, "zmp_plan": Path, "com_plan": Path}  # under /<ns>/walk/


class _PlanPublisher:
    """Publish each WalkPlan on /<ns>/walk/footsteps (geometry_msgs/PoseArray: the soles'
    centres, facing their way), /<ns>/walk/zmp_plan (on the ground) and /<ns>/walk/com_plan
    (nav_msgs/Path, at the COM's height, stamped when planned): what rviz and the GUI draw.
    Only while someone listens (else the COM path is not worked out); the topics latch, and a
    listener who comes while the plan stands still (a robot standing) gets it at the next tick."""

    def __init__(self):
        lab = self.lab = current().lab
        self.pubs = {k: rospy.Publisher(f"{lab.namespace}/walk/{k}", t, queue_size=1, latch=True)
                     for k, t in PLAN_TOPICS.items()}
        self.seq = 0
        self.last: WalkPlan | None = None
        self.sent = False  # the last plan was published (the latch holds it for newcomers)

    def __call__(self, plan: WalkPlan) -> None:
        self.last, self.sent = plan, False
        self.catch_up()

    def catch_up(self) -> None:
        """Publish the last plan if it went unheard and someone listens now (each tick)."""
        if self.sent or self.last is None or \
                not any(self.lab.bus.wanted(p.name) for p in self.pubs.values()):
            return
        self.sent = True
        plan = self.last
        self.seq += 1
        seq, now = self.seq, rospy.Time.now()
        ground, height = float(plan.ground), float(plan.com_height)
        header = Header(seq, now, "world")

        def path(points, z: float) -> Path:
            return Path(header, [PoseStamped(Header(seq, now + rospy.Duration(i * plan.dt),
                                                    "world"),
                                             Pose(Point(float(p[0]), float(p[1]), z)))
                                 for i, p in enumerate(points)])

        self.pubs["footsteps"].publish(PoseArray(header, [
            Pose(Point(float(x), float(y), ground),
                 Quaternion(0.0, 0.0, float(math.sin(yaw / 2)), float(math.cos(yaw / 2))))
            for x, y, yaw in plan.footsteps]))
        self.pubs["zmp_plan"].publish(path(plan.zmp, ground))
        self.pubs["com_plan"].publish(path(plan.com, height))


def _walk(source, gait: Gait) -> None:
    mover = _mover()
    qpos = mover.snapshot()
    ik = mover.ik
    with busy("the walk's set-up"):  # IK solves: seconds on a loaded machine, not a stall
        ik.reset(qpos)
        standing = ik.joint_positions()
        ik.reset(bent_knees(ik, qpos, gait.knee_bend))
        bent = ik.joint_positions()
    rate = rospy.Rate(1.0 / gait.dt)
    ticks = round(BEND_SECONDS / gait.dt)
    for k in range(1, ticks + 1):  # down into the walking stance
        mover.send({n: standing[n] + (bent[n] - standing[n]) * k / ticks for n in bent})
        rate.sleep()
    attitude = [(0.0, 0.0, 0.0)]  # the pelvis's roll, pitch, yaw (rad) from the IMU
    gyro = [np.zeros(3)]  # its angular velocity (rad/s, pelvis frame)

    def on_imu(msg: Imu) -> None:
        q = msg.orientation
        attitude[0] = (math.atan2(2 * (q.w * q.x + q.y * q.z), 1 - 2 * (q.x * q.x + q.y * q.y)),
                       math.asin(max(-1.0, min(1.0, 2 * (q.w * q.y - q.z * q.x)))),
                       math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z)))
        w = msg.angular_velocity
        gyro[0] = np.array([w.x, w.y, w.z])

    imu = rospy.Subscriber(f"{current().lab.namespace}/imu", Imu, on_imu)
    plans = _PlanPublisher()
    ticks = walk_ticks(ik, qpos, gait, source, imu=lambda: attitude[0],
                       measured=lambda: Measured(mover.measured, mover.velocities,
                                                 *attitude[0][:2], gyro[0]),
                       on_replan=plans)
    try:
        while True:
            # mexone's own planning and IK between two ticks (the first sets up the preview
            # control): the stall watchdog is for a routine's own code, not for this
            with busy("the walk's plan and IK"):
                joints = next(ticks, None)
            if joints is None:
                break
            mover.send(joints)
            plans.catch_up()
            rate.sleep()
    finally:
        imu.unregister()
