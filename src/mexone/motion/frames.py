"""The frames whole-body motion commands: every link (at its origin) and, for Mex-One, the named
end effectors its package declares (hands at the forearm tips, feet at the sole centres, the
camera), so a student writes reach("l_hand", ...) instead of an offset from a link."""

from __future__ import annotations

from dataclasses import dataclass

from mexone.description.model import RobotModel
from mexone.robots import mex_one

__all__ = ["Frame", "frames_for"]


@dataclass(frozen=True)
class Frame:
    name: str
    link: str
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)

    @property
    def site(self) -> str:
        """The site the IK model carries for it."""
        return f"motion/{self.name}"


def frames_for(robot: RobotModel) -> dict[str, Frame]:
    """Every link as a frame, and the robot's named end effectors (which win over a link of the
    same name: Mex-One's "l_foot" is the sole, not the ankle joint)."""
    frames = {name: Frame(name, name) for name in robot.links}
    named = mex_one.END_EFFECTORS
    if all(link in robot.links for link, _ in named.values()):
        frames |= {name: Frame(name, link, offset) for name, (link, offset) in named.items()}
    return frames
