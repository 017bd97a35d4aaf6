"""The walking stack: torque-level walking from swappable parts, each a PythonController chained
in the controller manager's loop (docs/walking-stack.md). A core layer above control."""
