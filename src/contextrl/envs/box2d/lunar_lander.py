"""LunarLander on Box2D: gymnasium's ``LunarLander-v3`` at the default context, step by step.

How the context reaches the simulation (all values held by the instance, the world rebuilt at reset):

- ``SCALE`` is pixels per metre. The world is ``VIEWPORT_W / SCALE`` by ``VIEWPORT_H / SCALE`` metres
  and the lander, its legs and the engine offsets are their pixel sizes divided by ``SCALE``, as in
  gymnasium; a smaller ``SCALE`` is a larger lander in a larger world under the same gravity.
- ``VIEWPORT_W/H`` set the size of that world: the terrain spans its width, the pad sits at a quarter
  of its height and the lander starts at the top centre.
- The observation is gymnasium's, computed with the episode's values, so it keeps its meaning under
  every context: x is -1 and +1 at the world's edges (where the episode ends), y is 0 with the legs
  resting on the pad and ±1 half the world's height away, velocities are in gymnasium's units of the
  current world (world half-sizes times metres per second over ``FPS``), angles in radians. Because
  these scales move with the context (and the lander may spin past ±2π, which gymnasium's own bounds
  do not allow for), the declared bounds of the positions, velocities and angles are unbounded; the leg
  contacts are 0 or 1.
- ``FPS`` is the number of physics steps per second; one action lasts one step, so an engine's impulse
  per second grows with ``FPS``, as in gymnasium.
- ``wind_power`` and ``turbulence_power`` are gymnasium's wind: above 0, either one turns it on (the
  wind and torque phases are then drawn at reset, as gymnasium does with ``enable_wind=True``).
- ``SIDE_ENGINE_HEIGHT`` places the side engines' thrust above the centre; their sideways offset
  along the lander's axis is gymnasium's fixed 17 pixels (its docs note the resulting
  orientation-dependent torque), kept so the default context stays gymnasium's.
"""

from __future__ import annotations

import math
from typing import Any

import Box2D
import gymnasium
import numpy as np
from Box2D.b2 import (
    bodyDef,
    contactListener,
    edgeShape,
    fixtureDef,
    polygonShape,
    revoluteJointDef,
)

from contextrl.context.features import ContextBase, context_type, feature
from contextrl.envs.box2d.base import Box2DEnv, fps_feature, paint_body

LANDER_POLYGON = ((-14, 17), (-17, 0), (-17, -10), (17, -10), (17, 0), (14, 17))  # pixels
TERRAIN_CHUNKS = 11
MAIN_ENGINE_BELOW = 4  # pixels below the centre where the main engine pushes
SIDE_ENGINE_ALONG = 17  # pixels along the lander's axis where the side engines push (gymnasium's)
VELOCITY_ITERATIONS, POSITION_ITERATIONS = 6 * 30, 2 * 30
SHAPE = ("dynamics", "start_state", "observation", "reward")  # features that resize the world


@context_type
class LunarLanderContext(ContextBase):
    """Context features of LunarLander; the defaults are gymnasium's ``LunarLander-v3``."""

    FPS: float = fps_feature()
    SCALE: float = feature(
        30.0,
        1.0,
        100.0,
        unit="px/m",
        doc="pixels per metre: every size in pixels is divided by it",
        affects=SHAPE,
    )
    MAIN_ENGINE_POWER: float = feature(13.0, 0.0, 50.0, doc="impulse scale of the main engine")
    SIDE_ENGINE_POWER: float = feature(0.6, 0.0, 50.0, doc="impulse scale of the side engines")
    INITIAL_RANDOM: float = feature(
        1000.0,
        0.0,
        2000.0,
        unit="N",
        doc="largest random push on each axis at the start",
        affects=("start_state",),
    )
    GRAVITY_X: float = feature(0.0, -20.0, 20.0, unit="m/s²", doc="gravity along x")
    GRAVITY_Y: float = feature(
        -10.0, -25.0, 0.01, unit="m/s²", doc="gravity along y (negative: down)"
    )
    LEG_AWAY: float = feature(
        20.0, 0.0, 50.0, unit="px", doc="sideways distance of each leg's hinge"
    )
    LEG_DOWN: float = feature(
        18.0,
        0.0,
        50.0,
        unit="px",
        doc="depth of the legs' hinges; the pad height y=0 sits this far",
        affects=("dynamics", "observation", "reward"),
    )
    LEG_W: float = feature(2.0, 1.0, 10.0, unit="px", doc="half-width of a leg")
    LEG_H: float = feature(8.0, 1.0, 20.0, unit="px", doc="half-length of a leg")
    LEG_SPRING_TORQUE: float = feature(40.0, 0.0, 100.0, doc="largest torque of the legs' springs")
    SIDE_ENGINE_HEIGHT: float = feature(
        14.0, 1.0, 20.0, unit="px", doc="height above the centre where the side engines push"
    )
    SIDE_ENGINE_AWAY: float = feature(
        12.0, 1.0, 20.0, unit="px", doc="lever of the side engines' thrust"
    )
    VIEWPORT_W: int = feature(
        600, 400, 1000, kind="int", unit="px", doc="world width (in pixels)", affects=SHAPE
    )
    VIEWPORT_H: int = feature(
        400, 200, 800, kind="int", unit="px", doc="world height (in pixels)", affects=SHAPE
    )
    wind_power: float = feature(
        0.0, 0.0, 20.0, unit="N", doc="largest sideways wind force in flight (gymnasium's)"
    )
    turbulence_power: float = feature(
        0.0, 0.0, 2.0, unit="N·m", doc="largest turbulence torque in flight (gymnasium's)"
    )


class _Contacts(contactListener):
    """Ends the episode when the lander's body touches the moon; tracks each leg's ground contact."""

    def __init__(self, env: LunarLander):
        contactListener.__init__(self)
        self.env = env

    def BeginContact(self, contact):
        bodies = (contact.fixtureA.body, contact.fixtureB.body)
        if self.env.lander in bodies:
            self.env.game_over = True
        for index, leg in enumerate(self.env.legs):
            if leg in bodies:
                self.env.leg_contact[index] = True

    def EndContact(self, contact):
        bodies = (contact.fixtureA.body, contact.fixtureB.body)
        for index, leg in enumerate(self.env.legs):
            if leg in bodies:
                self.env.leg_contact[index] = False


class LunarLander(Box2DEnv):
    """Land on the pad with a main and two side engines (gymnasium ``LunarLander-v3``, 1000 steps).

    ``continuous=False``: actions 0 (nothing), 1 (left engine), 2 (main), 3 (right engine).
    ``continuous=True``: two throttles in [-1, 1] (main above 0, sides beyond ±0.5), as gymnasium's.
    """

    context_type = LunarLanderContext
    default_max_steps = 1000

    def __init__(self, continuous: bool = False):
        if not isinstance(continuous, bool):
            raise TypeError(f"LunarLander: continuous must be True or False, got {continuous!r}")
        super().__init__()
        self.continuous = continuous
        if continuous:
            self.action_space = gymnasium.spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
        else:
            self.action_space = gymnasium.spaces.Discrete(4)
        unbounded = np.full(6, np.inf, np.float32)
        self.base_observation_space = gymnasium.spaces.Box(
            np.concatenate([-unbounded, [0.0, 0.0]]).astype(np.float32),
            np.concatenate([unbounded, [1.0, 1.0]]).astype(np.float32),
            dtype=np.float32,
        )
        # Definitions made once and reused: pybox2d never frees a fixture definition (about 0.3 kB
        # each), so definitions made at every reset would leak.
        self._static = bodyDef()
        self._edge = fixtureDef(shape=edgeShape(vertices=[(0, 0), (1, 0)]), density=0.0)
        self._hull = fixtureDef(
            shape=polygonShape(box=(1, 1)),
            density=5.0,
            friction=0.1,
            categoryBits=0x0010,
            maskBits=0x001,  # collides only with the ground
            restitution=0.0,
        )
        self._leg = fixtureDef(
            shape=polygonShape(box=(1, 1)),
            density=1.0,
            restitution=0.0,
            categoryBits=0x0020,
            maskBits=0x001,
        )
        self.world = None
        self.lander = None
        self.legs: tuple = ()
        self.leg_contact = [False, False]
        self.game_over = False

    @property
    def name(self) -> str:
        return "LunarLanderContinuous" if self.continuous else "LunarLander"

    # ---- episode ---------------------------------------------------------------------------------
    def reset_physics(self, context: Any, rng: np.random.Generator) -> np.ndarray:
        v = self._start(context, rng)
        scale = v["SCALE"]
        width, height = v["VIEWPORT_W"] / scale, v["VIEWPORT_H"] / scale
        self._half_width, self._half_height = width / 2, height / 2
        self._wind = v["wind_power"] > 0 or v["turbulence_power"] > 0
        # A new world per episode, as LunarLander-v3 does (reusing one is not deterministic).
        self.world = Box2D.b2World(gravity=(v["GRAVITY_X"], v["GRAVITY_Y"]))
        self._listener = _Contacts(self)
        self.world.contactListener = self._listener
        self.game_over = False
        self.leg_contact = [False, False]
        self._previous_shaping = None
        self._flames: list[tuple[tuple[float, float], float, float]] = []
        self._build_terrain(width, height)
        self._build_lander(width / 2, height)
        return self._advance(0 if not self.continuous else None, (0.0, 0.0))[0]

    def _build_terrain(self, width: float, height: float) -> None:
        heights = self._rng.uniform(0, height / 2, size=(TERRAIN_CHUNKS + 1,))
        chunk_x = [width / (TERRAIN_CHUNKS - 1) * i for i in range(TERRAIN_CHUNKS)]
        middle = TERRAIN_CHUNKS // 2
        self.pad_x = (chunk_x[middle - 1], chunk_x[middle + 1])
        self.pad_y = height / 4
        heights[middle - 2 : middle + 3] = self.pad_y
        smooth = [
            0.33 * (heights[i - 1] + heights[i + 0] + heights[i + 1]) for i in range(TERRAIN_CHUNKS)
        ]
        self.moon = self.world.CreateBody(self._static)
        edge = self._edge
        edge.shape.vertices, edge.friction = [(0, 0), (width, 0)], 0.2  # the floor: Box2D's default
        self.moon.CreateFixture(edge)
        edge.friction = 0.1
        self.sky: list[list[tuple[float, float]]] = []
        for i in range(TERRAIN_CHUNKS - 1):
            left, right = (chunk_x[i], smooth[i]), (chunk_x[i + 1], smooth[i + 1])
            edge.shape.vertices = [left, right]
            self.moon.CreateFixture(edge)
            self.sky.append([left, right, (right[0], height), (left[0], height)])

    def _build_lander(self, x: float, y: float) -> None:
        v, rng = self._values, self._rng
        scale = v["SCALE"]
        self._hull.shape.vertices = [(px / scale, py / scale) for px, py in LANDER_POLYGON]
        self.lander = self.world.CreateDynamicBody(position=(x, y), angle=0.0, fixtures=self._hull)
        push = v["INITIAL_RANDOM"]
        self.lander.ApplyForceToCenter((rng.uniform(-push, push), rng.uniform(-push, push)), True)
        if self._wind:  # phases of the wind and turbulence signals
            self._wind_index = int(rng.integers(-9999, 9999))
            self._torque_index = int(rng.integers(-9999, 9999))
        legs = []
        self._leg.shape.box = (v["LEG_W"] / scale, v["LEG_H"] / scale)
        for side in (-1, +1):
            leg = self.world.CreateDynamicBody(
                position=(x - side * v["LEG_AWAY"] / scale, y),
                angle=side * 0.05,
                fixtures=self._leg,
            )
            hinge = revoluteJointDef(
                bodyA=self.lander,
                bodyB=leg,
                localAnchorA=(0, 0),
                localAnchorB=(side * v["LEG_AWAY"] / scale, v["LEG_DOWN"] / scale),
                enableMotor=True,
                enableLimit=True,
                maxMotorTorque=v["LEG_SPRING_TORQUE"],
                motorSpeed=+0.3 * side,  # a weak spring that holds the leg out
            )
            # Each leg swings through 0.5 rad, angled outwards.
            hinge.lowerAngle, hinge.upperAngle = (
                (0.9 - 0.5, 0.9) if side == -1 else (-0.9, -0.9 + 0.5)
            )
            self.world.CreateJoint(hinge)
            legs.append(leg)
        self.legs = tuple(legs)

    def step_physics(self, action) -> tuple[np.ndarray, float, bool]:
        if self.lander is None:
            raise RuntimeError(f"{self.name}: call reset_physics before step_physics")
        if self.continuous:
            return self._advance(None, self._continuous_action(action, 2))
        if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
            action = np.asarray(action)
            if action.shape != () or action.dtype.kind not in "iu":
                raise ValueError(f"{self.name}: action must be an integer in 0..3, got {action!r}")
        if not 0 <= action <= 3:
            raise ValueError(f"{self.name}: action must be an integer in 0..3, got {action!r}")
        return self._advance(int(action), None)

    def _advance(self, discrete: int | None, throttles) -> tuple[np.ndarray, float, bool]:
        """One step under a discrete action or two (unclipped) throttles, as gymnasium computes it."""
        v, lander, rng = self._values, self.lander, self._rng
        scale, fps = v["SCALE"], v["FPS"]
        if self._wind and not (self.leg_contact[0] or self.leg_contact[1]):
            wind = self._wind_index
            wind_force = math.tanh(math.sin(0.02 * wind) + math.sin(math.pi * 0.01 * wind))
            lander.ApplyForceToCenter((wind_force * v["wind_power"], 0.0), True)
            self._wind_index += 1
            torque = self._torque_index
            turbulence = math.tanh(math.sin(0.02 * torque) + math.sin(math.pi * 0.01 * torque))
            lander.ApplyTorque(turbulence * v["turbulence_power"], True)
            self._torque_index += 1

        angle = lander.angle
        tip = (math.sin(angle), math.cos(angle))
        side = (-tip[1], tip[0])
        spread = (rng.uniform(-1.0, 1.0, 2) / scale).tolist()
        position = lander.position
        self._flames = []

        if discrete is None:
            main, lateral = (min(max(t, -1.0), 1.0) for t in throttles)
            main_power = (min(main, 1.0) + 1.0) * 0.5 if main > 0.0 else 0.0
            direction = (lateral > 0) - (lateral < 0) + 0.0
            side_power = min(max(abs(lateral), 0.5), 1.0) if abs(lateral) > 0.5 else 0.0
        else:
            main_power = 1.0 if discrete == 2 else 0.0
            direction = discrete - 2
            side_power = 1.0 if discrete in (1, 3) else 0.0

        if main_power:
            depth = MAIN_ENGINE_BELOW / scale + 2 * spread[0]
            ox = tip[0] * depth + side[0] * spread[1]
            oy = -tip[1] * depth - side[1] * spread[1]
            at = (position[0] + ox, position[1] + oy)
            power = v["MAIN_ENGINE_POWER"]
            lander.ApplyLinearImpulse(
                (-ox * power * main_power, -oy * power * main_power), at, True
            )
            self._flames.append((at, ox, oy))
        if side_power:
            lever = 3 * spread[1] + direction * v["SIDE_ENGINE_AWAY"] / scale
            ox = tip[0] * spread[0] + side[0] * lever
            oy = -tip[1] * spread[0] - side[1] * lever
            at = (
                position[0] + ox - tip[0] * SIDE_ENGINE_ALONG / scale,
                position[1] + oy + tip[1] * v["SIDE_ENGINE_HEIGHT"] / scale,
            )
            power = v["SIDE_ENGINE_POWER"]
            lander.ApplyLinearImpulse(
                (-ox * power * side_power, -oy * power * side_power), at, True
            )
            self._flames.append((at, ox, oy))

        self.world.Step(1.0 / fps, VELOCITY_ITERATIONS, POSITION_ITERATIONS)

        position, velocity = lander.position, lander.linearVelocity
        half_width, half_height = self._half_width, self._half_height
        state = [
            (position.x - half_width) / half_width,
            (position.y - (self.pad_y + v["LEG_DOWN"] / scale)) / half_height,
            velocity.x * half_width / fps,
            velocity.y * half_height / fps,
            lander.angle,
            20.0 * lander.angularVelocity / fps,
            1.0 if self.leg_contact[0] else 0.0,
            1.0 if self.leg_contact[1] else 0.0,
        ]
        shaping = (
            -100 * math.sqrt(state[0] * state[0] + state[1] * state[1])
            - 100 * math.sqrt(state[2] * state[2] + state[3] * state[3])
            - 100 * abs(state[4])
            + 10 * state[6]
            + 10 * state[7]
        )  # ten points per leg on the ground: losing contact again costs them
        reward = 0.0 if self._previous_shaping is None else shaping - self._previous_shaping
        self._previous_shaping = shaping
        reward -= main_power * 0.30
        reward -= side_power * 0.03
        terminated = False
        if self.game_over or abs(state[0]) >= 1.0:
            terminated, reward = True, -100.0
        if not lander.awake:  # come to rest
            terminated, reward = True, +100.0
        return np.array(state, dtype=np.float32), reward, terminated

    # ---- drawing -------------------------------------------------------------------------------
    def render_frame(self) -> np.ndarray:
        """The viewport of the current context: black sky, white moon, the pad's flags, engine flames."""
        if self.lander is None:
            raise RuntimeError(f"{self.name}: call reset_physics before render_frame")
        canvas = self._canvas(0.0, background=(255, 255, 255))
        for quad in self.sky:
            canvas.polygon(quad, (0, 0, 0))
        for at, ox, oy in self._flames:
            canvas.line(at, (at[0] + 3 * ox, at[1] + 3 * oy), 4.0 / canvas.scale, (255, 140, 30))
        for body in (self.lander, *self.legs):
            paint_body(canvas, body, (128, 102, 230), (77, 77, 128))
        pixel = 1.0 / canvas.scale
        for x in self.pad_x:
            top = self.pad_y + 50 * pixel
            canvas.line((x, self.pad_y), (x, top), pixel, (255, 255, 255))
            canvas.polygon(
                [(x, top), (x, top - 10 * pixel), (x + 25 * pixel, top - 5 * pixel)], (204, 204, 0)
            )
        return canvas.frame()

    def close(self) -> None:
        self.world = self.lander = None
        self.legs = ()
