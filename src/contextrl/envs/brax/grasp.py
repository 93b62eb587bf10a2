"""Grasp: a four-fingered claw picks up a ball-like capsule and carries it to targets in the air.

The model is written from brax v0.0.x's configuration of the task: a palm (a sphere of radius 1.5)
moved kinematically, four fingers of three capsule segments (radius 0.5, 2 m long with their caps, 1 kg
and unit inertia each) that open and close under angle actuators (position servos, gain 300) damped at
50 N·m·s/rad; the proximal joints turn ±45°, the middle and distal ones curl 0–90°. The object is a
capsule of radius 1 and length 2.02; 4 physics steps of 5 ms per action.

The palm moves as in the original: the last three actions pick a point in x, y ∈ [−10, 10],
z ∈ [3.5, 13.5], and each control step the palm moves 15 % of the way there (at most 0.3 m), in equal
parts over the physics steps. It hangs on three slide joints whose positions and velocities are set
before every physics step, and weighs 1,000 kg, so that within a step the fingers barely move it (a
MuJoCo mocap body would be the natural kinematic body, but MJX does not carry its pose to its children).

Contacts, as the original's: the fingertips and the palm touch the object, the object touches the
floor; here the fingertips touch the floor too (the original let them pass through it), and the claw
starts open, standing on its fingertips around the object, so a random policy already moves the
object's and the fingertips' contacts (where friction acts). Targets are drawn as in the other
reaching tasks, at a height ``target_height·U``; the object reaching one (within ``target_radius``)
pays 5 and moves it. Reward, as the original's: the palm moving toward the object, closeness to it,
fingertips touching it, the object moving toward the target, and the bonus.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import feature
from contextrl.core.spaces import Box
from contextrl.envs.brax.reaching import ReachingTask

# Where the palm may be sent (lower corner, extent), and where it starts: over the object, as high as
# the open claw's fingertips (3 m below the proximal joints) reach the floor.
PALM_LOW = np.array([-10.0, -10.0, 3.5])
PALM_EXTENT = np.array([20.0, 20.0, 10.0])
PALM_START = np.array([0.0, 0.0, 4.0])
PALM_RATE = 0.15  # the fraction of the way the palm moves per control step (at most 2 m of it)


def _finger(index: int) -> str:
    """Finger ``index`` (0–3): three segments pointing out along the palm's +x turned by index × 90°,
    each hinge turning about the segment's own y axis (positive curls the finger down)."""
    angle = index * math.pi / 2
    segment = """<inertial pos="0.75 0 0" mass="1" diaginertia="1 1 1"/>
        <geom {name}fromto="0.25 0 0 1.25 0 0" size="0.5" contype="{contype}"/>"""
    return f"""
    <body name="finger{index}_proximal" pos="{1.5 * math.cos(angle):.6f} {1.5 * math.sin(angle):.6f} -0.5"
          euler="0 0 {angle:.6f}">
      <joint name="finger{index}_proximal" range="-0.785398 0.785398"/>
      {segment.format(name="", contype=0)}
      <body name="finger{index}_middle" pos="1.5 0 0">
        <joint name="finger{index}_middle" range="0 1.570796"/>
        {segment.format(name="", contype=0)}
        <body name="finger{index}_distal" pos="1.5 0 0">
          <joint name="finger{index}_distal" range="0 1.570796"/>
          {segment.format(name=f'name="tip{index}" ', contype=3)}
        </body>
      </body>
    </body>"""


PARTS = ("proximal", "middle", "distal")
JOINTS = tuple(f"finger{index}_{part}" for index in range(4) for part in PARTS)
# The palm's slide joints follow the object's free joint: in q after its 7 coordinates, in qd after its 6.
PALM_Q, PALM_QD = slice(7, 10), slice(6, 9)
TIPS = tuple(f"tip{index}" for index in range(4))

# Collision bits (MuJoCo collides two geoms when one's contype shares a bit with the other's
# conaffinity): bit 1, the floor with the object and the fingertips; bit 2, the object with the
# fingertips and the palm. The other finger segments collide with nothing.
MODEL = f"""
<mujoco model="grasp">
  <compiler angle="radian"/>
  <option timestep="0.005" gravity="0 0 -9.8" iterations="4" ls_iterations="8"/>
  <default>
    <joint type="hinge" axis="0 1 0" damping="50" solreflimit="-5000 -100"/>
    <geom type="capsule" contype="0" conaffinity="0" friction="0.6 0.005 0.0001"
          rgba="0.8 0.6 0.4 1"/>
    <position kp="300"/>
  </default>
  <worldbody>
    <light pos="0 0 30" dir="0 0 -1" directional="true"/>
    <camera name="track" pos="0 -22 11" xyaxes="1 0 0 0 0.45 0.9"/>
    <geom name="ground" type="plane" size="0 0 1" conaffinity="1" rgba="0.5 0.5 0.5 1"/>
    <body name="object" pos="0 0 1">
      <freejoint/>
      <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
      <geom name="object" euler="1.570796 0 0" size="1 0.01" contype="1" conaffinity="2"
            rgba="0.3 0.5 0.9 1"/>
    </body>
    <body name="palm" pos="{PALM_START[0]} {PALM_START[1]} {PALM_START[2]}">
      <joint name="palm_x" type="slide" axis="1 0 0" ref="{PALM_START[0]}" damping="0"/>
      <joint name="palm_y" type="slide" axis="0 1 0" ref="{PALM_START[1]}" damping="0"/>
      <joint name="palm_z" type="slide" axis="0 0 1" ref="{PALM_START[2]}" damping="0"/>
      <inertial pos="0 0 0" mass="1000" diaginertia="5000 10000 10000"/>
      <geom name="palm" type="sphere" size="1.5" contype="2"/>
      {"".join(_finger(index) for index in range(4))}
    </body>
  </worldbody>
  <actuator>
    {"".join(f'<position joint="{joint}"/>' for joint in JOINTS)}
  </actuator>
</mujoco>
"""


@dataclasses.dataclass(frozen=True)
class Grasp(ReachingTask):
    """A claw picks up an object and carries it to targets; reward approach, touch, carry, reaching."""

    model_xml = MODEL
    n_frames = 4
    effector = "object"  # what must reach the target
    actuator_strength = 300.0
    joint_angular_damping = 50.0
    joint_stiffness = 5000.0
    target_distance = (10.0, 0.1, 100.0)
    target_radius = (1.1, 0.1, 20.0)
    target_height = 8.0
    # palm position (3), object from the palm (3) and its distance (1), target from the object (3) and
    # its distance (1), target from the palm (3), object velocity and angular velocity (6), finger joint
    # angles and velocities (24), fingertips touching (4)
    observation_size = 48

    @classmethod
    def feature_fields(cls, backend: str, goal: bool, fluid: bool) -> dict[str, Any]:
        return {
            **super().feature_fields(backend, goal, fluid),
            "actuator_strength": feature(
                cls.actuator_strength, 1.0, 10 * cls.actuator_strength, unit="N·m/rad",
                doc="gain of every finger's angle servo (torque per radian from its set angle)",
            ),
            "target_height": feature(
                cls.target_height, 0.0, 50.0, unit="m", affects=("goal", "observation"),
                doc="targets are drawn up to this high above the floor",
            ),
        }  # fmt: skip

    @property
    def action_space(self) -> Box:
        """12 finger angles, each −1 … 1 over its joint's range, then where to send the palm."""
        size = self._brax.sys.act_size() + 3
        return Box(-np.ones(size, np.float32), np.ones(size, np.float32))

    def actuator_changes(self, stock, strength) -> dict[str, jax.Array]:
        """Every angle servo's gain (torque per radian from its set angle) set to ``strength``."""
        gain = jnp.asarray(stock.actuator_gainprm).at[:, 0].set(strength)
        bias = jnp.asarray(stock.actuator_biasprm).at[:, 1].set(-strength)
        return {
            "actuator_gainprm": gain,
            "actuator_biasprm": bias,
            "actuator.gain": jnp.full_like(stock.actuator.gain, strength),
            "actuator.bias_q": jnp.full_like(stock.actuator.bias_q, -strength),
        }

    def target_elevation(self, state, context) -> jax.Array:
        """``target_height·U``: targets anywhere from the floor up to ``target_height``."""
        return context.target_height * state.target_draws[2]

    def physics_step(self, sys, pipeline_state, action):
        """The fingers' set angles from the first 12 actions; the palm moved toward the point the last
        three pick, in equal parts over the physics steps, at the matching velocity."""
        from brax.mjx import pipeline

        ranges = jnp.asarray(self._brax.sys.jnt_range)[self._fingers[0]]
        angles = ranges[:, 0] + (ranges[:, 1] - ranges[:, 0]) * (action[:12] + 1) / 2
        goal = PALM_LOW + PALM_EXTENT * (action[12:] + 1) / 2
        palm = self.palm_position(pipeline_state)
        offset = goal - palm
        move = PALM_RATE * offset * jnp.minimum(1.0, 2.0 / (1e-6 + jnp.linalg.norm(offset)))
        velocity = move / self.control_timestep

        def frame(pipeline_state, fraction):  # the palm where it should start this physics step
            qpos = pipeline_state.qpos.at[PALM_Q].set(palm + fraction * move)
            qvel = pipeline_state.qvel.at[PALM_QD].set(velocity)
            return pipeline.step(sys, pipeline_state.replace(qpos=qpos, qvel=qvel), angles), None

        fractions = jnp.arange(self.n_frames) / self.n_frames
        return jax.lax.scan(frame, pipeline_state, fractions)[0]

    def initial_pose(self) -> jax.Array:
        """The object at rest and the claw open, standing on its fingertips around it: the proximal
        joints turned fully down (45°), the middle and distal ones straight."""
        joints, positions, _ = self._fingers
        ranges = np.asarray(self._brax.sys.jnt_range)[joints]
        angles = np.where(np.arange(len(joints)) % 3 == 0, ranges[:, 1], ranges[:, 0])
        return jnp.asarray(self._brax.sys.init_q).at[positions].set(angles)

    def palm_position(self, pipeline_state) -> jax.Array:
        """Where the palm is (its slide joints' positions are its world coordinates)."""
        return pipeline_state.q[PALM_Q]

    @property
    def _fingers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The finger joints' ids and their addresses in q and in qd, in ``JOINTS`` order."""
        model = self._brax.sys.mj_model
        joints = np.array([model.joint(name).id for name in JOINTS])
        return joints, model.jnt_qposadr[joints], model.jnt_dofadr[joints]

    def reward(self, before, after, target, hit):
        palm_before, palm = self.palm_position(before), self.palm_position(after)
        offset = self.effector_position(after) - palm
        direction = offset / (1e-6 + jnp.linalg.norm(offset))
        moving_to_object = 0.1 * jnp.dot(palm - palm_before, direction)
        close_to_object = 0.1 * self.control_timestep / (1.0 + jnp.linalg.norm(offset[:2]))
        touching = 0.2 * self.control_timestep * jnp.sum(self.touching(after, TIPS, "object"))
        carrying = 1.5 * self.progress(before, after, target)
        return moving_to_object + close_to_object + touching + carrying + 5.0 * hit

    def observe(self, state, context) -> jax.Array:
        physics = state.pipeline_state
        palm = self.palm_position(physics)
        held = self.effector_position(physics)
        target = self.target(state, context)
        link = self._link(self.effector)
        _, positions, velocities = self._fingers
        return jnp.concatenate(
            [
                palm,
                held - palm,
                jnp.linalg.norm(held - palm)[None],
                target - held,
                jnp.linalg.norm(target - held)[None],
                target - palm,
                physics.xd.vel[link],
                physics.xd.ang[link],
                physics.q[positions],
                physics.qd[velocities],
                self.touching(physics, TIPS, "object"),
            ]
        )
