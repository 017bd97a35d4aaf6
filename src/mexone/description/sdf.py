"""SDF model (as Gazebo's model editor writes it, SDF 1.4-1.9) <-> RobotModel.

This is the seed's chapter 3.3 done by the machine. SDF places every link in the model frame
and every joint relative to its child link; URDF puts each child link's frame *at* its joint.
So a child link's URDF frame is the SDF joint frame, and everything attached to the link is
re-expressed in it. What URDF cannot say (ball joints, loops, several models) is an error.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from lxml import etree

from mexone.description.model import (
    INERTIA_KEYS,
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
from mexone.description.transforms import invert, make_transform
from mexone.description.urdf import fmt
from mexone.description.xmlio import XmlReader
from mexone.errors import UnsupportedError

__all__ = ["read_sdf", "write_sdf", "sdf_version"]

_KNOWN_VERSIONS = tuple((1, minor) for minor in (0, *range(2, 13)))  # SDFormat 1.0 .. 1.12
_UNBOUNDED = 1e15  # SDF writes +-1e16 for "no limit"; anything beyond this is a continuous joint
_URDF_TYPES = {"revolute": "revolute", "continuous": "continuous", "prismatic": "prismatic",
               "fixed": "fixed"}
_MODEL_FRAME = ("", "__model__")
_ENVIRONMENT_MODELS = ("model://ground_plane", "model://sun")


# ----- reading ---------------------------------------------------------------------------------
class _SdfModel:
    """One <model> with a resolver for the poses of its links, joints and frames."""

    def __init__(self, xml: XmlReader, el: etree._Element, version: tuple[int, int]) -> None:
        self.xml, self.el, self.version = xml, el, version
        self.links = self._named(el, "link")
        self.joints = self._named(el, "joint")
        self.frames = self._named(el, "frame")
        self._cache: dict[str, np.ndarray] = {}

    def _named(self, el: etree._Element, tag: str) -> dict[str, etree._Element]:
        """name -> element; sdformat refuses a name used twice, and so do we."""
        out: dict[str, etree._Element] = {}
        for child in el.iterfind(tag):
            name = self.xml.attr(child, "name")
            if name in out:
                raise self.xml.fail(child, f"reuses the name of the <{tag}> on line "
                                           f"{out[name].sourceline}", "names must be unique")
            out[name] = child
        return out

    def pose(self, el: etree._Element) -> np.ndarray:
        """The element's own <pose> as a matrix (relative to whatever it is relative to)."""
        pose = el.find("pose")
        if pose is None or not (pose.text or "").strip():
            return np.eye(4)
        text = pose.text.strip()
        fmt_ = pose.get("rotation_format", "euler_rpy")
        if fmt_ == "quat_xyzw":
            x, y, z, qx, qy, qz, qw = self.xml.numbers(pose, text, 7, "value")
            out = np.eye(4)
            out[:3, :3] = _quat_matrix(qw, qx, qy, qz)
            out[:3, 3] = (x, y, z)
            return out
        values = self.xml.numbers(pose, text, 6, "value")
        rpy = np.radians(values[3:]) if pose.get("degrees") == "true" else values[3:]
        return make_transform(values[:3], rpy)

    def _relative_to(self, el: etree._Element, default: str) -> str:
        pose = el.find("pose")
        if pose is None:
            return default
        # SDF 1.7+ says relative_to; 1.5-1.6 had an experimental frame attribute, '' by default
        return pose.get("relative_to") or pose.get("frame") or default

    def _placement(self, name: str, line_el: etree._Element) -> tuple[str, etree._Element]:
        """(the frame a named link, joint or frame is placed relative to, its element)."""
        if name in self.links:
            el = self.links[name]
            return self._relative_to(el, "__model__"), el
        if name in self.joints:
            el = self.joints[name]
            return self._relative_to(el, self.xml.text(el, "child") or ""), el
        if name in self.frames:
            el = self.frames[name]
            return self._relative_to(el, el.get("attached_to") or "__model__"), el
        raise self.xml.fail(line_el, f"refers to frame '{name}', which is not in the model")

    def frame_of(self, name: str, line_el: etree._Element) -> np.ndarray:
        """Model-frame pose of a named link, joint or frame (iterative: a chain of 1000
        relative_to frames is deeper than Python's recursion limit)."""
        chain: list[tuple[str, etree._Element]] = []
        on_chain: set[str] = set()
        current, where = name, line_el
        while current not in _MODEL_FRAME and current not in self._cache:
            if current in on_chain:
                raise self.xml.fail(where, f"pose frames form a cycle through '{current}'")
            on_chain.add(current)
            base, el = self._placement(current, where)
            chain.append((current, el))
            current, where = base, el
        pose = np.eye(4) if current in _MODEL_FRAME else self._cache[current]
        for frame, el in reversed(chain):
            pose = pose @ self.pose(el)
            self._cache[frame] = pose
        return pose


def _quat_matrix(w: float, x: float, y: float, z: float) -> np.ndarray:
    n = np.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def read_sdf(path: Path | str) -> RobotModel:
    path = Path(path)
    xml = XmlReader(path)
    root = xml.root
    if root.tag != "sdf":
        raise xml.fail(root, "is not an SDF root: expected <sdf>",
                       "a URDF file must end in .urdf" if root.tag == "robot" else None)
    version = sdf_version(xml, root)
    models = list(root.iterfind("model")) + list(root.iterfind("world/model"))
    if not models:
        raise xml.fail(root, "holds no <model>", "convert a model.sdf, not a world with includes")
    if len(models) > 1:
        names = ", ".join(m.get("name", "?") for m in models)
        raise UnsupportedError(f"holds {len(models)} models ({names}); URDF describes one robot",
                               file=path, line=models[1].sourceline,
                               hint="keep the robot's <model> only")
    if (nested := models[0].find("model")) is not None:
        raise UnsupportedError("nested <model> cannot be written as URDF", file=path,
                               line=nested.sourceline, hint="merge the nested model's links first")
    for include in (*models[0].iterfind("include"), *root.iterfind("world/include")):
        uri = (include.findtext("uri") or "").strip()
        if include.getparent() is not models[0] and uri in _ENVIRONMENT_MODELS:
            continue  # a world's ground and sun: the environment, not the robot (see --world)
        raise UnsupportedError(f"<include> of '{uri}' is not read: mexone does not merge included "
                               "models into the robot", file=path, line=include.sourceline,
                               hint="paste the included model's links and joints into this model")
    sdf = _SdfModel(xml, models[0], version)
    return _to_model(sdf, path)


def sdf_version(xml: XmlReader, root: etree._Element) -> tuple[int, int]:
    """(major, minor) of <sdf version>: '1.10' is after '1.9', which float() gets wrong."""
    text = root.get("version", "1.6").strip()
    major, dot, minor = text.partition(".")
    version = (int(major), int(minor)) if dot and major.isdigit() and minor.isdigit() else None
    if version not in _KNOWN_VERSIONS:
        raise xml.fail(root, f"has version '{text}', which is not an SDFormat version (1.0 to 1.12)",
                       "Gazebo 7 writes 1.6; correct the version attribute")
    return version


def _to_model(sdf: _SdfModel, path: Path) -> RobotModel:
    xml = sdf.xml
    model = RobotModel(name=xml.attr(sdf.el, "name"), links={}, joints={}, source=path)
    joints = list(sdf.joints.values())
    parent_of: dict[str, str] = {}
    for el in joints:
        child = xml.text(el, "child")
        parent = xml.text(el, "parent")
        if not child or not parent:
            raise xml.fail(el, "needs both <parent> and <child>")
        for end in (child, parent):
            if end not in sdf.links and end != "world":
                raise xml.fail(el, f"names link '{end}', which is not in the model")
        if child in parent_of:
            raise UnsupportedError(
                f"link '{child}' is the child of two joints: a closed loop cannot be written as URDF",
                file=path, line=el.sourceline, hint="cut the loop, e.g. drop one joint")
        parent_of[child] = xml.attr(el, "name")
    world_fixed = any(xml.text(el, "parent") == "world" for el in joints)
    roots = [name for name in sdf.links if name not in parent_of] + ["world"] * world_fixed
    if len(roots) != 1:
        raise UnsupportedError(
            f"the links form {len(roots)} separate trees ({', '.join(roots) or 'none'}); "
            "URDF needs exactly one root", file=path, line=sdf.el.sourceline,
            hint="join the parts with fixed joints")

    # URDF frame of each link: a child link sits at its joint; the root is the model frame, so
    # its parts keep their model-frame placement (the seed adds the link's "general pose").
    frames = {name: sdf.frame_of(parent_of[name], sdf.links[name]) if name in parent_of
              else np.eye(4) for name in sdf.links}
    if world_fixed:
        model.links["world"] = Link("world")
        frames["world"] = invert(sdf.pose(sdf.el))  # model pose: where the base is welded
    for name, el in sdf.links.items():
        model.links[name] = _link(sdf, el, name, invert(frames[name]) @ sdf.frame_of(name, el), model)
    for el in joints:
        joint = _joint(sdf, el, frames)
        model.joints[joint.name] = joint
        dyn = joint.dynamics
        if dyn.damping or dyn.friction:
            model.gazebo_joints[joint.name] = dyn
    _plugins(sdf, model)
    return model


def _geometry(sdf: _SdfModel, parent: etree._Element) -> Geometry:
    xml = sdf.xml
    geo = xml.child(parent, "geometry", required=True)
    if (box := geo.find("box")) is not None:
        size = box.find("size")
        return Box(xml.numbers(size, size.text or "", 3, "value") if size is not None else (1, 1, 1))
    if (cyl := geo.find("cylinder")) is not None:
        return Cylinder(xml.text_number(cyl, "radius", 1.0), xml.text_number(cyl, "length", 1.0))
    if (sph := geo.find("sphere")) is not None:
        return Sphere(xml.text_number(sph, "radius", 1.0))
    if (mesh := geo.find("mesh")) is not None:
        uri = xml.text(mesh, "uri")
        if not uri:
            raise xml.fail(mesh, "has no <uri>")
        scale_el = mesh.find("scale")
        scale = xml.numbers(scale_el, scale_el.text or "", 3, "value") if scale_el is not None \
            else (1.0, 1.0, 1.0)
        return Mesh(uri, scale)
    kinds = ", ".join(c.tag for c in geo) or "nothing"
    raise UnsupportedError(f"geometry {kinds} has no URDF equivalent", file=xml.label,
                           line=geo.sourceline, hint="use a box, cylinder, sphere or mesh")


def _link(sdf: _SdfModel, el: etree._Element, name: str, to_urdf: np.ndarray,
          model: RobotModel) -> Link:
    """to_urdf: the SDF link frame expressed in the link's URDF frame."""
    xml = sdf.xml
    link = Link(name, line=el.sourceline)
    inertial = el.find("inertial")
    if inertial is None:
        # SDF's default inertial is 1 kg with unit moments; Gazebo simulates exactly that
        link.inertial = Inertial(1.0, (1, 0, 0, 1, 0, 1), Pose.from_matrix(to_urdf))
    else:
        tensor = inertial.find("inertia")
        defaults = (1, 0, 0, 1, 0, 1)
        moments = tuple(xml.text_number(tensor, k, d) for k, d in zip(INERTIA_KEYS, defaults, strict=True)) \
            if tensor is not None else defaults
        link.inertial = Inertial(xml.text_number(inertial, "mass", 1.0), moments,
                                 Pose.from_matrix(to_urdf @ sdf.pose(inertial)))
    props = GazeboLink(line=el.sourceline)
    props.self_collide = xml.text_bool(el, "self_collide")
    for vis in el.iterfind("visual"):
        script = vis.findtext("material/script/name")
        rgba = None
        if (diffuse := vis.find("material/diffuse")) is not None:
            rgba = xml.numbers(diffuse, diffuse.text or "", 4, "value")
        link.visuals.append(Visual(_geometry(sdf, vis), Pose.from_matrix(to_urdf @ sdf.pose(vis)),
                                   vis.get("name"), None, rgba, vis.sourceline))
        if script and props.material is None:
            props.material = script.strip()
    for col in el.iterfind("collision"):
        link.collisions.append(Collision(_geometry(sdf, col),
                                         Pose.from_matrix(to_urdf @ sdf.pose(col)),
                                         col.get("name"), col.sourceline))
        _surface(sdf, col, props)
    if any(v is not None for v in (props.self_collide, props.mu1, props.mu2, props.kp, props.kd,
                                   props.max_vel, props.min_depth, props.material)):
        model.gazebo_links[name] = props
    for sensor_el in el.iterfind("sensor"):
        sensor = read_sensor(xml, sensor_el, link=name)
        sensor.pose = Pose.from_matrix(to_urdf @ sdf.pose(sensor_el))
        model.sensors.append(sensor)
    return link


def _surface(sdf: _SdfModel, col: etree._Element, props: GazeboLink) -> None:
    """Friction and contact of the first collision that states them (URDF keeps one per link)."""
    friction = col.find("surface/friction/ode")
    contact = col.find("surface/contact/ode")
    pairs = [(friction, "mu", "mu1"), (friction, "mu2", "mu2"), (contact, "kp", "kp"),
             (contact, "kd", "kd"), (contact, "max_vel", "max_vel"),
             (contact, "min_depth", "min_depth")]
    for parent, tag, attr in pairs:
        if parent is not None and parent.find(tag) is not None and getattr(props, attr) is None:
            setattr(props, attr, sdf.xml.text_number(parent, tag))


def _joint(sdf: _SdfModel, el: etree._Element, frames: dict[str, np.ndarray]) -> Joint:
    xml = sdf.xml
    name = xml.attr(el, "name")
    sdf_type = xml.attr(el, "type")
    parent, child = xml.text(el, "parent"), xml.text(el, "child")
    if not parent or not child:
        raise xml.fail(el, f"joint '{name}' needs a <parent> and a <child>")
    axis_el = el.find("axis")
    limit = None
    dynamics = Dynamics()
    axis = np.array([1.0, 0.0, 0.0])
    if axis_el is not None:
        xyz_el = xml.child(axis_el, "xyz", required=sdf_type != "fixed")
        if xyz_el is not None:
            axis = np.array(xml.numbers(xyz_el, xyz_el.text or "", 3, "value"))
            if not axis.any():
                raise xml.fail(xyz_el, "is a zero axis", "give the rotation axis, e.g. 0 0 1")
            axis = _axis_in_joint_frame(sdf, axis_el, xyz_el, axis, frames[child])
        lim = axis_el.find("limit")
        if lim is not None:
            limit = Limit(xml.text_number(lim, "lower", -1e16), xml.text_number(lim, "upper", 1e16),
                          xml.text_number(lim, "effort", -1.0), xml.text_number(lim, "velocity", -1.0))
        dyn = axis_el.find("dynamics")
        if dyn is not None:
            dynamics = Dynamics(xml.text_number(dyn, "damping", 0.0), xml.text_number(dyn, "friction", 0.0))
    mimic = _mimic(xml, axis_el) if axis_el is not None else None
    if sdf_type not in _URDF_TYPES:
        raise UnsupportedError(f"joint '{name}' is of type '{sdf_type}', which URDF cannot express",
                               file=xml.label, line=el.sourceline,
                               hint="URDF has revolute, continuous, prismatic and fixed joints")
    urdf_type = _URDF_TYPES[sdf_type]
    unbounded = limit is None or (limit.lower < -_UNBOUNDED and limit.upper > _UNBOUNDED)
    if urdf_type == "revolute" and unbounded:
        urdf_type = "continuous"
    if urdf_type in ("revolute", "prismatic") and limit is None:
        limit = Limit(0.0, 0.0, -1.0, -1.0)
    if urdf_type == "continuous":
        limit = Limit(0.0, 0.0, limit.effort, limit.velocity) if limit else None
    origin = Pose.from_matrix(invert(frames[parent]) @ frames[child])
    return Joint(name, urdf_type, parent, child, origin, tuple(float(v) for v in axis), limit,
                 dynamics, el.sourceline, mimic)


def _mimic(xml: XmlReader, axis_el: etree._Element) -> Mimic | None:
    """SDF 1.11's <mimic joint=...>: follower = multiplier (leader - reference) + offset."""
    el = axis_el.find("mimic")
    if el is None:
        return None
    multiplier = xml.text_number(el, "multiplier", 1.0)
    offset = xml.text_number(el, "offset", 0.0) - multiplier * xml.text_number(el, "reference", 0.0)
    return Mimic(xml.attr(el, "joint"), multiplier, offset, el.sourceline)


def _axis_in_joint_frame(sdf: _SdfModel, axis_el: etree._Element, xyz_el: etree._Element,
                         axis: np.ndarray,
                         joint_frame: np.ndarray) -> np.ndarray:
    """Rotate the SDF axis into the joint frame, whatever frame this SDF version wrote it in."""
    expressed_in = xyz_el.get("expressed_in")
    if expressed_in is None:
        use_model = sdf.xml.text_bool(axis_el, "use_parent_model_frame")
        # SDF 1.4 wrote axes in the model frame; 1.5 added the flag, default: the joint frame
        in_model = use_model if use_model is not None else sdf.version < (1, 5)
        if not in_model:
            return axis / np.linalg.norm(axis)
        expressed_in = "__model__"
    frame = sdf.frame_of(expressed_in, xyz_el)
    out = joint_frame[:3, :3].T @ frame[:3, :3] @ axis
    return out / np.linalg.norm(out)


def _plugins(sdf: _SdfModel, model: RobotModel) -> None:
    for joint_el in sdf.joints.values():  # force-torque sensors live in their joint
        for sensor_el in joint_el.iterfind("sensor"):
            model.sensors.append(read_sensor(sdf.xml, sensor_el, joint=joint_el.get("name")))
    for plugin in sdf.el.iterfind("plugin"):
        if (sensor := read_model_plugin(sdf.xml, plugin)) is not None:
            merge_model_plugin(model.sensors, sensor)
        elif (ns := plugin.findtext("robotNamespace")) is not None:
            model.ros_namespace = ns.strip()


# ----- writing ---------------------------------------------------------------------------------
def _sub(parent: etree._Element, tag: str, text: str | None = None, **attrs: str | None) -> etree._Element:
    el = etree.SubElement(parent, tag, attrs)
    if text is not None:
        el.text = text
    return el


def _pose_text(mat: np.ndarray) -> str:
    pose = Pose.from_matrix(mat)
    return " ".join(fmt(v) for v in (*pose.xyz, *pose.rpy))


def _write_geometry(parent: etree._Element, geometry: Geometry) -> None:
    geo = _sub(parent, "geometry")
    match geometry:
        case Box(size):
            _sub(_sub(geo, "box"), "size", " ".join(fmt(v) for v in size))
        case Cylinder(radius, length):
            cyl = _sub(geo, "cylinder")
            _sub(cyl, "radius", fmt(radius))
            _sub(cyl, "length", fmt(length))
        case Sphere(radius):
            _sub(_sub(geo, "sphere"), "radius", fmt(radius))
        case Mesh(filename, scale):
            mesh = _sub(geo, "mesh")
            _sub(mesh, "uri", filename)
            _sub(mesh, "scale", " ".join(fmt(v) for v in scale))


def write_sdf(model: RobotModel) -> str:
    """SDF 1.6 model: link poses in the model frame, joints at their child's origin."""
    if len(model.roots) != 1:
        raise UnsupportedError(f"the model has {len(model.roots)} roots; SDF export needs one tree",
                               file=model.source)
    sdf = etree.Element("sdf", version="1.6")
    el_model = _sub(sdf, "model", name=model.name)
    frames = model.link_frames
    for name in model.links:
        if name == "world":
            continue
        link = model.links[name]
        el = _sub(el_model, "link", name=name)
        _sub(el, "pose", _pose_text(frames[name]), frame="")
        props = model.gazebo_links.get(name, GazeboLink())
        if props.self_collide is not None:
            _sub(el, "self_collide", "1" if props.self_collide else "0")
        if link.inertial:
            inertial = _sub(el, "inertial")
            _sub(inertial, "pose", _pose_text(link.inertial.origin.matrix), frame="")
            _sub(inertial, "mass", fmt(link.inertial.mass))
            tensor = _sub(inertial, "inertia")
            for key, value in zip(INERTIA_KEYS, link.inertial.inertia, strict=True):
                _sub(tensor, key, fmt(value))
        for i, col in enumerate(link.collisions):
            c = _sub(el, "collision", name=col.name or f"{name}_collision_{i}")
            _sub(c, "pose", _pose_text(col.origin.matrix), frame="")
            _write_geometry(c, col.geometry)
            _write_surface(c, props)
        for i, vis in enumerate(link.visuals):
            v = _sub(el, "visual", name=vis.name or f"{name}_visual_{i}")
            _sub(v, "pose", _pose_text(vis.origin.matrix), frame="")
            _write_geometry(v, vis.geometry)
            if props.material or vis.rgba:
                mat = _sub(v, "material")
                if props.material:
                    script = _sub(mat, "script")
                    _sub(script, "uri", "file://media/materials/scripts/gazebo.material")
                    _sub(script, "name", props.material)
                if vis.rgba:
                    rgba = " ".join(fmt(x) for x in vis.rgba)
                    _sub(mat, "ambient", rgba)
                    _sub(mat, "diffuse", rgba)
    for joint in model.joints.values():
        _write_joint(el_model, model, joint)
    for sensor in model.sensors:
        if sensor.joint:  # a joint's sensor (force-torque) lives in its joint
            holder = el_model.find(f"joint[@name='{sensor.joint}']")
        else:
            holder = el_model.find(f"link[@name='{sensor.link}']")
        if holder is not None and needs_sensor_element(sensor):
            write_sensor(holder, sensor, fmt)
        if sensor.plugin in MODEL_PLUGINS:
            write_model_plugin(el_model, sensor, fmt)
    if model.ros_namespace is not None:
        plugin = _sub(el_model, "plugin", name="gazebo_ros_control", filename="libgazebo_ros_control.so")
        _sub(plugin, "robotNamespace", model.ros_namespace)
    etree.indent(sdf, space="  ")
    return '<?xml version="1.0"?>\n' + etree.tostring(sdf, encoding="unicode") + "\n"


def _write_surface(col: etree._Element, props: GazeboLink) -> None:
    if all(v is None for v in (props.mu1, props.mu2, props.kp, props.kd, props.max_vel,
                               props.min_depth)):
        return
    surface = _sub(col, "surface")
    if props.mu1 is not None or props.mu2 is not None:
        ode = _sub(_sub(surface, "friction"), "ode")
        if props.mu1 is not None:
            _sub(ode, "mu", fmt(props.mu1))
        if props.mu2 is not None:
            _sub(ode, "mu2", fmt(props.mu2))
    contact = [(t, v) for t, v in (("kp", props.kp), ("kd", props.kd), ("max_vel", props.max_vel),
                                   ("min_depth", props.min_depth)) if v is not None]
    if contact:
        ode = _sub(_sub(surface, "contact"), "ode")
        for tag, value in contact:
            _sub(ode, tag, fmt(value))


def _write_joint(el_model: etree._Element, model: RobotModel, joint: Joint) -> None:
    if joint.type not in ("revolute", "continuous", "prismatic", "fixed"):
        raise UnsupportedError(f"joint '{joint.name}' of type '{joint.type}' has no SDF export here",
                               file=model.source, line=joint.line)
    if joint.mimic is not None:
        raise UnsupportedError(f"joint '{joint.name}' mimics '{joint.mimic.joint}', which SDF 1.6 "
                               "cannot say (Gazebo 7 ignored <mimic>)", file=model.source,
                               line=joint.line, hint="convert to URDF or MJCF, which keep it")
    sdf_type = "revolute" if joint.type == "continuous" else joint.type
    el = _sub(el_model, "joint", name=joint.name, type=sdf_type)
    _sub(el, "parent", joint.parent)
    _sub(el, "child", joint.child)
    _sub(el, "pose", "0 0 0 0 0 0", frame="")
    if joint.type == "fixed":
        return
    axis = _sub(el, "axis")
    _sub(axis, "xyz", " ".join(fmt(v) for v in joint.axis))
    _sub(axis, "use_parent_model_frame", "0")
    lim = joint.limit or Limit(-1e16, 1e16, -1.0, -1.0)
    lower, upper = (-1e16, 1e16) if joint.type == "continuous" else (lim.lower, lim.upper)
    limit = _sub(axis, "limit")
    for tag, value in (("lower", lower), ("upper", upper), ("effort", lim.effort),
                       ("velocity", lim.velocity)):
        _sub(limit, tag, fmt(value))
    dyn = model.joint_dynamics(joint.name)
    dynamics = _sub(axis, "dynamics")
    _sub(dynamics, "damping", fmt(dyn.damping))
    _sub(dynamics, "friction", fmt(dyn.friction))
