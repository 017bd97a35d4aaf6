"""Generated Python (Debian's genpy) of the interfaces in ../share: see mexone.ros1.interfaces.
Each sub-folder is a top-level ROS message package (`import gazebo_msgs.srv` once
`interfaces.use_generated()` has put this folder on sys.path)."""
