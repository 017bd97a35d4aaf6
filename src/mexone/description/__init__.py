"""Robot descriptions: the one in-memory RobotModel every reader (URDF, xacro, SDF, MJCF)
produces and every layer consumes, its writers, conversions and `mexone check`'s lint."""
