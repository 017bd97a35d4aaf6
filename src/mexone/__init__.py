"""mexone: a humanoid-robot simulation lab in Python (Mex-One, MuJoCo, ros_control, ROS names).

Importing mexone changes nothing in the environment: offscreen rendering picks its OpenGL
platform where it starts (mexone.record.video).
"""

__version__ = "0.1.0"
