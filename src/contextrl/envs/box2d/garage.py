"""VehicleRacing's garage: every vehicle a small declarative definition, built into Box2D by the env.

A vehicle is a hull (convex polygons with densities), wheels (position, size, whether they steer, are
driven, and their share of the brake command), the drivetrain constants of gymnasium's car model (engine
power, wheel moment of inertia, friction limit) and optionally a trailer. A trailer is a chain of bodies,
each hitched to the one before it (the first to the vehicle's hitch point) by a revolute joint with an
angle limit; its wheels roll freely and brake with their own share.

Coordinates are in gymnasium's car units (``UNIT`` = 0.02 m, gymnasium's ``SIZE``), y pointing forward.
Trailer coordinates are relative to the vehicle's hitch point. The drivetrain constants are given in the
same units as gymnasium's ``car_dynamics`` (a number times ``UNIT²``).

The garage holds CARL's 29 vehicles in CARL's order (so CARL's integer ``VEHICLE_ID`` names the same
vehicle): race car, street car and bus, each without, with a small and with a large trailer, each in
rear-, front- and all-wheel drive; then the tuk-tuk and the tuk-tuk with a small trailer. The race car in
rear-wheel drive without a trailer is gymnasium's ``CarRacing`` car, value for value.
"""

from __future__ import annotations

import dataclasses

UNIT = 0.02  # metres per car unit (gymnasium's SIZE)
Points = tuple[tuple[float, float], ...]


@dataclasses.dataclass(frozen=True)
class Polygon:
    """One convex fixture (at most 8 vertices) and its density."""

    vertices: Points
    density: float = 1.0


@dataclasses.dataclass(frozen=True)
class Wheel:
    """A wheel: centre, radius and half width (car units); steered, driven, share of the brake."""

    x: float
    y: float
    radius: float = 27.0
    half_width: float = 14.0
    steered: bool = False
    driven: bool = False
    brake_share: float = 1.0
    steer_limit: float = (
        0.4  # joint angle limit (rad); unsteered wheels are held straight by the motor
    )


@dataclasses.dataclass(frozen=True)
class TrailerBody:
    """A trailer body hitched to the body before it at ``hitch`` (its own frame = the hitch frame)."""

    polygons: tuple[Polygon, ...]
    wheels: tuple[Wheel, ...]
    hitch: tuple[float, float]
    angle_limit: float
    color: tuple[float, float, float]


@dataclasses.dataclass(frozen=True)
class Trailer:
    name: str
    bodies: tuple[TrailerBody, ...]


@dataclasses.dataclass(frozen=True)
class Vehicle:
    """A complete vehicle definition; ``mass`` and friends are computed by Box2D from the polygons."""

    name: str
    hull: tuple[Polygon, ...]
    color: tuple[float, float, float]
    wheels: tuple[Wheel, ...]
    engine_power: float
    wheel_moment_of_inertia: float
    friction_limit: float
    hitch: tuple[float, float]  # where a trailer is hitched on the hull
    trailer: Trailer | None = None

    @property
    def all_wheels(self) -> tuple[Wheel, ...]:
        """The vehicle's wheels, then each trailer body's."""
        bodies = () if self.trailer is None else self.trailer.bodies
        return self.wheels + tuple(wheel for body in bodies for wheel in body.wheels)


def box(left: float, bottom: float, right: float, top: float, density: float = 1.0) -> Polygon:
    return Polygon(((left, top), (right, top), (right, bottom), (left, bottom)), density)


def wheels(
    front: tuple[float, float],
    rear: tuple[float, float],
    drive: str,
    half_width: float = 14.0,
    brake_shares: tuple[float, float] = (1.0, 1.0),
    steer_limit: float = 0.4,
) -> tuple[Wheel, ...]:
    """Four wheels: the front pair steers; ``drive`` ("rwd", "fwd", "awd") picks the driven pairs."""
    (front_x, front_y), (rear_x, rear_y) = front, rear
    front_wheel = dict(
        half_width=half_width,
        steered=True,
        driven=drive != "rwd",
        brake_share=brake_shares[0],
        steer_limit=steer_limit,
    )
    rear_wheel = dict(half_width=half_width, driven=drive != "fwd", brake_share=brake_shares[1])
    return (
        Wheel(-front_x, front_y, **front_wheel),
        Wheel(+front_x, front_y, **front_wheel),
        Wheel(-rear_x, rear_y, **rear_wheel),
        Wheel(+rear_x, rear_y, **rear_wheel),
    )


TRAILER_BLUE = (0.0, 0.0, 0.8)
DOLLY_CYAN = (0.0, 0.8, 0.8)

# A two-wheeled box on a drawbar, hitched at the vehicle's rear.
SMALL_TRAILER = Trailer(
    "small_trailer",
    (
        TrailerBody(
            polygons=(
                Polygon(((-10, 0), (10, 0), (60, -40), (60, -180), (-60, -180), (-60, -40)), 0.75),
            ),
            wheels=(
                Wheel(-65, -110, half_width=12, brake_share=0.7),
                Wheel(65, -110, half_width=12, brake_share=0.7),
            ),
            hitch=(0.0, 0.0),
            angle_limit=0.9,
            color=TRAILER_BLUE,
        ),
    ),
)

# A full trailer: a two-wheeled dolly on a drawbar, and a long box pivoting on the dolly's axle.
LARGE_TRAILER = Trailer(
    "large_trailer",
    (
        TrailerBody(
            polygons=(box(-8, -40, 8, 0, 0.5), box(-60, -70, 60, -40, 0.5)),
            wheels=(
                Wheel(-65, -55, half_width=12, brake_share=0.8),
                Wheel(65, -55, half_width=12, brake_share=0.8),
            ),
            hitch=(0.0, 0.0),
            angle_limit=0.9,
            color=DOLLY_CYAN,
        ),
        TrailerBody(
            polygons=(box(-20, -75, 20, -45, 2.0), box(-60, -420, 60, -75, 0.5)),
            wheels=(
                Wheel(-65, -390, half_width=12, brake_share=0.8),
                Wheel(65, -390, half_width=12, brake_share=0.8),
            ),
            hitch=(0.0, -55.0),
            angle_limit=0.5,
            color=TRAILER_BLUE,
        ),
    ),
)


def race_car(drive: str) -> Vehicle:
    """gymnasium's CarRacing car (with ``drive="rwd"`` exactly)."""
    return Vehicle(
        name="race_car",
        hull=(
            Polygon(((-60, 130), (60, 130), (60, 110), (-60, 110))),
            Polygon(((-15, 120), (15, 120), (20, 20), (-20, 20))),
            Polygon(
                (
                    (25, 20),
                    (50, -10),
                    (50, -40),
                    (20, -90),
                    (-20, -90),
                    (-50, -40),
                    (-50, -10),
                    (-25, 20),
                )
            ),
            Polygon(((-50, -120), (50, -120), (50, -90), (-50, -90))),
        ),
        color=(0.8, 0.0, 0.0),
        wheels=wheels((55, 80), (55, -82), drive),
        engine_power=100_000_000 * UNIT * UNIT,
        wheel_moment_of_inertia=4_000 * UNIT * UNIT,
        friction_limit=1_000_000 * UNIT * UNIT,
        hitch=(0.0, -120.0),
    )


def street_car(drive: str) -> Vehicle:
    """A hatchback: a tenth of the race car's power, less grip, brakes biased 40/60 front/rear."""
    return Vehicle(
        name="street_car",
        hull=(
            Polygon(((-40, 180), (40, 180), (55, 160), (-55, 160))),
            box(-55, -60, 55, 160),
            Polygon(((55, -40), (-55, -40), (-65, -75), (65, -75))),
        ),
        color=(1.0, 0.31, 0.0),
        wheels=wheels((60, 140), (60, -30), drive, half_width=10, brake_shares=(0.4, 0.6)),
        engine_power=10_000_000 * UNIT * UNIT,
        wheel_moment_of_inertia=1_000 * UNIT * UNIT,
        friction_limit=750_000 * UNIT * UNIT,
        hitch=(0.0, -75.0),
    )


def bus(drive: str) -> Vehicle:
    """A 14 m bus: half the race car's power, heavy wheels, more grip, wider steering."""
    return Vehicle(
        name="bus",
        hull=(
            Polygon(((-70, 700), (70, 700), (80, 550), (-80, 550)), 0.66),
            box(-90, -60, 90, 550, 0.2),
        ),
        color=(1.0, 0.85, 0.0),
        wheels=wheels(
            (85, 650), (85, -30), drive, half_width=20, brake_shares=(0.4, 0.6), steer_limit=0.7
        ),
        engine_power=50_000_000 * UNIT * UNIT,
        wheel_moment_of_inertia=6_000 * UNIT * UNIT,
        friction_limit=1_250_000 * UNIT * UNIT,
        hitch=(0.0, -60.0),
    )


def tuk_tuk() -> Vehicle:
    """A three-wheeler: one steered front wheel, two driven rear wheels, a quarter of the power."""
    return Vehicle(
        name="tuk_tuk",
        hull=(
            Polygon(((-15, 70), (15, 70), (20, 50), (-20, 50))),
            Polygon(((-65, -120), (65, -120), (45, 50), (-45, 50))),
        ),
        color=(0.2, 0.5, 1.0),
        wheels=(
            Wheel(0, 80, radius=30, half_width=10, steered=True, steer_limit=0.9),
            Wheel(-70, -82, radius=30, half_width=10, driven=True, brake_share=0.6),
            Wheel(70, -82, radius=30, half_width=10, driven=True, brake_share=0.6),
        ),
        engine_power=25_000_000 * UNIT * UNIT,
        wheel_moment_of_inertia=2_000 * UNIT * UNIT,
        friction_limit=1_000_000 * UNIT * UNIT,
        hitch=(0.0, -120.0),
    )


def with_trailer(vehicle: Vehicle, trailer: Trailer | None, drive: str) -> Vehicle:
    name = f"{vehicle.name}_{drive}" + ("" if trailer is None else f"_{trailer.name}")
    return dataclasses.replace(vehicle, name=name, trailer=trailer)


def build_garage() -> tuple[Vehicle, ...]:
    """The 29 vehicles in CARL's order."""
    vehicles = []
    for make in (race_car, street_car, bus):
        for trailer in (None, SMALL_TRAILER, LARGE_TRAILER):
            for drive in ("rwd", "fwd", "awd"):
                vehicles.append(with_trailer(make(drive), trailer, drive))
    vehicles.append(with_trailer(tuk_tuk(), None, "rwd"))
    vehicles.append(with_trailer(tuk_tuk(), SMALL_TRAILER, "rwd"))
    return tuple(vehicles)


GARAGE: tuple[Vehicle, ...] = build_garage()
VEHICLE_NAMES: tuple[str, ...] = tuple(v.name for v in GARAGE)
