"""What Gazebo 7 + gazebo_ros_control would have done differently with a controller YAML.

One home for these notes: the manager logs them when it loads a configuration, and
`mexone check --controllers` reports them as findings.
"""

from __future__ import annotations

from dataclasses import dataclass

from mexone.control.spec import ControlConfig, ControllerSpec

__all__ = ["gazebo_differences", "GazeboNote"]


@dataclass(frozen=True)
class GazeboNote:
    spec: ControllerSpec
    code: str  # the `mexone check` finding code
    severity: str  # as a check finding: info or warning
    text: str


def gazebo_differences(config: ControlConfig) -> list[GazeboNote]:
    """Each place where this configuration behaves differently than under Gazebo 7, or does
    something the user probably did not mean (ROS semantics kept on purpose)."""
    notes = []
    for spec in config.controllers.values():
        if spec.type.startswith("position_controllers/") and spec.pid and not spec.ideal_servo:
            notes.append(GazeboNote(
                spec, "position-controller-pid", "info",
                "Gazebo 7 ignored this pid: block and teleported the joint (SetPosition); mexone "
                "applies the PID as a torque, so the joint has real dynamics (ideal_servo: true "
                "restores Gazebo's behaviour)"))
        gains = ([spec.pid] if spec.pid else []) + list((spec.gains or {}).values())
        unclamped = [g for g in gains if g.i and not (g.i_clamp_min or g.i_clamp_max)]
        if unclamped:
            notes.append(GazeboNote(
                spec, "pid-integral-unclamped", "warning",
                f"i: {unclamped[0].i:g} without i_clamp_min/i_clamp_max gives no integral action "
                "(ROS clamps the integral term to 0); set the clamps"))
    return notes
