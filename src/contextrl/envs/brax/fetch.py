"""Fetch (the paper's Figure 1): a four-legged box "dog" runs to targets on the ground.

The model is written from brax v0.0.x's configuration of the task: a torso with shoulders and hips, each
carrying two legs of an upper and a lower segment (boxes of 1 kg, unit inertia); ten hinges limited to
±60° (the spine's two turn about the body's long axis, the legs' about its side axis), each driven by a
motor of 300 N·m and damped at 35 N·m·s/rad; only the lower legs touch the ground, as capsules of the
boxes' extent (box–ground contacts made a step about a fifth slower); 4 physics steps of 5 ms per
action, each solved with two Newton iterations (with one, strong motors on undamped joints gave NaN
within 100 steps). The reward, as the original's: 0.1·dt·torso height + 0.1 × progress toward the target +
0.1·dt·uprightness + (on reaching it) how squarely the torso faces the target.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.envs.brax.reaching import ReachingTask

LEG = '<geom size="0.25 0.125 0.5"/>'


def _leg(name: str, side: float) -> str:
    """An upper and a lower leg hanging from a shoulder or hip end (``side``: −1 right, +1 left)."""
    return f"""
      <body name="{name}_upper" pos="0 {0.875 * side} -0.375">
        <joint name="{name}_upper" axis="0 1 0" pos="0 0 0.375"/>
        <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
        {LEG}
        <body name="{name}_lower" pos="0 {-0.25 * side} -0.5">
          <joint name="{name}_lower" axis="0 1 0" pos="0 0 0.25"/>
          <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
          <geom name="{name}_foot" type="capsule" size="0.125 0.375" contype="1"/>
        </body>
      </body>"""


def _girdle(name: str, x: float, legs: tuple[str, str]) -> str:
    """Shoulders or hips: a crosswise box at one end of the torso, turning about the long axis."""
    return f"""
    <body name="{name}" pos="{x} 0 0">
      <joint name="{name}" axis="1 0 0"/>
      <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
      <geom size="0.25 0.75 0.125"/>
      {_leg(legs[0], -1.0)}
      {_leg(legs[1], 1.0)}
    </body>"""


JOINTS = (
    "shoulders", "front_right_upper", "front_right_lower", "front_left_upper", "front_left_lower",
    "hips", "back_right_upper", "back_right_lower", "back_left_upper", "back_left_lower",
)  # fmt: skip

MODEL = f"""
<mujoco model="fetch">
  <compiler angle="degree"/>
  <option timestep="0.005" gravity="0 0 -9.8" iterations="2" ls_iterations="4"/>
  <default>
    <joint type="hinge" limited="true" range="-60 60" damping="35" solreflimit="-5000 -100"/>
    <geom type="box" contype="0" conaffinity="0" friction="0.6 0.005 0.0001" rgba="0.8 0.6 0.4 1"/>
    <motor ctrllimited="true" ctrlrange="-1 1" gear="300"/>
  </default>
  <worldbody>
    <light pos="0 0 20" dir="0 0 -1" directional="true"/>
    <geom name="ground" type="plane" size="0 0 1" conaffinity="1" rgba="0.4 0.6 0.3 1"/>
    <body name="torso" pos="0 0 1.4">
      <camera name="track" mode="trackcom" pos="0 -12 6" xyaxes="1 0 0 0 0.45 0.9"/>
      <freejoint/>
      <inertial pos="0 0 0" mass="1" diaginertia="1 1 1"/>
      <geom size="0.75 0.25 0.125"/>
      {_girdle("shoulders", 1.0, ("front_right", "front_left"))}
      {_girdle("hips", -1.0, ("back_right", "back_left"))}
    </body>
  </worldbody>
  <actuator>
    {"".join(f'<motor joint="{joint}"/>' for joint in JOINTS)}
  </actuator>
</mujoco>
"""

# The ground's colour at ice, grass and concrete frictions (``Fetch.paint``).
GROUND_FRICTIONS = (0.05, 0.6, 1.0)
GROUND_COLOURS = np.array([[0.75, 0.88, 0.95], [0.35, 0.6, 0.25], [0.55, 0.55, 0.55]])

BODIES = ("torso", "shoulders", "hips") + tuple(
    f"{leg}_{part}"
    for leg in ("front_right", "front_left", "back_right", "back_left")
    for part in ("upper", "lower")
)
FEET = tuple(f"{leg}_foot" for leg in ("front_right", "front_left", "back_right", "back_left"))


def rotate_into(frame_quat, vectors):
    """``vectors`` (…, 3) expressed in the frame of the unit quaternion ``frame_quat`` (w, x, y, z)."""
    from brax import math as brax_math

    return jax.vmap(brax_math.inv_rotate, in_axes=(0, None))(vectors, frame_quat)


@dataclasses.dataclass(frozen=True)
class Fetch(ReachingTask):
    """A four-legged dog runs to targets on the ground; reward progress, height, uprightness, reaching."""

    model_xml = MODEL
    n_frames = 4
    effector = "torso"
    torso = "torso"
    actuator_strength = 300.0
    joint_angular_damping = 35.0
    joint_stiffness = 5000.0
    target_distance = (15.0, 0.1, 100.0)
    target_radius = (2.0, 0.1, 20.0)
    target_height = 1.0
    # forward and up (6), target distance and direction (4), the other bodies' positions (30) and
    # every body's velocity (33) in the torso's frame, the feet's ground contacts (4)
    observation_size = 77

    def paint(self, model, context) -> None:
        """The ground's colour follows its friction: ice (pale blue) at 0.05, grass (green) at the
        default 0.6, concrete (grey) at 1 and above, blended in between."""
        friction = float(context.friction)
        ground = model.geom("ground").id
        model.geom_rgba[ground, :3] = np.array(
            [np.interp(friction, GROUND_FRICTIONS, channel) for channel in GROUND_COLOURS.T]
        )

    def reward(self, before, after, target, hit):
        from brax import math as brax_math

        torso = self._link("torso")
        rotation = after.x.rot[torso]
        up = brax_math.rotate(jnp.array([0.0, 0.0, 1.0]), rotation)
        forward = brax_math.rotate(jnp.array([1.0, 0.0, 0.0]), rotation)
        position = after.x.pos[torso]
        direction = (target - position) / (1e-6 + jnp.linalg.norm(target - position))
        height = 0.1 * self.control_timestep * position[2]
        upright = 0.1 * self.control_timestep * up[2]
        facing = jnp.where(hit, jnp.dot(direction, forward), 0.0)
        return height + 0.1 * self.progress(before, after, target) + upright + facing

    def observe(self, state, context) -> jax.Array:
        from brax import math as brax_math

        physics = state.pipeline_state
        torso = self._link("torso")
        rotation = physics.x.rot[torso]
        forward = brax_math.rotate(jnp.array([1.0, 0.0, 0.0]), rotation)
        up = brax_math.rotate(jnp.array([0.0, 0.0, 1.0]), rotation)
        offsets = rotate_into(rotation, physics.x.pos - physics.x.pos[torso])
        velocities = rotate_into(rotation, physics.xd.vel)
        target_offset = self.target(state, context) - physics.x.pos[torso]
        target = rotate_into(rotation, target_offset[None])[0]
        distance = jnp.linalg.norm(target)
        others = [self._link(body) for body in BODIES[1:]]
        return jnp.concatenate(
            [
                forward,
                up,
                distance[None],
                target / (1e-6 + distance),
                offsets[jnp.asarray(others)].reshape(-1),
                velocities.reshape(-1),
                self.touching(physics, FEET),
            ]
        )
