"""The simulator against closed-form physics: free fall, pendulum period, energy, damping,
Coulomb friction on an incline. Each robot is a URDF written here, compiled the normal way."""

from __future__ import annotations

import numpy as np
import pytest

from mexone.description.urdf import read_urdf
from mexone.physics import Simulation, Spawn, World
from mexone.physics.world import Ground

G = 9.81


def urdf(tmp_path, text: str, name="robot.urdf"):
    path = tmp_path / name
    path.write_text(text)
    return read_urdf(path)


def box_urdf(mass=1.0, size=0.1, mu=None):
    i = mass * size * size / 6
    gz = f'<gazebo reference="box"><mu1>{mu}</mu1><mu2>{mu}</mu2></gazebo>' if mu else ""
    return f"""<robot name="box"><link name="box">
      <inertial><mass value="{mass}"/><inertia ixx="{i}" ixy="0" ixz="0" iyy="{i}" iyz="0" izz="{i}"/></inertial>
      <collision><geometry><box size="{size} {size} {size}"/></geometry></collision>
    </link>{gz}</robot>"""


def pendulum_urdf(damping=0.0, length=0.5, mass=1.0, radius=0.02):
    """A rod of length L hanging from a pin at the origin of a welded base (inertia from URDF)."""
    izz = mass * radius * radius / 2
    ixx = mass * (3 * radius * radius + length * length) / 12
    return f"""<robot name="pendulum">
      <link name="world"/>
      <joint name="weld" type="fixed"><parent link="world"/><child link="pivot"/><origin xyz="0 0 1"/></joint>
      <link name="pivot"/>
      <joint name="swing" type="continuous">
        <parent link="pivot"/><child link="rod"/><axis xyz="0 1 0"/>
        <limit effort="10" velocity="100"/><dynamics damping="{damping}" friction="0"/>
      </joint>
      <link name="rod">
        <inertial><origin xyz="0 0 {-length / 2}"/><mass value="{mass}"/>
          <inertia ixx="{ixx}" ixy="0" ixz="0" iyy="{ixx}" iyz="0" izz="{izz}"/></inertial>
        <collision><origin xyz="0 0 {-length / 2}"/><geometry><cylinder radius="{radius}" length="{length}"/></geometry></collision>
      </link></robot>"""


def test_free_fall_impact_time(tmp_path):
    sim = Simulation(urdf(tmp_path, box_urdf()), spawn=Spawn(xyz=(0, 0, 1.0)))
    while sim.data.ncon == 0 and sim.time < 1.0:
        sim.step()
    expected = np.sqrt(2 * 1.0 / G)
    assert sim.time == pytest.approx(expected, rel=0.01)


def _pendulum(tmp_path, damping=0.0, theta0=0.05):
    sim = Simulation(urdf(tmp_path, pendulum_urdf(damping)))
    sim.set_joint_positions({"swing": theta0})
    return sim


def _pivot_inertia(length=0.5, mass=1.0, radius=0.02):
    return mass * (3 * radius * radius + length * length) / 12 + mass * (length / 2) ** 2


def _record(sim, seconds):
    out = []
    for _ in range(round(seconds / sim.timestep)):
        sim.step()
        out.append((sim.time, sim.joint_positions()[0], sim.joint_velocities()[0]))
    return np.array(out)


def test_small_angle_period(tmp_path):
    sim = _pendulum(tmp_path)
    t, theta, _ = _record(sim, 10.0).T
    ups = np.flatnonzero((theta[:-1] < 0) & (theta[1:] >= 0))
    # interpolate the upward zero crossings
    crossings = t[ups] - theta[ups + 1] / (theta[ups + 1] - theta[ups]) * sim.timestep
    period = np.diff(crossings).mean()
    expected = 2 * np.pi * np.sqrt(_pivot_inertia() / (1.0 * G * 0.25))
    assert period == pytest.approx(expected, rel=0.01)


def test_energy_is_kept_without_damping(tmp_path):
    sim = _pendulum(tmp_path, theta0=0.5)
    t, theta, omega = _record(sim, 10.0).T
    energy = 0.5 * _pivot_inertia() * omega**2 + 1.0 * G * 0.25 * (1 - np.cos(theta))
    drift = np.abs(energy - energy[0]).max() / energy[0]
    assert drift < 0.01


def test_damping_decay_matches_the_exponential(tmp_path):
    damping = 0.05
    sim = _pendulum(tmp_path, damping=damping)
    t, theta, _ = _record(sim, 8.0).T
    peaks = np.flatnonzero((theta[1:-1] > theta[:-2]) & (theta[1:-1] >= theta[2:])) + 1
    rate = -np.polyfit(t[peaks], np.log(theta[peaks]), 1)[0]
    assert rate == pytest.approx(damping / (2 * _pivot_inertia()), rel=0.05)


@pytest.mark.parametrize("margin", [-0.1, 0.1])
def test_incline_slides_iff_tan_exceeds_mu(tmp_path, margin):
    """Tilting gravity by alpha is the same as tilting the ground: slide iff tan(alpha) > mu."""
    mu = 0.5
    alpha = np.arctan(mu * (1 + margin))
    world = World(gravity=(G * np.sin(alpha), 0.0, -G * np.cos(alpha)), ground=Ground(mu1=100, mu2=100))
    sim = Simulation(urdf(tmp_path, box_urdf(mu=mu)), world=world, spawn=Spawn(xyz=(0, 0, 0.0)))
    sim.step(300)  # settle onto the ground
    track = []
    for _ in range(100):
        sim.step(10)
        track.append((sim.time, sim.data.qpos[0]))
    t, x = np.array(track).T
    if margin < 0:
        assert abs(x[-1] - x[0]) < 1e-3  # sticks: under a millimetre in a second
    else:
        accel = 2 * np.polyfit(t, x, 2)[0]
        assert accel == pytest.approx(G * (np.sin(alpha) - mu * np.cos(alpha)), rel=0.05)
