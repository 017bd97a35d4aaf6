"""Sensors as Gazebo users declare them: ``<sensor>`` blocks (SDF's sensor element, inside a URDF's
``<gazebo reference="link|joint">`` or an SDF ``<link>``/``<joint>``) and the gazebo_ros plugins that
publish them (``libgazebo_ros_imu_sensor.so``, ``libgazebo_ros_imu.so``, ``libgazebo_ros_ft_sensor.so``,
``libgazebo_ros_bumper.so``, ``libgazebo_ros_camera.so``, ``libgazebo_ros_openni_kinect.so``).

The reader keeps what mexone simulates: type, where the sensor sits, its rate, Gazebo's noise model,
the camera's optics, the force-torque sensor's frame and direction, and the ROS names the plugin
would use. Existing robot packages need no mexone-specific markup.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

from lxml import etree

from mexone.description.model import Pose
from mexone.description.xmlio import XmlReader

__all__ = ["Noise", "CameraSpec", "SensorSpec", "SENSOR_TYPES", "MODEL_PLUGINS", "read_sensor",
           "read_model_plugin", "write_sensor", "write_model_plugin", "needs_sensor_element",
           "merge_model_plugin"]

# the types whose SDF elements the reader knows (<imu>, <camera>, <force_torque>, <contact>);
# any other <sensor type="..."> is read with its common elements and kept: whether mexone
# simulates it is the sensor plug-ins' registry's answer (mexone.sensors), asked when the model
# is built, so what a file parses to never depends on what was imported
SENSOR_TYPES = ("imu", "force_torque", "contact", "camera", "depth")
MODEL_PLUGINS = ("libgazebo_ros_imu.so", "libgazebo_ros_ft_sensor.so")  # plugins of the model,
# not of a <sensor>: they name their body or joint themselves
IMU_CHANNELS = tuple(f"{group}/{axis}" for group in ("angular_velocity", "linear_acceleration")
                     for axis in "xyz")


@dataclass(frozen=True)
class Noise:
    """Gazebo's <noise>: gaussian with a bias drawn once per run (bias_mean +- bias_stddev)."""

    type: str = "none"  # none, gaussian, gaussian_quantized
    mean: float = 0.0
    stddev: float = 0.0
    bias_mean: float = 0.0
    bias_stddev: float = 0.0
    precision: float = 0.0  # gaussian_quantized: the output resolution

    @property
    def active(self) -> bool:
        return self.type != "none" and (self.stddev > 0 or self.mean != 0 or self.bias_mean != 0
                                        or self.bias_stddev > 0 or self.precision > 0)


@dataclass(frozen=True)
class CameraSpec:
    """SDF <camera>: the optics of an RGB or depth camera."""

    width: int = 320
    height: int = 240
    horizontal_fov: float = 1.047  # rad, SDF's default
    near: float = 0.1
    far: float = 100.0
    format: str = "R8G8B8"
    noise: Noise = Noise()

    @property
    def vertical_fov(self) -> float:
        """Square pixels: the vertical field of view the aspect ratio implies."""
        return 2.0 * math.atan(math.tan(self.horizontal_fov / 2.0) * self.height / self.width)

    @property
    def focal(self) -> float:
        """Focal length in pixels (fx = fy) of the pinhole model the renderer uses."""
        return (self.width / 2.0) / math.tan(self.horizontal_fov / 2.0)


@dataclass
class SensorSpec:
    name: str
    type: str  # SDF's <sensor type>: one of SENSOR_TYPES or a sensor plug-in's
    link: str | None = None  # the link it is fixed to (force_torque: the joint's child)
    joint: str | None = None  # force_torque: the joint it measures
    pose: Pose = Pose()  # in the link's frame (SDF <sensor><pose>)
    update_rate: float = 0.0  # Hz; 0 as Gazebo: every physics step
    always_on: bool = True
    plugin: str | None = None  # the gazebo_ros plugin's file name, e.g. libgazebo_ros_imu_sensor.so
    namespace: str | None = None  # the plugin's robotNamespace
    topic: str | None = None  # the main topic, as the plugin names it (relative: in the namespace)
    topics: dict[str, str] = field(default_factory=dict)  # cameras: image, camera_info, depth, ...
    frame: str | None = None  # frame_id of its messages (plugin frameName / bodyName)
    noise: dict[str, Noise] = field(default_factory=dict)  # channel -> noise
    camera: CameraSpec | None = None
    ft_frame: str = "child"  # force_torque: child, parent or sensor
    measure_direction: str = "child_to_parent"  # force_torque: or parent_to_child
    collisions: tuple[str, ...] = ()  # contact: the collision elements it watches
    range: tuple[float, float] | None = None  # depth: the valid range (point cloud cutoffs)
    line: int | None = None


# ----- reading -------------------------------------------------------------------------------
def _noise(xml: XmlReader, el: etree._Element | None) -> Noise:
    """SDF 1.5+ <noise type="..."> or SDF 1.4's <noise><type>...</type>."""
    if el is None:
        return Noise()
    kind = el.get("type") or xml.text(el, "type") or "none"
    values = {tag: xml.text_number(el, tag, 0.0) for tag in
              ("mean", "stddev", "bias_mean", "bias_stddev", "precision")}
    if kind not in ("none", "gaussian", "gaussian_quantized"):
        raise xml.fail(el, f"noise type '{kind}' is not one Gazebo knows",
                       "use none, gaussian or gaussian_quantized")
    for tag in ("stddev", "bias_stddev", "precision"):
        if values[tag] < 0:
            raise xml.fail(el, f"noise {tag} {values[tag]:g} is negative", "a spread is >= 0")
    return Noise(kind, **values)


def _imu_noise(xml: XmlReader, imu: etree._Element | None) -> dict[str, Noise]:
    out: dict[str, Noise] = {}
    if imu is None:
        return out
    for group in ("angular_velocity", "linear_acceleration"):  # SDF 1.5+
        for axis in "xyz":
            noise = imu.find(f"{group}/{axis}/noise")
            if noise is not None:
                out[f"{group}/{axis}"] = _noise(xml, noise)
    old = imu.find("noise")  # SDF 1.4: <noise><type/><rate/><accel/></noise>
    if old is not None:
        kind = xml.text(old, "type") or "gaussian"
        for tag, group in (("rate", "angular_velocity"), ("accel", "linear_acceleration")):
            sub = old.find(tag)
            if sub is not None:
                noise = replace(_noise(xml, sub), type=kind)
                for axis in "xyz":
                    out.setdefault(f"{group}/{axis}", noise)
    return out


def _camera(xml: XmlReader, el: etree._Element) -> CameraSpec:
    cam = CameraSpec()
    width = xml.text_number(el, "image/width", cam.width)
    height = xml.text_number(el, "image/height", cam.height)
    fov = xml.text_number(el, "horizontal_fov", cam.horizontal_fov)
    near = xml.text_number(el, "clip/near", cam.near)
    far = xml.text_number(el, "clip/far", cam.far)
    if width < 1 or height < 1 or width != int(width) or height != int(height) \
            or width * height > 4096 * 4096:
        raise xml.fail(el, f"image {width:g} x {height:g} is not a camera size",
                       "whole numbers of pixels, at most 4096 x 4096")
    if not 0.01 < fov < math.pi - 0.01:
        raise xml.fail(el, f"horizontal_fov {fov:g} rad is not a pinhole camera's",
                       "between 0.01 and 3.13 rad (1.047 is 60 degrees)")
    if not 0 < near < far:
        raise xml.fail(el, f"clip near {near:g} / far {far:g}", "0 < near < far, in metres")
    return CameraSpec(int(width), int(height), fov, near, far,
                      xml.text(el, "image/format") or cam.format, _noise(xml, el.find("noise")))


# gazebo_ros plugin parameters -> (our field, output key)
_TOPIC_PARAMS = {
    "libgazebo_ros_imu_sensor.so": {"topicName": "main"},
    "libgazebo_ros_imu.so": {"topicName": "main"},
    "libgazebo_ros_ft_sensor.so": {"topicName": "main"},
    "libgazebo_ros_bumper.so": {"bumperTopicName": "main"},
    "libgazebo_ros_camera.so": {"imageTopicName": "image", "cameraInfoTopicName": "camera_info"},
    "libgazebo_ros_openni_kinect.so": {
        "imageTopicName": "image", "cameraInfoTopicName": "camera_info",
        "depthImageTopicName": "depth", "depthImageCameraInfoTopicName": "depth_camera_info",
        "depthImageInfoTopicName": "depth_camera_info", "pointCloudTopicName": "points"},
}
_DEFAULT_TOPICS = {  # what the plugins publish when their parameters are absent
    "libgazebo_ros_imu_sensor.so": {"main": "imu"},
    "libgazebo_ros_imu.so": {"main": "imu"},
    "libgazebo_ros_ft_sensor.so": {"main": "ft_sensor"},
    "libgazebo_ros_bumper.so": {"main": "bumper_states"},
    "libgazebo_ros_camera.so": {"image": "image_raw", "camera_info": "camera_info"},
    "libgazebo_ros_openni_kinect.so": {"image": "image_raw", "camera_info": "camera_info",
                                       "depth": "depth/image_raw",
                                       "depth_camera_info": "depth/camera_info",
                                       "points": "points"},
}


def _apply_plugin(xml: XmlReader, spec: SensorSpec, plugin: etree._Element) -> SensorSpec:
    """What a gazebo_ros plugin adds: topic names, frame, rate, namespace, extra noise."""
    filename = plugin.get("filename", "")
    spec.plugin = filename
    text = {child.tag: (child.text or "").strip() for child in plugin
            if isinstance(child.tag, str)}
    spec.namespace = text.get("robotNamespace") or spec.namespace
    topics = dict(_DEFAULT_TOPICS.get(filename, {}))
    for param, key in _TOPIC_PARAMS.get(filename, {}).items():
        if text.get(param):
            topics[key] = text[param]
    prefix = text.get("cameraName", "")
    if prefix:
        topics = {k: f"{prefix}/{v}" if not v.startswith("/") else v for k, v in topics.items()}
    spec.topic = topics.pop("main", spec.topic)
    spec.topics.update(topics)
    spec.frame = text.get("frameName") or text.get("bodyName") or spec.frame
    for param in ("updateRateHZ", "updateRate"):
        if text.get(param):
            rate = xml.number(plugin, text[param], param)
            if rate < 0:
                raise xml.fail(plugin, f"{param} {rate:g} is negative", "a rate in Hz, >= 0")
            if rate > 0:
                spec.update_rate = rate
    if text.get("gaussianNoise"):
        stddev = xml.number(plugin, text["gaussianNoise"], "gaussianNoise")
        if stddev < 0:
            raise xml.fail(plugin, f"gaussianNoise {stddev:g} is negative", "a stddev, >= 0")
        if stddev > 0:  # the plugin adds it on top of the sensor's own noise
            channels = IMU_CHANNELS if spec.type == "imu" else \
                tuple(f"{g}/{a}" for g in ("force", "torque") for a in "xyz")
            for channel in channels:
                spec.noise.setdefault(channel, Noise("gaussian", stddev=stddev))
    if filename == "libgazebo_ros_openni_kinect.so":
        low = xml.number(plugin, text.get("pointCloudCutoff") or "0", "pointCloudCutoff")
        high = xml.number(plugin, text.get("pointCloudCutoffMax") or "inf", "pointCloudCutoffMax")
        spec.range = (low, high)
    return spec


def read_sensor(xml: XmlReader, el: etree._Element, link: str | None = None,
                joint: str | None = None) -> SensorSpec:
    """A ``<sensor>`` element (and its gazebo_ros ``<plugin>``), fixed to `link` or on `joint`."""
    kind = el.get("type", "").strip()
    name = el.get("name") or f"{link or joint}_{kind}"
    if not kind:
        raise xml.fail(el, f"sensor '{name}' has no type", "types: " + ", ".join(SENSOR_TYPES)
                       + " (and the sensor plug-ins')")
    if kind == "force_torque" and joint is None:
        raise xml.fail(el, f"force_torque sensor '{name}' is not on a joint",
                       'put it in <gazebo reference="JOINT">')
    spec = SensorSpec(name, kind, link=link, joint=joint, line=el.sourceline)
    pose = el.find("pose")
    if pose is not None and (pose.text or "").strip():
        values = xml.numbers(pose, pose.text, 6, "pose")
        spec.pose = Pose(tuple(values[:3]), tuple(values[3:]))
    rate = xml.text_number(el, "update_rate", 0.0)
    if rate < 0:
        raise xml.fail(el, f"sensor '{name}' update_rate {rate:g} is negative",
                       "a rate in Hz; 0 means every step")
    spec.update_rate = rate
    always = xml.text_bool(el, "always_on")
    spec.always_on = True if always is None else always
    if kind == "imu":
        spec.noise = _imu_noise(xml, el.find("imu"))
    elif kind in ("camera", "depth"):
        cam = el.find("camera")
        spec.camera = _camera(xml, cam) if cam is not None else CameraSpec()
    elif kind == "force_torque":
        ft = el.find("force_torque")
        if ft is not None:
            spec.ft_frame = xml.text(ft, "frame") or spec.ft_frame
            spec.measure_direction = xml.text(ft, "measure_direction") or spec.measure_direction
        if spec.ft_frame not in ("child", "parent", "sensor"):
            raise xml.fail(el, f"force_torque frame '{spec.ft_frame}'", "child, parent or sensor")
        if spec.measure_direction not in ("child_to_parent", "parent_to_child"):
            raise xml.fail(el, f"measure_direction '{spec.measure_direction}'",
                           "child_to_parent or parent_to_child")
    elif kind == "contact":
        spec.collisions = tuple((c.text or "").strip() for c in el.iterfind("contact/collision"))
    plugin = el.find("plugin")
    if plugin is not None:
        _apply_plugin(xml, spec, plugin)
    return spec


def read_model_plugin(xml: XmlReader, plugin: etree._Element) -> SensorSpec | None:
    """A model-level gazebo_ros plugin that is a sensor by itself (libgazebo_ros_imu.so on a body,
    libgazebo_ros_ft_sensor.so on a joint); None for every other plugin."""
    filename = plugin.get("filename", "")
    name = plugin.get("name") or filename
    if filename == "libgazebo_ros_imu.so":
        body = xml.text(plugin, "bodyName")
        if not body:
            raise xml.fail(plugin, f"plugin '{name}' has no <bodyName>", "name the IMU's link")
        spec = SensorSpec(name, "imu", link=body, line=plugin.sourceline)
    elif filename == "libgazebo_ros_ft_sensor.so":
        joint = xml.text(plugin, "jointName")
        if not joint:
            raise xml.fail(plugin, f"plugin '{name}' has no <jointName>", "name the sensed joint")
        # gazebo_ros_ft_sensor publishes the joint's wrench on its child, in the child's frame
        spec = SensorSpec(name, "force_torque", joint=joint, measure_direction="parent_to_child",
                          line=plugin.sourceline)
    else:
        return None
    return _apply_plugin(xml, spec, plugin)


def merge_model_plugin(sensors: list[SensorSpec], plugin: SensorSpec) -> None:
    """A model plugin for a joint that already has a <sensor type="force_torque"> only names its
    topic (the sensor block says what is measured); otherwise it is a sensor of its own."""
    for spec in sensors:
        if plugin.type == "force_torque" and spec.type == "force_torque" \
                and spec.joint == plugin.joint and spec.plugin is None:
            spec.plugin, spec.topic, spec.namespace = plugin.plugin, plugin.topic, plugin.namespace
            spec.update_rate = spec.update_rate or plugin.update_rate
            for channel, noise in plugin.noise.items():
                spec.noise.setdefault(channel, noise)
            return
    sensors.append(plugin)


# ----- writing -------------------------------------------------------------------------------
def _text(parent: etree._Element, tag: str, text: str) -> etree._Element:
    el = etree.SubElement(parent, tag)
    el.text = text
    return el


def _write_noise(parent: etree._Element, noise: Noise) -> None:
    el = etree.SubElement(parent, "noise", type=noise.type)
    for tag in ("mean", "stddev", "bias_mean", "bias_stddev", "precision"):
        value = getattr(noise, tag)
        if value:
            _text(el, tag, format(value, ".12g"))


def write_sensor(parent: etree._Element, spec: SensorSpec, fmt: Callable[[float], str]) -> etree._Element:
    """The <sensor> element (with its plugin) a reader reads back to `spec`."""
    el = etree.SubElement(parent, "sensor", name=spec.name, type=spec.type)
    _text(el, "always_on", "true" if spec.always_on else "false")
    _text(el, "update_rate", fmt(spec.update_rate))
    if spec.pose != Pose():
        _text(el, "pose", " ".join(fmt(v) for v in (*spec.pose.xyz, *spec.pose.rpy)))
    if spec.type == "imu" and spec.noise:
        imu = etree.SubElement(el, "imu")
        for channel, noise in spec.noise.items():
            group, axis = channel.split("/")
            g = imu.find(group) if imu.find(group) is not None else etree.SubElement(imu, group)
            _write_noise(etree.SubElement(g, axis), noise)
    if spec.camera is not None:
        cam, c = etree.SubElement(el, "camera"), spec.camera
        _text(cam, "horizontal_fov", fmt(c.horizontal_fov))
        image = etree.SubElement(cam, "image")
        _text(image, "width", str(c.width))
        _text(image, "height", str(c.height))
        _text(image, "format", c.format)
        clip = etree.SubElement(cam, "clip")
        _text(clip, "near", fmt(c.near))
        _text(clip, "far", fmt(c.far))
        if c.noise.type != "none":
            _write_noise(cam, c.noise)
    if spec.type == "force_torque":
        ft = etree.SubElement(el, "force_torque")
        _text(ft, "frame", spec.ft_frame)
        _text(ft, "measure_direction", spec.measure_direction)
    if spec.type == "contact":
        contact = etree.SubElement(el, "contact")
        for name in spec.collisions:
            _text(contact, "collision", name)
    if spec.plugin and spec.plugin not in MODEL_PLUGINS:
        _write_plugin(el, spec, fmt)
    return el


def write_model_plugin(parent: etree._Element, spec: SensorSpec, fmt: Callable[[float], str]) -> None:
    """A model-level gazebo_ros plugin (IMU on a body, force-torque on a joint), under `parent`."""
    _write_plugin(parent, spec, fmt)


def needs_sensor_element(spec: SensorSpec) -> bool:
    """False for an IMU declared by libgazebo_ros_imu.so alone (the plugin is the sensor)."""
    return spec.plugin != "libgazebo_ros_imu.so"


def _write_plugin(parent: etree._Element, spec: SensorSpec, fmt: Callable[[float], str]) -> None:
    plugin = etree.SubElement(parent, "plugin", name=f"{spec.name}_plugin", filename=spec.plugin)
    if spec.namespace:
        _text(plugin, "robotNamespace", spec.namespace)
    if spec.topic:
        param = next((p for p, k in _TOPIC_PARAMS.get(spec.plugin or "", {}).items()
                      if k == "main"), "topicName")
        _text(plugin, param, spec.topic)
    for key, topic in spec.topics.items():
        keyed = next((p for p, k in _TOPIC_PARAMS.get(spec.plugin or "", {}).items() if k == key),
                      None)
        if keyed:
            _text(plugin, keyed, topic)
    if spec.frame:
        _text(plugin, "frameName", spec.frame)
    if spec.joint and spec.plugin == "libgazebo_ros_ft_sensor.so":
        _text(plugin, "jointName", spec.joint)
    if spec.link and spec.plugin == "libgazebo_ros_imu.so":
        _text(plugin, "bodyName", spec.link)
    if spec.update_rate and spec.plugin in MODEL_PLUGINS:
        _text(plugin, "updateRate", fmt(spec.update_rate))
    if spec.range is not None:
        _text(plugin, "pointCloudCutoff", fmt(spec.range[0]))
        if math.isfinite(spec.range[1]):
            _text(plugin, "pointCloudCutoffMax", fmt(spec.range[1]))
