"""VehicleRacing: gymnasium's ``CarRacing-v3`` with a garage of vehicles and the track shape as context.

At the default context (the race car in rear-wheel drive, gymnasium's track constants) an episode is
``CarRacing-v3``'s step by step: the same random draws lay out the same track, the same bodies are built in
the same order, the same car model runs, and the same pygame drawing calls produce the same 96×96×3
observation. Drawing differs only in how the scene is culled: the road and grass polygons are rotated and
tested against the window with NumPy in one pass (the same float64 arithmetic gymnasium does per vertex),
so only the few visible polygons reach pygame.

Context:

- ``vehicle`` (categorical): one of the garage's 29 vehicles (``garage.VEHICLE_NAMES``, CARL's order, so
  CARL's integer ``VEHICLE_ID`` picks the same vehicle). Everything the vehicle declares reaches Box2D
  and the car model: hull and wheel shapes and masses, which wheels steer and drive, engine power, wheel
  inertia, friction limit, brake shares, and the trailer with its joints.
- ``track_turn_rate``, ``track_width``, ``checkpoints``: gymnasium's ``TRACK_TURN_RATE``, ``TRACK_WIDTH``
  (half the road's width) and the number of checkpoints the track is laid through. They change the
  track: its curvature, the red-white borders on hard turns, the road's width (what counts as road for
  grip and tile rewards) and the number of tiles.

Every value an episode uses lives on the instance (its world, car, track and colours); the module holds
only CarRacing's fixed constants, which no context changes, so instances never leak into each other.
Rendering is headless: ``SDL_VIDEODRIVER=dummy`` is set (unless already set) when an environment is
constructed; no window is ever opened.
"""

from __future__ import annotations

import math
import os
from collections import deque
from typing import Any

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")  # pygame greets on stdout at import

import Box2D  # noqa: E402
import gymnasium  # noqa: E402
import numpy as np  # noqa: E402
import pygame  # noqa: E402
from Box2D.b2 import contactListener, fixtureDef, polygonShape, revoluteJointDef  # noqa: E402
from pygame import gfxdraw  # noqa: E402

from contextrl.context.features import ContextBase, ContextError, context_type, feature  # noqa: E402
from contextrl.core.host import HostEnv  # noqa: E402
from contextrl.envs.box2d.garage import GARAGE, UNIT, VEHICLE_NAMES, Vehicle, Wheel  # noqa: E402

# CarRacing's fixed constants (no context changes them).
STATE_W = STATE_H = 96
VIDEO_W, VIDEO_H = 600, 400
WINDOW_W, WINDOW_H = 1000, 800
SCALE = 6.0  # track scale
TRACK_RAD = 900 / SCALE  # the track is a heavily morphed circle of this radius
PLAYFIELD = 2000 / SCALE  # leaving this square ends the episode
FPS = 50
ZOOM = 2.7
TRACK_DETAIL_STEP = 21 / SCALE
BORDER = 8 / SCALE
BORDER_MIN_COUNT = 4
GRASS_DIM = PLAYFIELD / 20.0
MAX_TRACK_ATTEMPTS = 1000  # a safety net: within the bounds a track is found in a few attempts
ROAD_COLOR = (102, 102, 102)
BACKGROUND_COLOR = (102, 204, 102)
GRASS_COLOR = (102, 230, 102)
WHEEL_COLOR = (0, 0, 0)
WHEEL_WHITE = (77, 77, 77)
MUD_COLOR = (102, 102, 0)
GRASS_GRIP = 0.6  # share of the friction limit a wheel keeps off the road
WHEEL_SLIP_GAIN = 205000 * UNIT * UNIT  # gymnasium's coefficient that damps slip oscillations
BRAKE_SPEED = 15  # rad/s of wheel spin a full brake removes per step
WHEEL_DENSITY = 0.1
WHEEL_CATEGORY, TRAILER_CATEGORY, GROUND_CATEGORY = 0x0020, 0x0040, 0x0001
STEER_TORQUE = 180 * 900 * UNIT * UNIT


@context_type
class VehicleRacingContext(ContextBase):
    """Context features of VehicleRacing; the defaults are ``CarRacing-v3``."""

    vehicle: int = feature(
        "race_car_rwd",
        0,
        0,
        kind="categorical",
        choices=VEHICLE_NAMES,
        doc="the vehicle from the garage (body, wheels, drive, engine, grip, trailer)",
        affects=("dynamics", "observation"),
        aliases=("VEHICLE_ID", "VEHICLE"),
    )
    track_turn_rate: float = feature(
        0.31,
        0.05,
        1.0,
        unit="rad",
        doc="largest heading change between two track points as the track is laid out",
        affects=("start_state", "reward", "observation"),
        aliases=("TRACK_TURN_RATE",),
    )
    track_width: float = feature(
        40 / SCALE,
        3.0,
        15.0,
        unit="m",
        doc="half the road's width",
        affects=("dynamics", "reward", "observation"),
        aliases=("TRACK_WIDTH",),
    )
    checkpoints: int = feature(
        12,
        8,
        32,
        kind="int",
        doc="number of random checkpoints the track is laid through",
        affects=("start_state", "reward", "observation"),
        aliases=("CHECKPOINTS",),
    )


# ---- the track ------------------------------------------------------------------------------------
def lay_out_track(
    rng: np.random.Generator, turn_rate: float, checkpoint_count: int
) -> list[tuple[float, float, float, float]] | None:
    """Points ``(alpha, beta, x, y)`` of one closed lap, or None when this attempt does not close.

    CarRacing's procedure, random draws in its order: checkpoints at noisy angles and radii around a
    circle, then a walk that turns towards the next checkpoint by at most ``turn_rate`` per step; the
    second lap of the walk is the track if its ends meet.
    """
    checkpoints = []
    for c in range(checkpoint_count):
        noise = rng.uniform(0, 2 * math.pi * 1 / checkpoint_count)
        alpha = 2 * math.pi * c / checkpoint_count + noise
        radius = rng.uniform(TRACK_RAD / 3, TRACK_RAD)
        if c == 0:
            alpha, radius = 0, 1.5 * TRACK_RAD
        if c == checkpoint_count - 1:
            alpha, radius = 2 * math.pi * c / checkpoint_count, 1.5 * TRACK_RAD
        checkpoints.append((alpha, radius * math.cos(alpha), radius * math.sin(alpha)))
    start_alpha = 2 * math.pi * (-0.5) / checkpoint_count

    x, y, beta = 1.5 * TRACK_RAD, 0.0, 0.0
    target, laps, crossed_below = 0, 0, False
    walk = []
    for _ in range(2500):
        alpha = math.atan2(y, x)
        if crossed_below and alpha > 0:
            laps += 1
            crossed_below = False
        if alpha < 0:
            crossed_below = True
            alpha += 2 * math.pi
        while True:  # the next checkpoint ahead; past the last one, look again one turn earlier
            found = False
            while True:
                target_alpha, target_x, target_y = checkpoints[target % checkpoint_count]
                if alpha <= target_alpha:
                    found = True
                    break
                target += 1
                if target % checkpoint_count == 0:
                    break
            if found:
                break
            alpha -= 2 * math.pi
        heading_x, heading_y = math.cos(beta), math.sin(beta)
        projection = heading_x * (target_x - x) + heading_y * (target_y - y)
        while beta - alpha > 1.5 * math.pi:
            beta -= 2 * math.pi
        while beta - alpha < -1.5 * math.pi:
            beta += 2 * math.pi
        previous_beta = beta
        projection *= SCALE
        if projection > 0.3:
            beta -= min(turn_rate, abs(0.001 * projection))
        if projection < -0.3:
            beta += min(turn_rate, abs(0.001 * projection))
        x += -heading_y * TRACK_DETAIL_STEP
        y += heading_x * TRACK_DETAIL_STEP
        walk.append((alpha, previous_beta * 0.5 + beta * 0.5, x, y))
        if laps > 4:
            break

    first = last = -1  # the last two crossings of the start line bound one lap
    i = len(walk)
    while True:
        i -= 1
        if i == 0:
            return None
        crosses = walk[i][0] > start_alpha and walk[i - 1][0] <= start_alpha
        if crosses and last == -1:
            last = i
        elif crosses and first == -1:
            first = i
            break
    track = walk[first : last - 1]
    if len(track) < 3:
        return None
    first_beta = track[0][1]
    gap_x = math.cos(first_beta) * (track[0][2] - track[-1][2])
    gap_y = math.sin(first_beta) * (track[0][3] - track[-1][3])
    gap = math.sqrt(gap_x * gap_x + gap_y * gap_y)
    return None if gap > TRACK_DETAIL_STEP else track


def sign(value: float) -> float:
    return float((value > 0) - (value < 0))


def hard_turns(track: list, turn_rate: float) -> list[bool]:
    """Which track segments get a red-white border: runs of turns sharper than a fifth of the rate."""
    border = [False] * len(track)
    for i in range(len(track)):
        sharp, direction = True, 0.0
        for back in range(BORDER_MIN_COUNT):
            turn = track[i - back][1] - track[i - back - 1][1]
            sharp &= abs(turn) > turn_rate * 0.2
            direction += sign(turn)
        border[i] = sharp and abs(direction) == BORDER_MIN_COUNT
    for i in range(len(track)):  # in place, as CarRacing does (the wrap-around carries on)
        for back in range(BORDER_MIN_COUNT):
            border[i - back] |= border[i]
    return border


# ---- Box2D objects the contact listener and the car model work on --------------------------------
class Tile:
    """One road tile: its index along the track and whether a wheel has touched it."""

    __slots__ = ("index", "polygon", "visited")

    def __init__(self, index: int, polygon: int):
        self.index, self.polygon, self.visited = index, polygon, False


class WheelState:
    """A wheel body and everything gymnasium's car model keeps per wheel."""

    __slots__ = (
        "body",
        "joint",
        "spec",
        "radius",
        "gas",
        "brake",
        "steer",
        "phase",
        "omega",
        "skid_start",
        "skid_mark",
        "tiles",
    )

    def __init__(self, body, joint, spec: Wheel):
        self.body, self.joint, self.spec = body, joint, spec
        self.radius = spec.radius * UNIT
        self.gas = self.brake = self.steer = self.phase = self.omega = 0.0
        self.skid_start = self.skid_mark = None
        self.tiles: set[Tile] = set()


class SkidMark:
    __slots__ = ("color", "points", "on_grass")

    def __init__(self, start, end, on_grass: bool):
        self.color = MUD_COLOR if on_grass else WHEEL_COLOR
        self.points = [(start[0], start[1]), (end[0], end[1])]
        self.on_grass = on_grass


class TileContacts(contactListener):
    """Forwards Box2D's contact events to the one race they belong to."""

    def __init__(self, race: VehicleRacing):
        contactListener.__init__(self)
        self.race = race

    def BeginContact(self, contact):  # noqa: N802 - Box2D's name
        self.race.tile_contact(contact, True)

    def EndContact(self, contact):  # noqa: N802 - Box2D's name
        self.race.tile_contact(contact, False)


class VehicleRacing(HostEnv):
    """``CarRacing-v3`` with a vehicle and a track shape per episode; pixels in, steer/gas/brake out.

    ``continuous`` (default True): actions ``(steer, gas, brake)`` in ``[-1, 1] × [0, 1] × [0, 1]``;
    False: five discrete actions (nothing, right, left, gas, brake), as gymnasium's. An episode ends when
    the lap is done (``lap_complete_percent`` of the tiles visited and the start tile reached) or the car
    leaves the playfield (reward −100); the adapter's time limit is 1000 steps.
    """

    context_type = VehicleRacingContext
    default_max_steps = 1000
    control_timestep = 1.0 / FPS

    def __init__(self, continuous: bool = True, lap_complete_percent: float = 0.95):
        if not isinstance(continuous, bool):
            raise ValueError(f"{self.name}: continuous must be True or False, got {continuous!r}")
        if isinstance(lap_complete_percent, bool) or not (
            isinstance(lap_complete_percent, (int, float)) and 0.0 <= lap_complete_percent <= 1.0
        ):
            raise ValueError(
                f"{self.name}: lap_complete_percent must be a number in [0, 1], "
                f"got {lap_complete_percent!r}"
            )
        self.continuous = continuous
        self.lap_complete_percent = float(lap_complete_percent)
        if continuous:
            self.action_space = gymnasium.spaces.Box(
                np.array([-1, 0, 0], np.float32), np.array([1, 1, 1], np.float32)
            )
        else:
            self.action_space = gymnasium.spaces.Discrete(5)
        self.base_observation_space = gymnasium.spaces.Box(
            0, 255, (STATE_H, STATE_W, 3), dtype=np.uint8
        )
        os.environ.setdefault("SDL_VIDEODRIVER", "dummy")  # headless: no window is ever opened
        pygame.font.init()
        self._font = pygame.font.Font(pygame.font.get_default_font(), 42)
        self._surface = pygame.Surface((WINDOW_W, WINDOW_H))
        # One world per instance, emptied at every reset (as CarRacing's): a Box2D world dropped whole
        # with its contact listener is never freed.
        self.world = Box2D.b2World((0, 0), contactListener=TileContacts(self))
        self.track: list | None = None
        self.vehicle: Vehicle | None = None
        self.outcome: dict[str, bool] = {}
        # Fixture definitions are reused: pybox2d never frees one (a leak of ~300 bytes each).
        self._tile_fixture = fixtureDef(
            shape=polygonShape(vertices=[(0, 0), (1, 0), (1, -1), (0, -1)]), isSensor=True
        )
        self._fixtures: dict[str, tuple] = {}

    # ---- HostEnv interface ------------------------------------------------------------------------

    def reset_physics(self, context: Any, rng: np.random.Generator) -> np.ndarray:
        vehicle_index, turn_rate, width, checkpoint_count = self.episode_values(context)
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"{self.name}: rng must be a numpy.random.Generator, got {rng!r}")
        self.vehicle = GARAGE[vehicle_index]
        self.turn_rate, self.track_width = turn_rate, width
        self._clear_world()
        self.reward = self.previous_reward = 0.0
        self.outcome: dict[str, bool] = {}
        self.visited_count = 0
        self.time = 0.0
        self.new_lap = False
        for _ in range(MAX_TRACK_ATTEMPTS):
            track = lay_out_track(rng, turn_rate, checkpoint_count)
            if track is not None:
                break
        else:  # pragma: no cover - not reached inside the bounds
            raise RuntimeError(f"{self.name}: no closed track in {MAX_TRACK_ATTEMPTS} attempts")
        self.track = track
        self._build_road(track)
        self._build_vehicle(*track[0][1:4])
        self.skid_marks: deque[SkidMark] = deque(maxlen=30)
        return self._advance(None)[0]

    def step_physics(self, action) -> tuple[np.ndarray, float, bool]:
        if self.track is None:
            raise RuntimeError(f"{self.name}: call reset_physics before step_physics")
        return self._advance(self._check_action(action))

    def step_info(self) -> dict[str, bool]:
        """CarRacing's ``info["lap_finished"]`` when an episode has just ended, else nothing."""
        return dict(self.outcome)

    def render_frame(self) -> np.ndarray:
        if self.track is None:
            raise RuntimeError(f"{self.name}: call reset_physics before render_frame")
        return self._draw((VIDEO_W, VIDEO_H), skid_marks=True)

    def close(self) -> None:
        self._clear_world()

    def _clear_world(self) -> None:
        """Destroy the last episode's bodies (and with them their joints)."""
        for body in list(self.world.bodies):
            self.world.DestroyBody(body)
        self.track = None
        self.tiles = self.wheels = self.bodies = self.joints = ()

    # ---- context -----------------------------------------------------------------------------------
    def episode_values(self, context: Any) -> tuple[int, float, float, int]:
        """``(vehicle index, turn rate, width, checkpoints)`` of a checked context.

        A context holds float32: where it holds the rounding of a default, CarRacing's exact constant
        is used, so the default context is CarRacing bit for bit.
        """
        values = self.context_values(context)
        for name, declared in self.context_space.features.items():
            if declared.kind != "float" and not values[name].is_integer():
                raise ContextError(
                    f"{name}: expected an integer ({declared.kind}), got {values[name]}"
                )
            if np.float32(values[name]) == np.float32(declared.default):
                values[name] = declared.default
        return (
            int(values["vehicle"]),
            float(values["track_turn_rate"]),
            float(values["track_width"]),
            int(values["checkpoints"]),
        )

    def _check_action(self, action):
        if self.continuous:
            try:
                array = np.asarray(action, dtype=np.float64)
            except (TypeError, ValueError) as error:
                raise ValueError(f"{self.name}: action {action!r} is not numeric") from error
            if array.shape != (3,) or not np.isfinite(array).all():
                raise ValueError(
                    f"{self.name}: action must be 3 finite numbers (steer, gas, brake), got {action!r}"
                )
            return array
        if not self.action_space.contains(action):
            raise ValueError(f"{self.name}: action {action!r} is not one of 0..4")
        return int(action)

    # ---- building the world ------------------------------------------------------------------------
    def _build_road(self, track: list) -> None:
        """Tiles (sensor bodies) along the track, and the polygons to draw: tiles and borders."""
        width = self.track_width
        border = hard_turns(track, self.turn_rate)
        tiles, polygons, colors = [], [], []
        for i in range(len(track)):
            _, beta1, x1, y1 = track[i]
            _, beta2, x2, y2 = track[i - 1]
            cos1, sin1, cos2, sin2 = (
                math.cos(beta1),
                math.sin(beta1),
                math.cos(beta2),
                math.sin(beta2),
            )
            road = [
                (x1 - width * cos1, y1 - width * sin1),
                (x1 + width * cos1, y1 + width * sin1),
                (x2 + width * cos2, y2 + width * sin2),
                (x2 - width * cos2, y2 - width * sin2),
            ]
            tile = Tile(i, len(polygons))
            self._tile_fixture.shape.vertices = road
            body = self.world.CreateStaticBody(fixtures=self._tile_fixture)
            body.userData = tile
            tiles.append(tile)
            polygons.append(road)
            colors.append(np.array(ROAD_COLOR) + 0.01 * (i % 3) * 255)
            if border[i]:
                side = sign(beta2 - beta1)
                inner, outer = side * width, side * (width + BORDER)
                polygons.append(
                    [
                        (x1 + inner * cos1, y1 + inner * sin1),
                        (x1 + outer * cos1, y1 + outer * sin1),
                        (x2 + outer * cos2, y2 + outer * sin2),
                        (x2 + inner * cos2, y2 + inner * sin2),
                    ]
                )
                colors.append(np.array((255, 255, 255) if i % 2 == 0 else (255, 0, 0), float))
        self.tiles = tiles
        self.road_polygons = np.array(polygons, dtype=np.float64)
        self.road_colors = np.array(colors, dtype=np.float64)
        self.clip_margin = max(GRASS_DIM, width, TRACK_DETAIL_STEP) * math.sqrt(2) * ZOOM * SCALE

    def _build_vehicle(self, angle: float, x: float, y: float) -> None:
        """The hull, its wheels and the trailer bodies with theirs, in that order.

        Wheels start at their offsets from the hull's origin without the hull's rotation and are pulled
        onto their joints in the first steps, as CarRacing's car is (the start heading is close to a
        multiple of 2π, so the pull is small).
        """
        vehicle = self.vehicle
        if vehicle.name not in self._fixtures:
            self._fixtures[vehicle.name] = vehicle_fixtures(vehicle)
        hull_fixtures, trailer_fixtures, wheel_fixtures = self._fixtures[vehicle.name]
        self.hull = self.world.CreateDynamicBody(
            position=(x, y), angle=angle, fixtures=hull_fixtures
        )
        self.wheels: list[WheelState] = []
        self.bodies = [(self.hull, vehicle.color)]  # drawn after the wheels
        self.joints = []
        self._attach_wheels(self.hull, vehicle.wheels, wheel_fixtures, (0.0, 0.0), angle, x, y)
        pulling = self.hull
        hitch = vehicle.hitch
        parts = () if vehicle.trailer is None else vehicle.trailer.bodies
        for part, fixtures in zip(parts, trailer_fixtures, strict=True):
            body = self.world.CreateDynamicBody(position=(x, y), angle=angle, fixtures=fixtures)
            anchor = ((hitch[0] + part.hitch[0]) * UNIT, (hitch[1] + part.hitch[1]) * UNIT)
            self.joints.append(
                self.world.CreateJoint(
                    revoluteJointDef(
                        bodyA=pulling,
                        bodyB=body,
                        localAnchorA=anchor,
                        localAnchorB=anchor,
                        enableLimit=True,
                        lowerAngle=-part.angle_limit,
                        upperAngle=part.angle_limit,
                    )
                )
            )
            self._attach_wheels(body, part.wheels, wheel_fixtures, hitch, angle, x, y)
            self.bodies.insert(len(self.bodies) - 1, (body, part.color))
            pulling = body
        self.driven = [w for w in self.wheels if w.spec.driven]
        self.steered = [w for w in self.wheels if w.spec.steered]

    def _attach_wheels(
        self, body, specs, fixtures, offset, angle: float, x: float, y: float
    ) -> None:
        for spec in specs:
            wx, wy = spec.x + offset[0], spec.y + offset[1]
            wheel = self.world.CreateDynamicBody(
                position=(x + wx * UNIT, y + wy * UNIT),
                angle=angle,
                fixtures=fixtures[spec.radius, spec.half_width],
            )
            joint = self.world.CreateJoint(
                revoluteJointDef(
                    bodyA=body,
                    bodyB=wheel,
                    localAnchorA=(wx * UNIT, wy * UNIT),
                    localAnchorB=(0, 0),
                    enableMotor=True,
                    enableLimit=True,
                    maxMotorTorque=STEER_TORQUE,
                    motorSpeed=0,
                    lowerAngle=-spec.steer_limit,
                    upperAngle=spec.steer_limit,
                )
            )
            state = WheelState(wheel, joint, spec)
            wheel.userData = state
            self.wheels.append(state)

    # ---- contacts ----------------------------------------------------------------------------------
    def tile_contact(self, contact, begin: bool) -> None:
        """A wheel touching a tile: grip, and the tile's reward the first time; any touch greys it."""
        first, second = contact.fixtureA.body.userData, contact.fixtureB.body.userData
        if isinstance(second, Tile):
            tile, other = second, first
        elif isinstance(first, Tile):
            tile, other = first, second
        else:
            return
        self.road_colors[tile.polygon] = ROAD_COLOR
        if not isinstance(other, WheelState):
            return
        if not begin:
            other.tiles.discard(tile)
            return
        other.tiles.add(tile)
        if not tile.visited:
            tile.visited = True
            self.reward += 1000.0 / len(self.track)
            self.visited_count += 1
            if tile.index == 0 and self.visited_count / len(self.track) > self.lap_complete_percent:
                self.new_lap = True

    # ---- stepping ----------------------------------------------------------------------------------
    def _control(self, action) -> None:
        if self.continuous:
            steer, gas, brake = action.tolist()
            steer = -steer
        else:
            steer = -0.6 * (action == 1) + 0.6 * (action == 2)
            gas, brake = 0.2 * (action == 3), 0.8 * (action == 4)
        for wheel in self.steered:
            wheel.steer = steer
        gas = min(max(gas, 0.0), 1.0)
        for wheel in self.driven:
            wheel.gas += min(gas - wheel.gas, 0.1)  # the throttle opens gradually, closes at once
        for wheel in self.wheels:
            wheel.brake = brake * wheel.spec.brake_share

    def _drive(self, dt: float) -> None:
        """gymnasium's car model, per wheel: steering motor, engine, brakes, slip-limited tyre force."""
        vehicle = self.vehicle
        engine_power = vehicle.engine_power
        inertia = vehicle.wheel_moment_of_inertia
        for wheel in self.wheels:
            body = wheel.body
            offset = wheel.steer - wheel.joint.angle
            wheel.joint.motorSpeed = sign(offset) * min(50.0 * abs(offset), 3.0)
            on_grass = not wheel.tiles
            friction_limit = vehicle.friction_limit * (GRASS_GRIP if on_grass else 1.0)
            forward = body.GetWorldVector((0, 1))
            sideways = body.GetWorldVector((1, 0))
            velocity = body.linearVelocity
            forward_speed = forward[0] * velocity[0] + forward[1] * velocity[1]
            side_speed = sideways[0] * velocity[0] + sideways[1] * velocity[1]
            wheel.omega += dt * engine_power * wheel.gas / inertia / (abs(wheel.omega) + 5.0)
            if wheel.brake >= 0.9:
                wheel.omega = 0.0
            elif wheel.brake > 0:
                braking = min(BRAKE_SPEED * wheel.brake, abs(wheel.omega))
                wheel.omega += -sign(wheel.omega) * braking
            wheel.phase += wheel.omega * dt
            forward_force = (-forward_speed + wheel.omega * wheel.radius) * WHEEL_SLIP_GAIN
            side_force = -side_speed * WHEEL_SLIP_GAIN
            force = math.sqrt(forward_force * forward_force + side_force * side_force)
            if force > 2.0 * friction_limit:
                self._skid(wheel, on_grass)
            else:
                wheel.skid_start = wheel.skid_mark = None
            if force > friction_limit:
                forward_force = forward_force / force * friction_limit
                side_force = side_force / force * friction_limit
            wheel.omega -= dt * forward_force * wheel.radius / inertia
            body.ApplyForceToCenter(
                (
                    side_force * sideways[0] + forward_force * forward[0],
                    side_force * sideways[1] + forward_force * forward[1],
                ),
                True,
            )

    def _skid(self, wheel: WheelState, on_grass: bool) -> None:
        mark = wheel.skid_mark
        if mark and mark.on_grass == on_grass and len(mark.points) < 30:
            mark.points.append((wheel.body.position[0], wheel.body.position[1]))
        elif wheel.skid_start is None:
            wheel.skid_start = wheel.body.position
        else:
            wheel.skid_mark = SkidMark(wheel.skid_start, wheel.body.position, on_grass)
            self.skid_marks.append(wheel.skid_mark)
            wheel.skid_start = None

    def _advance(self, action) -> tuple[np.ndarray, float, bool]:
        """One step (``action`` None: the step CarRacing's reset takes, without reward)."""
        if action is not None:
            self._control(action)
        self._drive(1.0 / FPS)
        self.world.Step(1.0 / FPS, 6 * 30, 2 * 30)
        self.time += 1.0 / FPS
        observation = self._draw((STATE_W, STATE_H), skid_marks=False)
        if action is None:
            return observation, 0.0, False
        self.reward -= 0.1
        step_reward = self.reward - self.previous_reward
        self.previous_reward = self.reward
        terminated = self.visited_count == len(self.track) or self.new_lap
        if terminated:
            self.outcome = {"lap_finished": True}
        x, y = self.hull.position
        if abs(x) > PLAYFIELD or abs(y) > PLAYFIELD:
            terminated, step_reward = True, -100.0
            self.outcome = {"lap_finished": False}
        return observation, float(step_reward), bool(terminated)

    # ---- drawing -----------------------------------------------------------------------------------
    def _draw(self, size: tuple[int, int], skid_marks: bool) -> np.ndarray:
        """The scene from above, following the car, at ``size``; CarRacing's drawing calls."""
        surface = self._surface
        angle = -self.hull.angle
        zoom = 0.1 * SCALE * max(1 - self.time, 0) + ZOOM * SCALE * min(self.time, 1)
        # pygame's own rotation of (1, 0): the exact cosine and sine its Vector2.rotate_rad uses
        cos_a, sin_a = pygame.math.Vector2(1.0, 0.0).rotate_rad(angle)
        scroll_x = -self.hull.position[0] * zoom
        scroll_y = -self.hull.position[1] * zoom
        view = (
            cos_a,
            sin_a,
            zoom,
            WINDOW_W / 2 + (cos_a * scroll_x - sin_a * scroll_y),
            WINDOW_H / 4 + (sin_a * scroll_x + cos_a * scroll_y),
        )
        self._draw_ground(view)
        if skid_marks:
            for mark in self.skid_marks:
                points = [to_screen(view, px, py) for px, py in mark.points]
                pygame.draw.lines(surface, color=mark.color, points=points, width=2, closed=False)
        self._draw_vehicle(view)
        surface = pygame.transform.flip(surface, False, True)
        self._draw_indicators(surface)
        text = self._font.render(f"{self.reward:04.0f}", True, (255, 255, 255), (0, 0, 0))
        rectangle = text.get_rect()
        rectangle.center = (60, WINDOW_H - WINDOW_H * 2.5 / 40.0)
        surface.blit(text, rectangle)
        scaled = pygame.transform.smoothscale(surface, size)
        return np.ascontiguousarray(pygame.surfarray.array3d(scaled).transpose(1, 0, 2))

    def _draw_ground(self, view) -> None:
        """Background, then the grass patches and road polygons that can reach the window.

        The background is the playfield square drawn over black. When the square covers the whole
        window with a few pixels to spare (always, once the opening zoom is over and the car is not at
        the playfield's edge), its edges fall outside and every pixel takes its colour: one fill.
        """
        cos_a, sin_a, zoom, shift_x, shift_y = view
        corners = np.array(
            [(-4, -4), (WINDOW_W + 4, -4), (-4, WINDOW_H + 4), (WINDOW_W + 4, WINDOW_H + 4)]
        )
        dx, dy = (corners[:, 0] - shift_x) / zoom, (corners[:, 1] - shift_y) / zoom
        world_x, world_y = cos_a * dx + sin_a * dy, -sin_a * dx + cos_a * dy
        if max(np.abs(world_x).max(), np.abs(world_y).max()) < PLAYFIELD:
            self._surface.fill(BACKGROUND_COLOR)
        else:
            bound = PLAYFIELD
            field = np.array([[(bound, bound), (bound, -bound), (-bound, -bound), (-bound, bound)]])
            self._surface.fill((0, 0, 0))
            self._fill_polygons(view, field, [BACKGROUND_COLOR], clip=False)
        self._fill_polygons(view, GRASS_POLYGONS, [GRASS_COLOR] * len(GRASS_POLYGONS), clip=True)
        self._fill_polygons(view, self.road_polygons, self.road_colors, clip=True)

    def _fill_polygons(self, view, polygons: np.ndarray, colors, clip: bool) -> None:
        cos_a, sin_a, zoom, shift_x, shift_y = view
        xs, ys = polygons[..., 0], polygons[..., 1]
        screen_x = (cos_a * xs - sin_a * ys) * zoom + shift_x
        screen_y = (sin_a * xs + cos_a * ys) * zoom + shift_y
        if clip:
            margin = self.clip_margin
            inside = (
                (-margin <= screen_x)
                & (screen_x <= WINDOW_W + margin)
                & (-margin <= screen_y)
                & (screen_y <= WINDOW_H + margin)
            )
            shown = np.flatnonzero(inside.any(axis=1))
        else:
            shown = range(len(polygons))
        surface = self._surface
        for index in shown:
            points = list(zip(screen_x[index].tolist(), screen_y[index].tolist(), strict=True))
            color = [int(c) for c in colors[index]]
            gfxdraw.aapolygon(surface, points, color)
            gfxdraw.filled_polygon(surface, points, color)

    def _draw_vehicle(self, view) -> None:
        surface = self._surface
        for wheel in self.wheels:
            transform = wheel.body.transform
            for fixture in wheel.body.fixtures:
                points = [to_screen(view, *(transform * v)) for v in fixture.shape.vertices]
                pygame.draw.polygon(surface, color=WHEEL_COLOR, points=points)
            self._draw_tread(view, wheel, transform)
        for body, color in self.bodies:
            transform = body.transform
            color = [int(c * 255) for c in color]
            for fixture in body.fixtures:
                points = [to_screen(view, *(transform * v)) for v in fixture.shape.vertices]
                pygame.draw.polygon(surface, color=color, points=points)

    def _draw_tread(self, view, wheel: WheelState, transform) -> None:
        """The lighter band that shows a wheel turning."""
        start, end = wheel.phase, wheel.phase + 1.2
        sin1, sin2, cos1, cos2 = math.sin(start), math.sin(end), math.cos(start), math.cos(end)
        if sin1 > 0 and sin2 > 0:
            return
        if sin1 > 0:
            cos1 = sign(cos1)
        if sin2 > 0:
            cos2 = sign(cos2)
        w, r = wheel.spec.half_width * UNIT, wheel.spec.radius
        near, far = r * cos1 * UNIT, r * cos2 * UNIT
        band = [(-w, near), (w, near), (w, far), (-w, far)]
        points = [to_screen(view, *(transform * v)) for v in band]
        pygame.draw.polygon(self._surface, color=WHEEL_WHITE, points=points)

    def _draw_indicators(self, surface) -> None:
        """Speed, the first four wheels' spin, steering angle and yaw rate, along the bottom."""
        s, h = WINDOW_W / 40.0, WINDOW_H / 40.0
        bottom = WINDOW_H
        pygame.draw.polygon(
            surface,
            color=(0, 0, 0),
            points=[
                (WINDOW_W, bottom),
                (WINDOW_W, bottom - 5 * h),
                (0, bottom - 5 * h),
                (0, bottom),
            ],
        )

        def vertical(place, value):
            top = bottom - (h + h * value)
            return [(place * s, top), ((place + 1) * s, top), ((place + 1) * s, bottom - h)] + [
                (place * s, bottom - h)
            ]

        def horizontal(place, value):
            return [
                (place * s, bottom - 4 * h),
                ((place + value) * s, bottom - 4 * h),
                ((place + value) * s, bottom - 2 * h),
                (place * s, bottom - 2 * h),
            ]

        velocity = self.hull.linearVelocity
        speed = math.sqrt(velocity[0] * velocity[0] + velocity[1] * velocity[1])
        bars = [(speed, vertical(5, 0.02 * speed), (255, 255, 255))]
        own_wheels = self.wheels[: min(4, len(self.vehicle.wheels))]
        for place, wheel in enumerate(own_wheels):
            color = (0, 0, 255) if place < 2 else (51, 0, 255)
            bars.append((wheel.omega, vertical(7 + place, 0.01 * wheel.omega), color))
        steering = self.wheels[0].joint.angle
        bars.append((steering, horizontal(20, -10.0 * steering), (0, 255, 0)))
        yaw_rate = self.hull.angularVelocity
        bars.append((yaw_rate, horizontal(30, -0.8 * yaw_rate), (255, 0, 0)))
        for value, points, color in bars:
            if abs(value) > 1e-4:
                pygame.draw.polygon(surface, points=points, color=color)


def vehicle_fixtures(vehicle: Vehicle) -> tuple[list, list[list], dict]:
    """Box2D fixture definitions of a vehicle: the hull's, each trailer body's (in the hull's frame,
    behind the hitch) and one per wheel size. Built once per vehicle and environment, because pybox2d
    never frees a definition's shape."""

    def polygons(parts, offset=(0.0, 0.0), **filtering):
        return [
            fixtureDef(
                shape=polygonShape(
                    vertices=[
                        ((px + offset[0]) * UNIT, (py + offset[1]) * UNIT)
                        for px, py in part.vertices
                    ]
                ),
                density=part.density,
                **filtering,
            )
            for part in parts
        ]

    def wheel(radius: float, half_width: float):
        r, w = radius, half_width
        return fixtureDef(
            shape=polygonShape(
                vertices=[(-w * UNIT, r * UNIT), (w * UNIT, r * UNIT)]
                + [(w * UNIT, -r * UNIT), (-w * UNIT, -r * UNIT)]
            ),
            density=WHEEL_DENSITY,
            categoryBits=WHEEL_CATEGORY,
            maskBits=GROUND_CATEGORY,
            restitution=0.0,
        )

    parts = () if vehicle.trailer is None else vehicle.trailer.bodies
    trailer = [
        polygons(
            part.polygons, vehicle.hitch, categoryBits=TRAILER_CATEGORY, maskBits=GROUND_CATEGORY
        )
        for part in parts
    ]
    sizes = {(spec.radius, spec.half_width) for spec in vehicle.all_wheels}
    return polygons(vehicle.hull), trailer, {size: wheel(*size) for size in sizes}


def to_screen(view, x: float, y: float) -> tuple[float, float]:
    """A world point in window pixels (before the vertical flip)."""
    cos_a, sin_a, zoom, shift_x, shift_y = view
    return (
        (cos_a * x - sin_a * y) * zoom + shift_x,
        (sin_a * x + cos_a * y) * zoom + shift_y,
    )


def grass_polygons() -> np.ndarray:
    """CarRacing's checkerboard of grass patches."""
    patches = []
    for i in range(-20, 20, 2):
        for j in range(-20, 20, 2):
            patches.append(
                [
                    (GRASS_DIM * i + GRASS_DIM, GRASS_DIM * j + 0),
                    (GRASS_DIM * i + 0, GRASS_DIM * j + 0),
                    (GRASS_DIM * i + 0, GRASS_DIM * j + GRASS_DIM),
                    (GRASS_DIM * i + GRASS_DIM, GRASS_DIM * j + GRASS_DIM),
                ]
            )
    return np.array(patches, dtype=np.float64)


GRASS_POLYGONS = grass_polygons()
GRASS_POLYGONS.flags.writeable = False
