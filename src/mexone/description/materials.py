"""Colours: URDF named materials and Gazebo's material names, resolved the way each tool does.

URDF (urdfdom) lets a robot define ``<material name="dark"><color rgba=.../></material>`` once
and visuals name it; Gazebo ignores URDF colours when a link's ``<gazebo><material>`` names a
script such as ``Gazebo/White``. `display_rgba` is the one rule every renderer uses (the GUI,
MuJoCo's geoms, hence videos and the MJCF export).
"""

from __future__ import annotations

from collections.abc import Iterable

from mexone.description.model import Link, RobotModel, Visual

__all__ = ["GAZEBO_COLORS", "DEFAULT_RGBA", "gazebo_rgba", "display_rgba", "apply_named_colors"]

DEFAULT_RGBA = (0.7, 0.7, 0.72, 1.0)  # an unpainted part

# Diffuse colours of Gazebo 7's media/materials/scripts/gazebo.material (textured ones as their
# average colour); keys lower case, as Ogre's material names are matched here case-insensitively.
GAZEBO_COLORS: dict[str, tuple[float, float, float, float]] = {
    "gazebo/grey": (0.7, 0.7, 0.7, 1.0),
    "gazebo/gray": (0.7, 0.7, 0.7, 1.0),
    "gazebo/darkgrey": (0.175, 0.175, 0.175, 1.0),
    "gazebo/darkgray": (0.175, 0.175, 0.175, 1.0),
    "gazebo/lightgrey": (0.85, 0.85, 0.85, 1.0),
    "gazebo/white": (1.0, 1.0, 1.0, 1.0),
    "gazebo/flatblack": (0.1, 0.1, 0.1, 1.0),
    "gazebo/black": (0.05, 0.05, 0.05, 1.0),
    "gazebo/red": (1.0, 0.0, 0.0, 1.0),
    "gazebo/redbright": (0.87, 0.26, 0.07, 1.0),
    "gazebo/green": (0.0, 1.0, 0.0, 1.0),
    "gazebo/blue": (0.0, 0.0, 1.0, 1.0),
    "gazebo/skyblue": (0.13, 0.44, 0.70, 1.0),
    "gazebo/yellow": (1.0, 1.0, 0.0, 1.0),
    "gazebo/zincyellow": (0.97, 0.95, 0.21, 1.0),
    "gazebo/darkyellow": (0.7, 0.7, 0.0, 1.0),
    "gazebo/purple": (1.0, 0.0, 1.0, 1.0),
    "gazebo/turquoise": (0.0, 1.0, 1.0, 1.0),
    "gazebo/orange": (1.0, 0.51, 0.05, 1.0),
    "gazebo/indigo": (0.33, 0.0, 0.5, 1.0),
    "gazebo/gold": (0.8, 0.65, 0.2, 1.0),
    "gazebo/wood": (0.6, 0.4, 0.2, 1.0),
    "gazebo/woodpallet": (0.6, 0.45, 0.3, 1.0),
    "gazebo/bricks": (0.6, 0.3, 0.2, 1.0),
    "gazebo/greytransparent": (0.5, 0.5, 0.5, 0.5),
    "gazebo/bluetransparent": (0.0, 0.0, 1.0, 0.5),
    "gazebo/redtransparent": (1.0, 0.0, 0.0, 0.5),
    "gazebo/greentransparent": (0.0, 1.0, 0.0, 0.5),
    "gazebo/redglow": (1.0, 0.0, 0.0, 1.0),
    "gazebo/greenglow": (0.0, 1.0, 0.0, 1.0),
    "gazebo/blueglow": (0.0, 0.0, 1.0, 1.0),
    "gazebo/yellowglow": (1.0, 1.0, 0.0, 1.0),
    "gazebo/purpleglow": (1.0, 0.0, 1.0, 1.0),
    "gazebo/turquoiseglow": (0.0, 1.0, 1.0, 1.0),
}


def gazebo_rgba(name: str | None) -> tuple[float, float, float, float] | None:
    """The colour of a Gazebo material script name, or None if it is not one of Gazebo's."""
    return GAZEBO_COLORS.get(name.strip().lower()) if name else None


def display_rgba(robot: RobotModel, link: str, visual: Visual) -> tuple[float, ...]:
    """What Gazebo draws: the link's <gazebo><material> if Gazebo knows it, else the visual's
    URDF colour, else unpainted grey."""
    props = robot.gazebo_links.get(link)
    return (gazebo_rgba(props.material if props else None) or visual.rgba or DEFAULT_RGBA)


def apply_named_colors(links: list[Link], named: dict[str, tuple[float, ...]]) -> None:
    """Give visuals that name a material without a colour that material's colour, as urdfdom
    does: robot-level <material>s first, then the first visual that defined the name inline."""
    table = dict(named)
    for link in links:
        for vis in link.visuals:
            if vis.material and vis.rgba is not None:
                table.setdefault(vis.material, vis.rgba)
    for link in links:
        link.visuals = [v if v.rgba is not None or v.material not in table
                        else _with_rgba(v, table[v.material]) for v in link.visuals]


def _with_rgba(visual: Visual, rgba: Iterable[float]) -> Visual:
    from dataclasses import replace

    return replace(visual, rgba=tuple(float(c) for c in rgba))
