"""UR5e: a six-joint arm touches targets with its wrist.

The model is written from brax v0.0.x's configuration of the task, which placed the six joints where
the UR5e's are (the Denavit–Hartenberg offsets: base 0.163 m, upper arm 0.425 m, forearm 0.392 m, wrist
offsets 0.138, 0.13, 0.127 and 0.1 m) and approximated the links by capsules; links of 1 kg with unit
inertia, motors of 100 N·m, joint damping 50 N·m·s/rad, 8 physics steps of 2.5 ms per action. The arm
starts upright; targets appear 0.5 m above the floor. Reward, as the original's: 0.1 × the wrist's
progress toward the target + 1 on reaching it (within ``target_radius``, 2 cm by default).
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp

from contextrl.envs.brax.reaching import ReachingTask

MODEL = """
<mujoco model="ur5e">
  <option timestep="0.0025" gravity="0 0 -9.81" iterations="1" ls_iterations="4" tolerance="0" ls_tolerance="0"/>
  <default>
    <joint type="hinge" damping="50"/>
    <geom type="capsule" contype="1" conaffinity="0" friction="0.6 0.005 0.0001"
          rgba="0.6 0.65 0.7 1"/>
    <motor ctrllimited="true" ctrlrange="-1 1" gear="100"/>
  </default>
  <worldbody>
    <light pos="0 0 5" dir="0 0 -1" directional="true"/>
    <camera name="track" pos="1.6 -1.6 1.4" xyaxes="1 1 0 -0.3 0.3 0.9"/>
    <geom name="floor" type="plane" size="0 0 1" contype="0" conaffinity="1" rgba="0.5 0.5 0.5 1"/>
    <body name="shoulder_link" pos="0 0 0.163">
      <joint name="shoulder_pan" axis="0 0 1"/>
      <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
      <geom size="0.0595" fromto="0 0.0595 0 0 0.0741 0"/>
      <body name="upper_arm_link" pos="0 0.138 0">
        <joint name="shoulder_lift" axis="0 1 0"/>
        <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
        <geom size="0.0597" fromto="0 0 0.0003 0 0 0.4255"/>
        <body name="forearm_link" pos="0 -0.13 0.425">
          <joint name="elbow" axis="0 1 0"/>
          <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
          <geom size="0.0558" fromto="0 0 -0.0036 0 0 0.374"/>
          <body name="wrist_1_link" pos="0 0 0.392">
            <joint name="wrist_1" axis="0 1 0"/>
            <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
            <geom size="0.0387" fromto="0 0.0911 0 0 0.1183 0"/>
            <body name="wrist_2_link" pos="0 0.127 0">
              <joint name="wrist_2" axis="0 0 1"/>
              <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
              <geom size="0.0388" fromto="0 0 0.0387 0 0 0.0659"/>
              <body name="wrist_3_link" pos="0 0 0.1">
                <joint name="wrist_3" axis="0 1 0"/>
                <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
                <geom size="0.01725" fromto="0 -0.0633 0 0 -0.0173 0"/>
              </body>
            </body>
          </body>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor joint="shoulder_pan"/>
    <motor joint="shoulder_lift"/>
    <motor joint="elbow"/>
    <motor joint="wrist_1"/>
    <motor joint="wrist_2"/>
    <motor joint="wrist_3"/>
  </actuator>
</mujoco>
"""


@dataclasses.dataclass(frozen=True)
class Ur5e(ReachingTask):
    """A six-joint arm touches targets with its wrist; reward progress toward the target, 1 on reaching."""

    model_xml = MODEL
    n_frames = 8
    effector = "wrist_3_link"
    torso = "wrist_3_link"  # the original task's "torso" (its effector): the wrist's last link
    actuator_strength = 100.0
    joint_angular_damping = 50.0
    joint_stiffness = None  # the paper's 40,000: see left_out
    target_distance = (0.5, 0.01, 2.0)
    target_radius = (0.02, 0.01, 1.0)
    target_height = 0.5
    # joint angles (6) and velocities (6), the wrist's position (3), the target from it (3), its distance
    observation_size = 19
    left_out = {
        **ReachingTask.left_out,
        "joint_stiffness": "the arm's joints turn freely (±360° in the original, never reached) and "
        "MJX's joints are exact: there is no limit and no anchoring spring to stiffen",
    }

    def reward(self, before, after, target, hit):
        return 0.1 * self.progress(before, after, target) + hit

    def observe(self, state, context) -> jax.Array:
        physics = state.pipeline_state
        wrist = self.effector_position(physics)
        offset = self.target(state, context) - wrist
        return jnp.concatenate(
            [physics.q, physics.qd, wrist, offset, jnp.linalg.norm(offset)[None]]
        )
