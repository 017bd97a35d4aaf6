"""What Gazebo 7 + gazebo_ros_control would have done differently with a controller YAML.

One home for these notes: the manager logs them when it loads a configuration, and
`mexone check --controllers` reports them as findings.
"""

from __future__ import annotations

from mexone.control.spec import ControlConfig, ControllerSpec

__all__ = ["gazebo_differences"]


def gazebo_differences(config: ControlConfig) -> list[tuple[ControllerSpec, str, str]]:
    """(controller, code, note) for each place mexone's behaviour differs from Gazebo 7's."""
    notes = []
    for spec in config.controllers.values():
        if spec.type.startswith("position_controllers/") and spec.pid and not spec.ideal_servo:
            notes.append((spec, "gazebo-position-pid",
                          "Gazebo 7 ignored this pid: block and teleported the joint (SetPosition); "
                          "mexone applies the PID as a torque, so the joint has real dynamics "
                          "(ideal_servo: true restores Gazebo's behaviour)"))
        gains = ([spec.pid] if spec.pid else []) + list((spec.gains or {}).values())
        if any(g.i and not (g.i_clamp_min or g.i_clamp_max) for g in gains):
            notes.append((spec, "pid-no-clamp",
                          "i is set but i_clamp_min/i_clamp_max are 0, so there is no integral "
                          "action (ROS clamps the integral term to 0); set the clamps"))
    return notes
