"""Every bus topic, the robot and sim time on the Foxglove WebSocket protocol (foxglove-sdk), for
Foxglove and Lichtblick: a front end, like the GUI."""

from mexone.foxglove.server import DEFAULT_PORT, FOXGLOVE_INSTALL, FoxgloveBridge

__all__ = ["DEFAULT_PORT", "FOXGLOVE_INSTALL", "FoxgloveBridge"]
