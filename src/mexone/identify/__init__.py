"""`mexone identify`: fit a robot model's joint damping, friction, armature, link masses or
controller gains to recorded bags, with MuJoCo's own system identification (mujoco.sysid).

recording (bag -> samples and commands) -> replay (commands through mexone's controllers ->
actuator controls) -> problem (sysid parameters, residual, fit, intervals) -> session (the whole
job) -> outputs (patched URDF/YAML, JSON, report)."""
