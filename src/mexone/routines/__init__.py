"""Routines in lockstep with the simulation: the runtime a routine's rospy calls reach, the
runner that starts and stops them, and the shipped routines."""
