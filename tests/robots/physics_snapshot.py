"""Mex-One's compiled physics as plain numbers: every body's mass, inertia and centre of mass,
every collision geom's shape and place, every joint's axis, range and dynamics, the contact
exclusions and the spawn height.

The fixture tests/data/robots/mex_one_physics.json was written by this file from the model as
it was BEFORE the visual shells (issue 28), so test_mex_one_looks.py proves the new looks left
the physics alone. Rewrite it only for a deliberate physics change:

    PYTHONPATH=src python3 tests/robots/physics_snapshot.py
"""

from __future__ import annotations

import json
from pathlib import Path

import mujoco
import numpy as np

from mexone.description.loader import load_model
from mexone.physics.compile import GROUP_COLLISION, compile_model
from mexone.robots import mex_one

SNAPSHOT = Path(__file__).parents[1] / "data" / "robots" / "mex_one_physics.json"


def _floats(values) -> list[float]:
    return [float(v) for v in np.asarray(values).ravel()]


def snapshot() -> dict:
    """The compiled built-in robot, as JSON-ready numbers keyed by MuJoCo names."""
    model = compile_model(load_model(mex_one.urdf_path())).model
    bodies = {}
    for b in range(1, model.nbody):
        bodies[model.body(b).name] = {
            "parent": model.body(int(model.body_parentid[b])).name,
            "mass": float(model.body_mass[b]), "inertia": _floats(model.body_inertia[b]),
            "ipos": _floats(model.body_ipos[b]), "iquat": _floats(model.body_iquat[b]),
            "pos": _floats(model.body_pos[b]), "quat": _floats(model.body_quat[b])}
    geoms = {}
    for g in range(model.ngeom):
        if model.geom_group[g] != GROUP_COLLISION:
            continue
        geoms[model.geom(g).name] = {
            "body": model.body(int(model.geom_bodyid[g])).name,
            "type": mujoco.mjtGeom(model.geom_type[g]).name, "size": _floats(model.geom_size[g]),
            "pos": _floats(model.geom_pos[g]), "quat": _floats(model.geom_quat[g]),
            "friction": _floats(model.geom_friction[g]), "solref": _floats(model.geom_solref[g]),
            "contype": int(model.geom_contype[g]), "conaffinity": int(model.geom_conaffinity[g])}
    joints = {}
    for j in range(model.njnt):
        dof = model.jnt_dofadr[j]
        joints[model.joint(j).name] = {
            "type": mujoco.mjtJoint(model.jnt_type[j]).name, "axis": _floats(model.jnt_axis[j]),
            "pos": _floats(model.jnt_pos[j]), "limited": bool(model.jnt_limited[j]),
            "range": _floats(model.jnt_range[j]), "damping": float(model.dof_damping[dof]),
            "frictionloss": float(model.dof_frictionloss[dof]),
            "armature": float(model.dof_armature[dof])}
    excludes = sorted(sorted((model.body(int(model.exclude_signature[i] >> 16)).name,
                              model.body(int(model.exclude_signature[i] & 0xFFFF)).name))
                      for i in range(model.nexclude))
    return {"bodies": bodies, "collision_geoms": geoms, "joints": joints, "excludes": excludes,
            "total_mass": float(sum(model.body_mass)), "qpos0": _floats(model.qpos0)}


if __name__ == "__main__":
    SNAPSHOT.parent.mkdir(parents=True, exist_ok=True)
    SNAPSHOT.write_text(json.dumps(snapshot(), indent=1, sort_keys=True) + "\n")
    print(SNAPSHOT)
