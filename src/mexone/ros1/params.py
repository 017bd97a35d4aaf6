"""Controller configurations on the ROS parameter server, as `rosparam load` of a controller
YAML puts them there (read by the bridge's start and by /gazebo/spawn_urdf_model)."""

from __future__ import annotations

import yaml

from mexone.control.config import parse_control_config
from mexone.control.spec import ControlConfig
from mexone.errors import MexoneError

__all__ = ["config_from_param_server", "controllers_at"]


def config_from_param_server(rospy, namespace: str) -> ControlConfig:
    """The controller configuration a `rosparam load` of the seed's YAML put under /<ns>."""
    key = "/" + namespace.strip("/")
    try:
        params = rospy.get_param(key)
    except KeyError:
        raise MexoneError(f"no controller configuration at {key} on the parameter server",
                          hint="rosparam load your controllers.yaml first, or pass "
                               "--controllers YAML") from None
    return parse_control_config(yaml.safe_dump({namespace.strip("/"): _controllers_only(params)}))


def controllers_at(rospy, namespace: str) -> ControlConfig:
    """The controllers on the parameter server under /<ns>, possibly none (a robot spawned
    before its controllers.yaml was loaded: the spawner's load_controller reads them later)."""
    ns = namespace.strip("/")
    params = rospy.get_param("/" + ns, {})
    return parse_control_config(yaml.safe_dump({ns: _controllers_only(params)}))


def _controllers_only(params) -> dict:
    """The entries of a namespace that are controllers (a `type:`) or gazebo_ros_control's gains;
    a namespace also holds robot_description, dynamic_reconfigure's values, ..."""
    if not isinstance(params, dict):
        return {}
    return {k: v for k, v in params.items()
            if (isinstance(v, dict) and "type" in v) or k == "gazebo_ros_control"}
