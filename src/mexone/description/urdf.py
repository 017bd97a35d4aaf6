"""URDF (with Gazebo's ``<gazebo>`` extensions and ros_control ``<transmission>``) <-> RobotModel."""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import replace
from pathlib import Path
from typing import Any

from lxml import etree

from mexone.description.conflicts import Statement, Statements, leaves
from mexone.description.findings import Finding
from mexone.description.materials import apply_named_colors
from mexone.description.model import (
    INERTIA_KEYS,
    JOINT_TYPES,
    MOVING_JOINT_TYPES,
    Box,
    Collision,
    Cylinder,
    Dynamics,
    GazeboLink,
    Geometry,
    Inertial,
    Joint,
    Limit,
    Link,
    Mesh,
    Mimic,
    Pose,
    RobotModel,
    Sphere,
    Transmission,
    Visual,
)
from mexone.description.sensors import (
    MODEL_PLUGINS,
    merge_model_plugin,
    needs_sensor_element,
    read_model_plugin,
    read_sensor,
    write_model_plugin,
    write_sensor,
)
from mexone.description.xmlio import XmlReader

__all__ = ["read_urdf", "parse_urdf", "write_urdf", "fmt"]

_GAZEBO_LINK_NUMBERS = {"mu1": "mu1", "mu2": "mu2", "kp": "kp", "kd": "kd", "maxVel": "max_vel",
                        "minDepth": "min_depth"}
_GAZEBO_JOINT_DYNAMICS = {"axis/dynamics/damping": "damping", "axis/dynamics/friction": "friction"}
# elements urdfdom reads once, the first: a second, different copy is dead
_ONCE = {"link": ("inertial",),
         "joint": ("origin", "axis", "limit", "dynamics", "mimic", "calibration", "safety_controller")}


def read_urdf(path: Path | str, label: str | None = None) -> RobotModel:
    return parse_urdf(XmlReader(path, label=label), Path(path))


def parse_urdf(xml: XmlReader, source: Path | None = None) -> RobotModel:
    root = xml.root
    if root.tag != "robot":
        hint = "an SDF file must end in .sdf or .world" if root.tag == "sdf" else None
        raise xml.fail(root, "is not a URDF root: expected <robot>", hint)
    findings: list[Finding] = []
    model = RobotModel(name=xml.attr(root, "name"), links={}, joints={}, source=source,
                       reader_findings=findings)
    statements = Statements(xml.label, findings)

    for el in root.iterfind("link"):
        link = _link(xml, el)
        if _keep_first(model.links, link, "link", findings):
            _state_once(statements, el, f'link "{link.name}"', _ONCE["link"])
    for el in root.iterfind("joint"):
        joint = _joint(xml, el)
        for end in (joint.parent, joint.child):
            if end not in model.links:
                raise xml.fail(el, f"names link '{end}', which is not defined",
                               "add the <link> or correct the name")
        if _keep_first(model.joints, joint, "joint", findings):
            _state_once(statements, el, f'joint "{joint.name}"', _ONCE["joint"])
    for el in root.iterfind("transmission"):
        model.transmissions.append(_transmission(xml, el))
    for el in root.iterfind("gazebo"):
        _gazebo(xml, el, model, statements)
    apply_named_colors(list(model.links.values()), _named_colors(xml, root))
    return model


def _named_colors(xml: XmlReader, root: etree._Element) -> dict[str, tuple[float, ...]]:
    """Robot-level <material name><color rgba/></material>: what visuals may name."""
    out: dict[str, tuple[float, ...]] = {}
    for el in root.iterfind("material"):
        if (color := el.find("color")) is not None and (name := el.get("name")):
            out.setdefault(name, xml.vector_attr(color, "rgba", count=4))
    return out


def _keep_first(table: dict[str, Any], item: Any, kind: str, findings: list[Finding]) -> bool:
    """Add item unless its name is taken (reported); whether it was added."""
    if item.name in table:
        findings.append(Finding("duplicate-name", "error", f'{kind} "{item.name}"',
                                f"the name is used twice (first on line {table[item.name].line}); "
                                "names must be unique", item.line))
        return False
    table[item.name] = item
    return True


def _state_once(statements: Statements, el: etree._Element, element: str,
                tags: tuple[str, ...]) -> None:
    """Every attribute under the elements urdfdom reads once: a later copy that differs is dead."""
    for tag in tags:
        for copy in el.iterfind(tag):
            for node in copy.iter(etree.Element):
                path = [n.tag for n in node.iterancestors() if el in n.iterancestors()][::-1]
                path.append(node.tag)
                for attr, value in node.attrib.items():
                    quantity = attr if path == ["dynamics"] else f"<{'><'.join(path)}> {attr}"
                    statements.state(element, quantity, Statement(value, f"<{tag}>", node.sourceline),
                                     overrides=False, why=f"urdfdom reads only the first <{node.tag}>")


# ----- reading ---------------------------------------------------------------------------------
def _origin(xml: XmlReader, parent: etree._Element) -> Pose:
    el = parent.find("origin")
    if el is None:
        return Pose()
    return Pose(xml.vector_attr(el, "xyz", (0, 0, 0)), xml.vector_attr(el, "rpy", (0, 0, 0)))


def _geometry(xml: XmlReader, parent: etree._Element) -> Geometry:
    geo = xml.child(parent, "geometry", required=True)
    shapes = [c for c in geo if c.tag in ("box", "cylinder", "sphere", "mesh")]
    if len(shapes) != 1:
        raise xml.fail(geo, f"must hold exactly one of box, cylinder, sphere, mesh (found {len(shapes)})")
    el = shapes[0]
    if el.tag == "box":
        return Box(xml.vector_attr(el, "size"))
    if el.tag == "cylinder":
        return Cylinder(xml.float_attr(el, "radius"), xml.float_attr(el, "length"))
    if el.tag == "sphere":
        return Sphere(xml.float_attr(el, "radius"))
    return Mesh(xml.attr(el, "filename"), xml.vector_attr(el, "scale", (1, 1, 1)))


def _link(xml: XmlReader, el: etree._Element) -> Link:
    link = Link(name=xml.attr(el, "name"), line=el.sourceline)
    inertial = el.find("inertial")
    if inertial is not None:
        mass = xml.child(inertial, "mass", required=True)
        tensor = xml.child(inertial, "inertia", required=True)
        link.inertial = Inertial(
            mass=xml.float_attr(mass, "value"),
            inertia=tuple(xml.float_attr(tensor, k) for k in INERTIA_KEYS),
            origin=_origin(xml, inertial),
        )
    for vis in el.iterfind("visual"):
        material, rgba = None, None
        mat = vis.find("material")
        if mat is not None:
            material = mat.get("name")
            color = mat.find("color")
            if color is not None:
                rgba = xml.vector_attr(color, "rgba", count=4)
        link.visuals.append(Visual(_geometry(xml, vis), _origin(xml, vis), vis.get("name"),
                                   material, rgba, vis.sourceline))
    for col in el.iterfind("collision"):
        link.collisions.append(Collision(_geometry(xml, col), _origin(xml, col), col.get("name"),
                                         col.sourceline))
    return link


def _joint(xml: XmlReader, el: etree._Element) -> Joint:
    name = xml.attr(el, "name")
    jtype = xml.attr(el, "type")
    if jtype not in JOINT_TYPES:
        raise xml.fail(el, f"has unknown type '{jtype}'", "use one of " + ", ".join(JOINT_TYPES))
    parent = xml.attr(xml.child(el, "parent", required=True), "link")
    child = xml.attr(xml.child(el, "child", required=True), "link")
    axis: tuple[float, ...] = (1.0, 0.0, 0.0)
    axis_el = el.find("axis")
    if axis_el is not None:
        axis = xml.vector_attr(axis_el, "xyz", (1, 0, 0))
        if not any(axis):  # urdfdom reads no axis on fixed and floating joints: nor do we
            if jtype in MOVING_JOINT_TYPES:
                raise xml.fail(axis_el, "has a zero axis", "give the rotation axis, e.g. xyz=\"0 0 1\"")
            axis = (1.0, 0.0, 0.0)
    limit = None
    limit_el = el.find("limit")
    if limit_el is not None:
        limit = Limit(
            lower=xml.float_attr(limit_el, "lower", 0.0),
            upper=xml.float_attr(limit_el, "upper", 0.0),
            effort=xml.float_attr(limit_el, "effort"),
            velocity=xml.float_attr(limit_el, "velocity"),
        )
    elif jtype in ("revolute", "prismatic"):
        raise xml.fail(el, f"is {jtype} but has no <limit>",
                       "add <limit lower upper effort velocity>; URDF requires it")
    dynamics = Dynamics()
    dyn = el.find("dynamics")
    if dyn is not None:
        dynamics = Dynamics(xml.float_attr(dyn, "damping", 0.0), xml.float_attr(dyn, "friction", 0.0),
                            xml.float_attr(dyn, "armature", 0.0))
    mimic = None
    if (mim := el.find("mimic")) is not None:
        mimic = Mimic(xml.attr(mim, "joint"), xml.float_attr(mim, "multiplier", 1.0),
                      xml.float_attr(mim, "offset", 0.0), mim.sourceline)
    return Joint(name, jtype, parent, child, _origin(xml, el), axis, limit, dynamics, el.sourceline,
                 mimic)


def _transmission(xml: XmlReader, el: etree._Element) -> Transmission:
    name = xml.attr(el, "name")
    joint = xml.child(el, "joint", required=True)
    actuator = el.find("actuator")
    # ros_control reads the hardwareInterface under <joint>; older files put it under <actuator>
    iface = joint.findtext("hardwareInterface") or (
        actuator.findtext("hardwareInterface") if actuator is not None else None)
    reduction = 1.0
    if actuator is not None and actuator.find("mechanicalReduction") is not None:
        reduction = xml.text_number(actuator, "mechanicalReduction")
    return Transmission(
        name=name,
        joint=xml.attr(joint, "name"),
        type=(el.findtext("type") or el.get("type") or "transmission_interface/SimpleTransmission").strip(),
        hardware_interface=(iface or "hardware_interface/EffortJointInterface").strip(),
        actuator=actuator.get("name") if actuator is not None else None,
        mechanical_reduction=reduction,
        line=el.sourceline,
    )


def _gazebo(xml: XmlReader, el: etree._Element, model: RobotModel, statements: Statements) -> None:
    ref = el.get("reference")
    if ref is None:
        for plugin in el.iterfind("plugin"):
            if (sensor := read_model_plugin(xml, plugin)) is not None:
                merge_model_plugin(model.sensors, sensor)
            elif (ns := plugin.findtext("robotNamespace")) is not None:
                model.ros_namespace = ns.strip()
        return
    for sensor in el.iterfind("sensor"):
        on_link = ref in model.links
        if not on_link and ref not in model.joints:
            break  # reported below, with the reference
        model.sensors.append(read_sensor(xml, sensor, link=ref if on_link else None,
                                         joint=None if on_link else ref))
    if ref in model.links or ref in model.joints:
        # in file order, each value overriding the one before, as Gazebo's URDF parser applies them
        on_link = ref in model.links
        element = f'{"link" if on_link else "joint"} "{ref}"'
        if on_link:
            props = model.gazebo_links.setdefault(ref, GazeboLink(line=el.sourceline))
        for path, leaf in leaves(el, skip=("sensor", "plugin")):
            text = (leaf.text or "").strip()
            if text:
                quantity = _GAZEBO_JOINT_DYNAMICS.get(path) if not on_link else None
                statements.state(
                    element, quantity or f"<{path.replace('/', '><')}>",
                    Statement(text, f'<gazebo reference="{ref}">', leaf.sourceline), overrides=True,
                    why="Gazebo applies <gazebo reference> over the URDF, later over earlier")
            if on_link:
                _gazebo_link_value(xml, props, path, leaf, text)
            elif path in _GAZEBO_JOINT_DYNAMICS and text:
                current = model.gazebo_joints.get(ref, model.joints[ref].dynamics)
                model.gazebo_joints[ref] = replace(current, **{
                    _GAZEBO_JOINT_DYNAMICS[path]: xml.number(leaf, text, "value")})
    else:
        model.reader_findings.append(Finding(
            "gazebo-unknown-reference", "warning", f'<gazebo reference="{ref}">',
            "names no link or joint; Gazebo ignores it silently: correct the name", el.sourceline))


def _gazebo_link_value(xml: XmlReader, props: GazeboLink, path: str, leaf: etree._Element,
                       text: str) -> None:
    if path == "selfCollide":
        props.self_collide = xml.bool_of(leaf)
    elif path in _GAZEBO_LINK_NUMBERS:
        setattr(props, _GAZEBO_LINK_NUMBERS[path], xml.number(leaf, text, "value"))
    elif path == "material":
        props.material = text


# ----- writing ---------------------------------------------------------------------------------
def fmt(value: float) -> str:
    """Text that reads back to the same float within 1e-12; noise below 1e-15 prints as 0."""
    value = float(value)
    if abs(value) < 1e-15:  # rounding noise from frame algebra
        return "0"
    return format(value, ".12g")


def _vec(values: Iterable[float]) -> str:
    return " ".join(fmt(v) for v in values)


def _sub(parent: etree._Element, tag: str, text: str | None = None, **attrs: str | None) -> etree._Element:
    el = etree.SubElement(parent, tag, {k: v for k, v in attrs.items() if v is not None})
    if text is not None:
        el.text = text
    return el


def _write_origin(parent: etree._Element, pose: Pose) -> None:
    if not pose.is_identity():
        _sub(parent, "origin", xyz=_vec(pose.xyz), rpy=_vec(pose.rpy))


def _write_geometry(parent: etree._Element, geometry: Geometry) -> None:
    geo = _sub(parent, "geometry")
    match geometry:
        case Box(size):
            _sub(geo, "box", size=_vec(size))
        case Cylinder(radius, length):
            _sub(geo, "cylinder", radius=fmt(radius), length=fmt(length))
        case Sphere(radius):
            _sub(geo, "sphere", radius=fmt(radius))
        case Mesh(filename, scale):
            _sub(geo, "mesh", filename=filename, scale=None if scale == (1, 1, 1) else _vec(scale))


def write_urdf(model: RobotModel, comment: str | None = None) -> str:
    robot = etree.Element("robot", name=model.name)
    if comment:
        robot.append(etree.Comment(comment))
    for link in model.links.values():
        el = _sub(robot, "link", name=link.name)
        if link.inertial:
            inertial = _sub(el, "inertial")
            _write_origin(inertial, link.inertial.origin)
            _sub(inertial, "mass", value=fmt(link.inertial.mass))
            values = zip(INERTIA_KEYS, link.inertial.inertia, strict=True)
            _sub(inertial, "inertia", **{k: fmt(v) for k, v in values})
        for vis in link.visuals:
            v = _sub(el, "visual", name=vis.name)
            _write_origin(v, vis.origin)
            _write_geometry(v, vis.geometry)
            if vis.material or vis.rgba:
                mat = _sub(v, "material", name=vis.material or f"{link.name}_color")
                if vis.rgba:
                    _sub(mat, "color", rgba=_vec(vis.rgba))
        for col in link.collisions:
            c = _sub(el, "collision", name=col.name)
            _write_origin(c, col.origin)
            _write_geometry(c, col.geometry)
    for joint in model.joints.values():
        el = _sub(robot, "joint", name=joint.name, type=joint.type)
        _write_origin(el, joint.origin)
        _sub(el, "parent", link=joint.parent)
        _sub(el, "child", link=joint.child)
        if joint.type != "fixed":
            _sub(el, "axis", xyz=_vec(joint.axis))
        if joint.limit:
            lim = joint.limit
            _sub(el, "limit", lower=fmt(lim.lower), upper=fmt(lim.upper), effort=fmt(lim.effort),
                 velocity=fmt(lim.velocity))
        dyn = joint.dynamics
        if joint.moving and (dyn.damping or dyn.friction or dyn.armature):
            _sub(el, "dynamics", damping=fmt(dyn.damping), friction=fmt(dyn.friction),
                 armature=fmt(dyn.armature) if dyn.armature else None)
        if joint.mimic is not None:
            _sub(el, "mimic", joint=joint.mimic.joint, multiplier=fmt(joint.mimic.multiplier),
                 offset=fmt(joint.mimic.offset))
    for tx in model.transmissions:
        el = _sub(robot, "transmission", name=tx.name)
        _sub(el, "type", tx.type)
        _sub(_sub(el, "joint", name=tx.joint), "hardwareInterface", tx.hardware_interface)
        act = _sub(el, "actuator", name=tx.actuator or f"{tx.joint}_motor")
        _sub(act, "mechanicalReduction", fmt(tx.mechanical_reduction))
    _write_gazebo(robot, model)
    etree.indent(robot, space="  ")
    return '<?xml version="1.0"?>\n' + etree.tostring(robot, encoding="unicode") + "\n"


def _write_gazebo(robot: etree._Element, model: RobotModel) -> None:
    for name, props in model.gazebo_links.items():
        el = _sub(robot, "gazebo", reference=name)
        if props.self_collide is not None:
            _sub(el, "selfCollide", "true" if props.self_collide else "false")
        for tag, attr in _GAZEBO_LINK_NUMBERS.items():
            if (value := getattr(props, attr)) is not None:
                _sub(el, tag, fmt(value))
        if props.material:
            _sub(el, "material", props.material)
    for name, dyn in model.gazebo_joints.items():
        dynamics = _sub(_sub(_sub(robot, "gazebo", reference=name), "axis"), "dynamics")
        _sub(dynamics, "damping", fmt(dyn.damping))
        _sub(dynamics, "friction", fmt(dyn.friction))
    for sensor in model.sensors:
        holder = sensor.joint or sensor.link  # a joint's sensor (force-torque) in its joint's block
        if needs_sensor_element(sensor):
            write_sensor(_sub(robot, "gazebo", reference=holder), sensor, fmt)
        if sensor.plugin in MODEL_PLUGINS:
            write_model_plugin(_sub(robot, "gazebo"), sensor, fmt)
    if model.ros_namespace is not None:
        plugin = _sub(_sub(robot, "gazebo"), "plugin", name="gazebo_ros_control",
                      filename="libgazebo_ros_control.so")
        _sub(plugin, "robotNamespace", model.ros_namespace)
        _sub(plugin, "robotSimType", "gazebo_ros_control/DefaultRobotHWSim")
