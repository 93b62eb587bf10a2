"""BipedalWalker on Box2D: gymnasium's ``BipedalWalker-v3`` (and its hardcore terrain) step by step.

How the context reaches the simulation (all values held by the instance):

- ``FRICTION`` is the friction of every fixture gymnasium builds from it: the ground's edges and the
  hardcore obstacles (stumps, pit walls, stairs). The hull (0.1) and the legs (Box2D's 0.2) keep
  their own friction, as in gymnasium; a contact takes the geometric mean of its two fixtures'.
- ``SCALE`` is pixels per metre for what gymnasium sizes in pixels: the hull polygon, the terrain's
  random slope steps, the reward (130 per ``SCALE`` metres walked) and the drawing. Lengths that CARL
  exposes in metres (legs, terrain, lidar) are their own features.
- ``VIEWPORT_W/H`` are the drawn window (pixels); in the observation they scale the hull's velocity as
  gymnasium does (``0.3 · v · VIEWPORT / SCALE / FPS``), so the velocity keeps gymnasium's units of
  the window the walker is seen in. Because ``FPS``, ``SCALE`` and the viewport rescale these
  velocities (and angles are unbounded), the declared bounds of the hull and joint states are
  unbounded; leg contacts are 0 or 1 and the ten lidar fractions lie in [0, 1].
- ``hardcore`` adds gymnasium's obstacles; its time limit there is 2000 steps (pass ``max_steps=2000``).
"""

from __future__ import annotations

import math
from typing import Any

import Box2D
import gymnasium
import numpy as np
from Box2D.b2 import (
    bodyDef as b2BodyDef,
)
from Box2D.b2 import (
    contactListener,
    edgeShape,
    fixtureDef,
    polygonShape,
    rayCastCallback,
    revoluteJointDef,
)

from contextrl.context.features import ContextBase, context_type, feature
from contextrl.envs.box2d.base import Box2DEnv, fps_feature, paint_body, sign

HULL_POLYGON = ((-30, 9), (6, 9), (34, 1), (34, -8), (-30, -8))  # pixels
GRASS, STUMP, STAIRS, PIT = range(4)  # gymnasium draws each obstacle uniformly from STUMP..PIT
LIDAR_RAYS = 10
WALKER = "walker"  # the userData of the walker's fixtures, which the lidar looks through
VELOCITY_ITERATIONS, POSITION_ITERATIONS = 6 * 30, 2 * 30


@context_type
class BipedalWalkerContext(ContextBase):
    """Context features of BipedalWalker; the defaults are gymnasium's ``BipedalWalker-v3``."""

    FPS: float = fps_feature()
    SCALE: float = feature(
        30.0,
        1.0,
        100.0,
        unit="px/m",
        doc="pixels per metre of the hull, slope noise and reward",
        affects=("dynamics", "start_state", "observation", "reward"),
    )
    GRAVITY_X: float = feature(0.0, -20.0, 20.0, unit="m/s²", doc="gravity along x")
    GRAVITY_Y: float = feature(
        -10.0, -20.0, -0.01, unit="m/s²", doc="gravity along y (negative: down)"
    )
    FRICTION: float = feature(2.5, 0.0, 10.0, doc="friction of the ground and the obstacles")
    TERRAIN_STEP: float = feature(
        14 / 30,
        0.25,
        1.0,
        unit="m",
        doc="width of one terrain segment",
        affects=("dynamics", "start_state", "goal"),
    )
    TERRAIN_LENGTH: int = feature(
        200,
        100,
        500,
        kind="int",
        doc="terrain segments; the goal is 'TERRAIN_GRASS' before the end",
        affects=("dynamics", "goal"),
    )
    TERRAIN_HEIGHT: float = feature(
        10 / 3, 3.0, 10.0, unit="m", doc="height of the flat start pad", affects=("start_state",)
    )
    TERRAIN_GRASS: int = feature(
        10,
        5,
        15,
        kind="int",
        doc="longest stretch of grass between obstacles (segments)",
        affects=("dynamics", "goal"),
    )
    TERRAIN_STARTPAD: int = feature(
        20,
        10,
        30,
        kind="int",
        doc="flat segments at the start",
        affects=("dynamics", "start_state"),
    )
    MOTORS_TORQUE: float = feature(
        80.0,
        0.01,
        200.0,
        unit="N·m",
        doc="largest torque of each joint's motor",
        affects=("dynamics", "reward"),
    )
    SPEED_HIP: float = feature(
        4.0,
        0.01,
        15.0,
        unit="rad/s",
        doc="speed of the hip motors",
        affects=("dynamics", "observation"),
    )
    SPEED_KNEE: float = feature(
        6.0,
        0.01,
        15.0,
        unit="rad/s",
        doc="speed of the knee motors",
        affects=("dynamics", "observation"),
    )
    LIDAR_RANGE: float = feature(
        160 / 30, 0.01, 20.0, unit="m", doc="reach of the ten lidar rays", affects=("observation",)
    )
    LEG_DOWN: float = feature(
        -8 / 30, -2.0, -0.25, unit="m", doc="height of the hips relative to the hull's centre"
    )
    LEG_W: float = feature(8 / 30, 0.25, 0.5, unit="m", doc="width of the upper legs (lower: 80 %)")
    LEG_H: float = feature(34 / 30, 0.25, 2.0, unit="m", doc="length of each leg segment")
    INITIAL_RANDOM: float = feature(
        5.0,
        0.0,
        50.0,
        unit="N",
        doc="largest random forward push at the start",
        affects=("start_state",),
    )
    VIEWPORT_W: int = feature(
        600,
        400,
        1000,
        kind="int",
        unit="px",
        doc="drawn window width; scales the x velocity seen",
        affects=("observation",),
    )
    VIEWPORT_H: int = feature(
        400,
        200,
        800,
        kind="int",
        unit="px",
        doc="drawn window height; scales the y velocity seen",
        affects=("observation",),
    )
    hardcore: int = feature(
        "off",
        0,
        1,
        kind="categorical",
        choices=("off", "on"),
        doc="gymnasium's hardcore terrain: stumps, pits and stairs",
    )


class _Contacts(contactListener):
    """Ends the episode when the hull touches the ground; tracks the lower legs' ground contact."""

    def __init__(self, env: BipedalWalker):
        contactListener.__init__(self)
        self.env = env

    def BeginContact(self, contact):
        bodies = (contact.fixtureA.body, contact.fixtureB.body)
        if self.env.hull in bodies:
            self.env.game_over = True
        for index in (1, 3):
            if self.env.legs[index] in bodies:
                self.env.foot_contact[index] = True

    def EndContact(self, contact):
        bodies = (contact.fixtureA.body, contact.fixtureB.body)
        for index in (1, 3):
            if self.env.legs[index] in bodies:
                self.env.foot_contact[index] = False


class _Lidar(rayCastCallback):
    """The nearest ground hit along a ray; the walker's own fixtures (marked by their ``userData``,
    cheaper to read than gymnasium's category bits, which single out the same fixtures) are passed
    through."""

    def ReportFixture(self, fixture, point, normal, fraction):
        if fixture.userData is not None:
            return -1
        self.fraction = fraction
        return fraction


class BipedalWalker(Box2DEnv):
    """Walk to the end of the terrain with four motor-driven joints (gymnasium ``BipedalWalker-v3``).

    Actions: four motor commands in [-1, 1] (hips and knees); observation: hull angle and velocities,
    joint angles and speeds, foot contacts and ten lidar fractions. 1600 steps.
    """

    context_type = BipedalWalkerContext
    default_max_steps = 1600

    def __init__(self) -> None:
        super().__init__()
        self.action_space = gymnasium.spaces.Box(-1.0, 1.0, (4,), dtype=np.float32)
        low = np.full(24, -np.inf, np.float32)
        high = np.full(24, np.inf, np.float32)
        low[[8, 13]], high[[8, 13]] = 0.0, 1.0  # foot contacts
        low[14:], high[14:] = 0.0, 1.0  # lidar fractions
        self.base_observation_space = gymnasium.spaces.Box(low, high, dtype=np.float32)
        # One world for the instance's life, emptied at each reset in gymnasium's order (its bodies'
        # creation order decides the order of contacts, so episodes after the first match too).
        self.world = Box2D.b2World()
        self.terrain: list = []
        self.hull = None
        self.legs: list = []
        self.joints: list = []
        self.foot_contact = [False] * 4
        self.game_over = False
        # Definitions made once and reused: pybox2d never frees a fixture definition (about 0.3 kB
        # each), so definitions made at every reset would leak.
        self._ground = b2BodyDef()  # static, at the origin
        self._hull = fixtureDef(
            shape=polygonShape(box=(1, 1)),
            density=5.0,
            friction=0.1,
            categoryBits=0x0020,
            maskBits=0x001,  # collides only with the ground
            restitution=0.0,
            userData=WALKER,
        )
        self._thigh, self._shin = (
            fixtureDef(
                shape=polygonShape(box=(1, 1)),
                density=1.0,
                restitution=0.0,
                categoryBits=0x0020,
                maskBits=0x001,
                userData=WALKER,
            )
            for _ in range(2)
        )
        self._edge = fixtureDef(shape=edgeShape(vertices=[(0, 0), (1, 1)]), categoryBits=0x0001)
        square = [(0, 0), (1, 0), (1, -1), (0, -1)]
        self._block = fixtureDef(shape=polygonShape(vertices=square), categoryBits=0x0001)
        self._lidar = _Lidar()
        angles = [1.5 * i / 10.0 for i in range(LIDAR_RAYS)]
        self._ray_directions = [(math.sin(a), -math.cos(a)) for a in angles]

    # ---- episode ---------------------------------------------------------------------------------
    def reset_physics(self, context: Any, rng: np.random.Generator) -> np.ndarray:
        v = self._start(context, rng)
        self._destroy()
        self.world.gravity = (v["GRAVITY_X"], v["GRAVITY_Y"])
        self._listener = _Contacts(self)
        self.world.contactListener = self._listener
        self.game_over = False
        self._previous_shaping = None
        self._generate_terrain(bool(v["hardcore"]))
        self._generate_clouds()
        self._build_walker()
        self._goal_x = (v["TERRAIN_LENGTH"] - v["TERRAIN_GRASS"]) * v["TERRAIN_STEP"]
        self._window = (v["VIEWPORT_W"] / v["SCALE"], v["VIEWPORT_H"] / v["SCALE"])
        reach = v["LIDAR_RANGE"]
        self._ray_offsets = [(dx * reach, dy * reach) for dx, dy in self._ray_directions]
        return self._advance([0.0, 0.0, 0.0, 0.0])[0]

    def _destroy(self) -> None:
        if not self.terrain:
            return
        self.world.contactListener = None
        for body in (*self.terrain, self.hull, *self.legs):
            self.world.DestroyBody(body)
        self.terrain, self.hull, self.legs, self.joints = [], None, [], []

    def _static(self, definition, vertices, color) -> None:
        """A ground body (an edge or an obstacle) from a reused definition: building the terrain's
        hundreds of bodies from fresh definitions would cost more than gymnasium's reset."""
        definition.shape.vertices = vertices
        body = self.world.CreateBody(self._ground)
        body.CreateFixture(definition)
        self.terrain.append(body)
        self._colors.append(color)

    def _generate_terrain(self, hardcore: bool) -> None:
        """gymnasium's terrain, drawn from the episode's generator in the same order."""
        v, rng = self._values, self._rng
        step, start_pad, grass = (
            v["TERRAIN_STEP"],
            int(v["TERRAIN_STARTPAD"]),
            int(v["TERRAIN_GRASS"]),
        )
        terrain_height, scale = v["TERRAIN_HEIGHT"], v["SCALE"]
        edge, block = self._edge, self._block
        edge.friction = block.friction = v["FRICTION"]
        obstacle = ((255, 255, 255), (153, 153, 153))
        self.terrain, self._colors = [], []
        state, velocity, y, counter, oneshot = GRASS, 0.0, terrain_height, start_pad, False
        stair_steps = stair_width = stair_height = 0
        original_y = 0.0
        self.terrain_x, self.terrain_y = [], []
        for i in range(int(v["TERRAIN_LENGTH"])):
            x = i * step
            self.terrain_x.append(x)
            if state == GRASS and not oneshot:
                velocity = 0.8 * velocity + 0.01 * sign(terrain_height - y)
                if i > start_pad:
                    velocity += rng.uniform(-1, 1) / scale
                y += velocity
            elif state == PIT and oneshot:
                counter = int(rng.integers(3, 5))
                wall = [(x, y), (x + step, y), (x + step, y - 4 * step), (x, y - 4 * step)]
                self._static(block, wall, obstacle)
                far = [(px + step * counter, py) for px, py in wall]
                self._static(block, far, obstacle)
                counter += 2
                original_y = y
            elif state == PIT and not oneshot:
                y = original_y
                if counter > 1:
                    y -= 4 * step
            elif state == STUMP and oneshot:
                counter = int(rng.integers(1, 3))
                size = counter * step
                stump = [(x, y), (x + size, y), (x + size, y + size), (x, y + size)]
                self._static(block, stump, obstacle)
            elif state == STAIRS and oneshot:
                stair_height = +1 if rng.random() > 0.5 else -1
                stair_width = int(rng.integers(4, 5))
                stair_steps = int(rng.integers(3, 5))
                original_y = y
                for s in range(stair_steps):
                    left, right = x + (s * stair_width) * step, x + ((1 + s) * stair_width) * step
                    top, bottom = y + (s * stair_height) * step, y + (-1 + s * stair_height) * step
                    stair = [(left, top), (right, top), (right, bottom), (left, bottom)]
                    self._static(block, stair, obstacle)
                counter = stair_steps * stair_width
            elif state == STAIRS and not oneshot:
                s = stair_steps * stair_width - counter - stair_height
                y = original_y + (s / stair_width * stair_height) * step
            oneshot = False
            self.terrain_y.append(y)
            counter -= 1
            if counter == 0:
                counter = int(rng.integers(grass // 2, grass))
                state = int(rng.integers(STUMP, PIT + 1)) if state == GRASS and hardcore else GRASS
                oneshot = True
        self.ground: list[list[tuple[float, float]]] = []  # the grass under each edge, for drawing
        for i in range(len(self.terrain_x) - 1):
            left = (self.terrain_x[i], self.terrain_y[i])
            right = (self.terrain_x[i + 1], self.terrain_y[i + 1])
            green = (76, 255 if i % 2 == 0 else 204, 76)
            self._static(edge, [left, right], (green, green))
            self.ground.append([left, right, (right[0], 0.0), (left[0], 0.0)])
        self.terrain.reverse()
        self._colors.reverse()

    def _generate_clouds(self) -> None:
        """Decoration only, but drawn from the generator as gymnasium does (later draws follow it)."""
        v, rng = self._values, self._rng
        step = v["TERRAIN_STEP"]
        y = v["VIEWPORT_H"] / v["SCALE"] * 3 / 4
        self.clouds = []
        for _ in range(int(v["TERRAIN_LENGTH"]) // 20):
            x = rng.uniform(0, v["TERRAIN_LENGTH"]) * step
            cloud = []
            for a in range(5):
                px = x + 15 * step * math.sin(3.14 * 2 * a / 5) + rng.uniform(0, 5 * step)
                py = y + 5 * step * math.cos(3.14 * 2 * a / 5) + rng.uniform(0, 5 * step)
                cloud.append((px, py))
            self.clouds.append(cloud)

    def _build_walker(self) -> None:
        v, rng = self._values, self._rng
        scale, leg_down, leg_w, leg_h = v["SCALE"], v["LEG_DOWN"], v["LEG_W"], v["LEG_H"]
        torque = v["MOTORS_TORQUE"]
        x = v["TERRAIN_STEP"] * v["TERRAIN_STARTPAD"] / 2
        y = v["TERRAIN_HEIGHT"] + 2 * leg_h
        self._hull.shape.vertices = [(px / scale, py / scale) for px, py in HULL_POLYGON]
        self.hull = self.world.CreateDynamicBody(position=(x, y), fixtures=self._hull)
        push = v["INITIAL_RANDOM"]
        self.hull.ApplyForceToCenter((rng.uniform(-push, push), 0), True)
        upper, lower = self._thigh, self._shin
        upper.shape.box = (leg_w / 2, leg_h / 2)
        lower.shape.box = (0.8 * leg_w / 2, leg_h / 2)
        for side in (-1, +1):
            thigh = self._limb(upper, (x, y - leg_h / 2 - leg_down), side)
            hip = revoluteJointDef(
                bodyA=self.hull,
                bodyB=thigh,
                localAnchorA=(0, leg_down),
                localAnchorB=(0, leg_h / 2),
                enableMotor=True,
                enableLimit=True,
                maxMotorTorque=torque,
                motorSpeed=side,
                lowerAngle=-0.8,
                upperAngle=1.1,
            )
            self.joints.append(self.world.CreateJoint(hip))
            shin = self._limb(lower, (x, y - leg_h * 3 / 2 - leg_down), side)
            knee = revoluteJointDef(
                bodyA=thigh,
                bodyB=shin,
                localAnchorA=(0, -leg_h / 2),
                localAnchorB=(0, leg_h / 2),
                enableMotor=True,
                enableLimit=True,
                maxMotorTorque=torque,
                motorSpeed=1,
                lowerAngle=-1.6,
                upperAngle=-0.1,
            )
            self.joints.append(self.world.CreateJoint(knee))
        self.foot_contact = [False] * 4

    def _limb(self, definition, position: tuple[float, float], side: int):
        limb = self.world.CreateDynamicBody(
            position=position, angle=side * 0.05, fixtures=definition
        )
        self.legs.append(limb)
        return limb

    def step_physics(self, action) -> tuple[np.ndarray, float, bool]:
        if self.hull is None:
            raise RuntimeError(f"{self.name}: call reset_physics before step_physics")
        return self._advance(self._continuous_action(action, 4))

    def _advance(self, action: list[float]) -> tuple[np.ndarray, float, bool]:
        """One step under four motor commands (float32 values), as gymnasium computes it."""
        v = self._values
        fps, torque = v["FPS"], v["MOTORS_TORQUE"]
        speeds = (v["SPEED_HIP"], v["SPEED_KNEE"], v["SPEED_HIP"], v["SPEED_KNEE"])
        for joint, command, speed in zip(self.joints, action, speeds, strict=True):
            joint.motorSpeed = speed * sign(command)
            joint.maxMotorTorque = torque * min(abs(command), 1.0)
        self.world.Step(1.0 / fps, VELOCITY_ITERATIONS, POSITION_ITERATIONS)

        hull = self.hull
        position, velocity = hull.position, hull.linearVelocity
        lidar, world = self._lidar, self.world
        x, y = position[0], position[1]
        fractions = []
        for dx, dy in self._ray_offsets:
            lidar.fraction = 1.0
            world.RayCast(lidar, position, (x + dx, y + dy))
            fractions.append(lidar.fraction)
        self._lidar_seen = (x, y), fractions
        hip_a, knee_a, hip_b, knee_b = self.joints
        state = [
            hull.angle,
            2.0 * hull.angularVelocity / fps,
            0.3 * velocity.x * self._window[0] / fps,
            0.3 * velocity.y * self._window[1] / fps,
            hip_a.angle,
            hip_a.speed / v["SPEED_HIP"],
            knee_a.angle + 1.0,
            knee_a.speed / v["SPEED_KNEE"],
            1.0 if self.foot_contact[1] else 0.0,
            hip_b.angle,
            hip_b.speed / v["SPEED_HIP"],
            knee_b.angle + 1.0,
            knee_b.speed / v["SPEED_KNEE"],
            1.0 if self.foot_contact[3] else 0.0,
            *fractions,
        ]
        self.scroll = position.x - self._window[0] / 5
        shaping = 130 * position[0] / v["SCALE"]  # walking forward earns reward
        shaping -= 5.0 * abs(state[0])  # and keeping the hull level
        reward = 0.0 if self._previous_shaping is None else shaping - self._previous_shaping
        self._previous_shaping = shaping
        # The motors' effort; gymnasium subtracts it in float32 (a Python float minus a float32 is a
        # float32 under NumPy 2), so the reward is rounded the same way here.
        reward = np.float32(reward)
        for cost in np.float32(0.00035 * torque) * np.minimum(np.abs(np.float32(action)), 1):
            reward -= cost
        reward = float(reward)
        terminated = False
        if self.game_over or position[0] < 0:
            terminated, reward = True, -100.0
        if position[0] > self._goal_x:
            terminated = True
        return np.array(state, dtype=np.float32), reward, terminated

    # ---- drawing -------------------------------------------------------------------------------
    def render_frame(self) -> np.ndarray:
        """The window following the walker: sky, clouds, terrain, obstacles, lidar, walker, flag."""
        if self.hull is None:
            raise RuntimeError(f"{self.name}: call reset_physics before render_frame")
        canvas = self._canvas(self.scroll, background=(215, 215, 255))
        left, right = canvas.x_min, canvas.x_max
        drift = self.scroll / 2  # clouds move at half the walker's speed
        for cloud in self.clouds:
            shifted = [(x + drift, y) for x, y in cloud]
            xs = [p[0] for p in shifted]
            if max(xs) >= left and min(xs) <= right:
                canvas.polygon(shifted, (255, 255, 255))
        for quad in self.ground:
            if quad[1][0] >= left and quad[0][0] <= right:
                canvas.polygon(quad, (102, 153, 76))
        for body, (fill, outline) in zip(self.terrain, self._colors, strict=True):
            shape = body.fixtures[0].shape
            if isinstance(shape, Box2D.b2PolygonShape):
                paint_body(canvas, body, fill, outline)
        pixel = 1.0 / canvas.scale
        (x, y), fractions = self._lidar_seen
        for (dx, dy), fraction in zip(self._ray_offsets, fractions, strict=True):
            canvas.line((x, y), (x + fraction * dx, y + fraction * dy), pixel, (255, 0, 0))
        for index, body in enumerate((*self.legs, self.hull)):
            if body is self.hull:
                paint_body(canvas, body, (127, 51, 229), (76, 76, 127))
            else:
                shade = 25 if index < 2 else -25  # the far leg lighter, the near one darker
                paint_body(canvas, body, (153 + shade, 76 + shade, 127 + shade), (102, 51, 76))
        flag_x, flag_y = self.terrain_x[1], self.terrain_y[1]
        canvas.line((flag_x, flag_y), (flag_x, flag_y + 50 * pixel), pixel, (0, 0, 0))
        canvas.polygon(
            [
                (flag_x, flag_y + 50 * pixel),
                (flag_x, flag_y + 40 * pixel),
                (flag_x + 25 * pixel, flag_y + 45 * pixel),
            ],
            (230, 51, 0),
        )
        return canvas.frame()

    def close(self) -> None:
        self._destroy()
