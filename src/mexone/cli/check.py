"""`mexone check`: print the kinematic tree like check_urdf, then lint the physics."""

from __future__ import annotations

import argparse
import dataclasses
import json
from dataclasses import replace
from pathlib import Path

from mexone.cli import add_input_limit_option
from mexone.control.config import load_control_config
from mexone.control.lint import lint_controllers
from mexone.description.check import check_model, format_tree, summary
from mexone.description.loader import load_model, model_format
from mexone.robots import mex_one
from mexone.sensors import sensor_types
from mexone.sensors.build import lint_sensors

HELP = """\
Read a robot (URDF, .urdf.xacro or Gazebo SDF), print its kinematic tree the way ROS's
check_urdf does, then look for the mistakes that make a simulated robot explode or misbehave:
non-positive or implausible masses, impossible or oversized inertias, centres of mass outside
the link, collision shapes away from the visuals, misplaced joints, missing meshes or meshes in
millimetres without a 0.001 scale, meaningless effort/velocity limits, negative friction or
contact stiffness, values given twice (a <gazebo reference> block overriding the URDF's
<dynamics>, two <gazebo> blocks or tags disagreeing, a repeated URDF element: both lines and
the one that wins), planar/floating joints and trees deeper than MuJoCo can build, <mimic>
joints, duplicated or capitalised names, several roots or loops, and (with --controllers)
controllers naming joints that have no transmission, two controllers on one joint,
impossible PID gains and what a Python controller's class refuses (a StateFeedback's missing
design file, a rate that is not its design's), each with the YAML's file:line.

Only regular files up to 4 MB are read (--max-input-mb lifts that); xacro gets 6 s
(MEXONE_XACRO_TIMEOUT) and finds $(find pkg) on ROS_PACKAGE_PATH, above the file, or among
mexone's robots.

exit status: 0 no errors or warnings, 1 findings, 2 unreadable input"""


def add_parser(sub) -> None:
    parser = sub.add_parser("check", help="print the kinematic tree and lint a robot model",
                            description=HELP, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("model", nargs="?", type=Path,
                        help="URDF, .urdf.xacro, .sdf, Gazebo model folder or MJCF (.xml) "
                             "(default: the built-in Mex-One with its controllers)")
    parser.add_argument("--controllers", type=Path, metavar="YAML",
                        help="ros_control controller YAML to check against the model")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON object: robot, root, links, joints, actuated, mass, "
                             "findings")
    add_input_limit_option(parser)
    parser.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    path, controllers = args.model, args.controllers
    if path is None:
        path = mex_one.urdf_path()
        controllers = controllers or mex_one.controllers_path()
    model = load_model(path)
    findings = check_model(model) + lint_sensors(model)  # the sensor rules: the plug-ins' layer
    if controllers:  # the controller rules live in the control layer, above the model's
        findings += lint_controllers(model, load_control_config(controllers))
    if model_format(path) == "xacro":  # a line of the expanded document is nowhere in the source
        findings = [f if f.file else replace(f, line=None) for f in findings]
    failing = [f for f in findings if f.severity != "info"]
    if args.json:
        print(json.dumps(summary(model, findings) | {"sensors": sensor_rows(model)}, indent=2))
        return 1 if failing else 0
    print(format_tree(model))
    print()
    rows = sensor_rows(model)
    if rows:
        print("sensors (a controller reads state.sensors[name]; see docs/sensors.md):")
        for row in rows:
            print(f"  {row['name']:<16} {row['type']:<13} on {row['on']:<16} "
                  f"{row['rate_hz']:>6g} Hz  {', '.join(row['state']) or '(topics only)'}")
        print()
    print(f"physics lint: {len(model.links)} links, {len(model.joints)} joints "
          f"({len(model.actuated_joints)} actuated), {model.mass:.3f} kg")
    for finding in findings:
        print("  " + finding.one_line(str(path)))
    errors = sum(f.severity == "error" for f in findings)
    warnings = sum(f.severity == "warning" for f in findings)
    print(f"{errors} error(s), {warnings} warning(s)" if failing else "no problems found")
    return 1 if failing else 0


def sensor_rows(model) -> list[dict]:
    """Every declared sensor: name, type, where it sits, its rate (0: every step) and its
    state interfaces (the fields of its type's state object)."""
    rows = []
    for spec in model.sensors:
        cls = sensor_types().get(spec.type)
        state = cls.state_type if cls is not None else None
        names = [f.name for f in dataclasses.fields(state)] if state is not None else []
        if state is not None and isinstance(getattr(state, "in_contact", None), property):
            names.insert(0, "in_contact")
        rows.append({"name": spec.name, "type": spec.type, "on": spec.joint or spec.link or "",
                     "rate_hz": spec.update_rate, "state": names})
    return rows
