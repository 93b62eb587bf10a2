"""The return's gradient with respect to the context equals central finite differences, and every input
it cannot differentiate is refused in one line before anything runs.

The finite differences step each feature by ±0.3 % of its value (at least 3e-5) in float32, under the
same fixed key as the gradient. Measured for the cases below (key 0), with XLA's default flags and with
the suite's: the largest relative difference between gradient and finite difference is 8.7e-4 on
CartPole (masspole) and 3.2e-4 on Pendulum (max_torque); at ±1 % and ±0.1 % steps it stays within
7.4e-3 (the float32 rounding of the return grows as the step shrinks, the curvature as it grows). The
tolerance, 1e-2 of the gradient (or of 1e-2 where the gradient is smaller), clears those at the test's
±0.3 % by more than ten times. Over keys 0 to 7 the same steps differ by up to 3.5e-2 on CartPole
(key 2, tau): there the ±0.3 % step moves the pole's fall across a step boundary (the return passes
8.0), a kink of the return, which is why the key is fixed. Without the terminating step's fraction
CartPole's return is an integer and its gradient zero, which the last assertion of the first test
refuses.

The other classic-control environments, measured with the suite's flags (key 0, ±0.3 %): MountainCar
differs by up to 5.8e-4 (max_velocity_start), within the same 1e-2. Acrobot differs by up to 1.4e-2
(INITIAL_ANGLE_UPPER: its links amplify a change of the start several times over 30 steps, so the
step's curvature shows) and MountainCarContinuous by up to 7.8e-3 (max_position_start: its return of
about 98, the goal's +100 counted in full, rounds to 7.6e-6, large against the step of a start
feature); their tolerance is 5e-2. Over keys 0 to 7 MountainCar stays within 1.5e-2; Acrobot reaches
0.12 at key 5 and MountainCarContinuous 5.2e-2 at key 3, and 0.71 at key 7, where the car does not
reach the goal within the horizon (the step moves the goal across its end): kinks again.

On MJX (``MJX_CASES``; the rollout's jvp is compiled once and called per feature, as
``gradient_and_differences`` says): PointMass differs by up to 1.2e-3 (wind_y); Reacher's masses barely act (the joints' armature outweighs the links' inertia), so their
effect on its return is near float32's resolution even at ±3 % steps, and its floor is 0.1: the
largest difference is 2.9e-3 of that floor (mass_body1), 3.3e-4 of the gradient on actuator_strength.
The MJX tolerance, 3e-2, clears both by ten times. On one core and a cold compilation cache each MJX
test takes 22 to 25 s, most of it tracing and compiling the jvp (the classic cases 1 to 3 s each).
"""

import dataclasses
import math
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import contextrl as crl
from contextrl.context import ContextBase
from contextrl.core.env import Env
from contextrl.core.spaces import Box

pytestmark = pytest.mark.quick

KEY = jax.random.key(0)
RELATIVE_STEP = 3e-3
TOLERANCE = 1e-2
PENDULUM_GAINS = jnp.array([0.0, -3.0, -1.0])
COARSE_TOLERANCE = 5e-2
MJX_RELATIVE_STEP = 3e-2
MJX_TOLERANCE = 3e-2
REACHER_FLOOR = 0.1


def push_right(obs):
    return 1


def hold_up(obs):
    """A smooth policy that holds the pendulum up under weak gravity (it never reaches the clip)."""
    return 2.0 * jnp.tanh(PENDULUM_GAINS @ obs)[None]


def torque_back(obs):
    """Acrobot's torque −1 throughout: from a start up to 2 rad the tip swings over the goal line."""
    return 0


def drive_right(obs):
    """MountainCar's push right throughout: with a stronger push than the hill's pull it drives up."""
    return 2


def lean_forward(obs):
    """A smooth push that grows with the car's speed (never clipped, the speed never reaches its clip)."""
    return 0.6 + 5.0 * obs[1:2]


class Case(NamedTuple):
    """A rollout to differentiate and how closely the gradient must match central differences:
    within ``tolerance`` of it, or of ``floor`` where the gradient is smaller."""

    policy: Callable
    horizon: int
    values: dict
    tolerance: float = TOLERANCE
    floor: float = 1e-2
    relative_step: float = RELATIVE_STEP
    options: dict = {}  # make options


CASES = {
    "CartPole": Case(push_right, 50, {}),
    "Pendulum": Case(hold_up, 50, {"g": 2.0, "initial_angle_max": 1.0}),
    "Acrobot": Case(
        torque_back, 30, {"INITIAL_ANGLE_UPPER": 2.0, "torque_noise_max": 0.5}, COARSE_TOLERANCE
    ),
    "MountainCar": Case(drive_right, 100, {"force": 0.004}),
    "MountainCarContinuous": Case(
        lean_forward,
        150,
        {"power": 0.003, "max_speed": 0.2, "min_velocity_start": -0.05, "max_velocity_start": 0.05},
        COARSE_TOLERANCE,
    ),
}


def central_difference(return_of, values, name, relative_step=RELATIVE_STEP):
    value = float(values[name])
    step = relative_step * max(abs(value), 1e-2)
    up, down = jnp.float32(value + step), jnp.float32(value - step)
    higher = float(return_of({**values, name: up}))
    lower = float(return_of({**values, name: down}))
    return (higher - lower) / (float(up) - float(down))


@pytest.mark.parametrize("env_id", sorted(CASES))
def test_gradient_equals_central_differences(env_id):
    case = CASES[env_id]
    env = crl.make(env_id)
    context = env.context(**case.values)
    gradient = crl.context_gradient(env, case.policy, context, key=KEY, horizon=case.horizon)
    floats = [n for n, f in env.context_space.features.items() if f.kind == "float"]
    assert list(gradient) == floats
    return_of, at_context = crl.return_of_context(
        env, case.policy, context, key=KEY, horizon=case.horizon
    )
    return_of = jax.jit(return_of)
    differences = {
        name: central_difference(return_of, at_context, name, case.relative_step)
        for name in gradient
    }
    assert_agrees(gradient, differences, case)
    assert sum(abs(d) > 0.1 for d in gradient.values()) >= 5  # the check is not of zeros


def assert_agrees(gradient, differences, case):
    for name, derivative in gradient.items():
        difference = differences[name]
        assert abs(difference - derivative) <= case.tolerance * max(abs(derivative), case.floor), (
            name,
            derivative,
            difference,
        )


def reach(obs):
    """Reacher's torques, smooth in the fingertip's offset from the target and the joints' speeds."""
    return 0.5 * jnp.tanh(3.0 * obs[8:10] - 0.2 * obs[6:8])


def home(obs):
    """PointMass's push toward the origin, damped by the ball's velocity."""
    return 0.5 * jnp.tanh(-10.0 * obs[:2] - obs[2:4])


# MJX compiles slowly on CPU: each family's smallest model, over a short horizon
MJX_CASES = {
    "BraxReacher": Case(reach, 20, {}, MJX_TOLERANCE, REACHER_FLOOR, MJX_RELATIVE_STEP),
    "DmcPointMass": Case(
        home,
        20,
        {
            "starting_x": 0.03,
            "starting_y": -0.01,
            "start_spread": 0.02,
            "density": 1.0,
            "viscosity": 0.1,
            "wind_x": 0.5,
            "wind_y": 0.3,
        },
        MJX_TOLERANCE,
        options={"backend": "mjx"},
    ),
}


def gradient_and_differences(return_of, values, relative_step):
    """The return's derivative along each feature and its central difference, from one compiled
    program (an MJX rollout traces and compiles for tens of seconds): the rollout's jvp, called with
    each feature's tangent at the context (what ``jax.jacfwd`` in ``context_gradient`` batches) and
    with none at the context stepped up and down along each feature, as ``central_difference`` steps."""
    names = list(values)
    centre = np.array([float(values[name]) for name in names], np.float32)
    basis = np.eye(len(names), dtype=np.float32)
    jvp = jax.jit(
        lambda point, tangent: jax.jvp(
            lambda x: return_of(dict(zip(names, x, strict=True))), (point,), (tangent,)
        )
    )
    gradient, differences = {}, {}
    for axis, name in enumerate(names):
        gradient[name] = float(jvp(centre, basis[axis])[1])
        step = relative_step * max(abs(float(centre[axis])), 1e-2)
        up, down = (centre + sign * step * basis[axis] for sign in (1, -1))
        higher, lower = (float(jvp(point, 0 * basis[axis])[0]) for point in (up, down))
        differences[name] = (higher - lower) / float(up[axis] - down[axis])
    return gradient, differences


@pytest.mark.slow  # an MJX rollout compiles for tens of seconds on the CPU
@pytest.mark.parametrize("env_id", sorted(MJX_CASES))
def test_mjx_gradient_equals_central_differences(env_id):
    pytest.importorskip("mujoco.mjx")
    pytest.importorskip("brax" if env_id.startswith("Brax") else "dm_control")
    case = MJX_CASES[env_id]
    env = crl.make(env_id, **case.options)
    assert env.differentiable
    return_of, at_context = crl.return_of_context(
        env, case.policy, env.context(**case.values), key=KEY, horizon=case.horizon
    )
    gradient, differences = gradient_and_differences(return_of, at_context, case.relative_step)
    assert_agrees(gradient, differences, case)
    assert sum(abs(d) > 0.01 for d in gradient.values()) >= 2  # the check is not of zeros


def test_cartpole_counts_the_terminating_step_by_its_fraction():
    """The return lies in (k − 1, k] where the episode terminates in step k, and is not an integer:
    the terminating step counts by the part of it spent inside the limits."""
    env = crl.make("CartPole")
    context = env.default_context()
    return_of, values = crl.return_of_context(env, push_right, context, key=KEY, horizon=50)
    smooth = float(return_of(values))
    state, ts = env.reset(jax.random.split(KEY)[0], context)
    steps = 0
    while not bool(ts.terminated):
        state, ts = env.advance(KEY, state, 1, context)
        steps += 1
    assert steps - 1 < smooth < steps
    only_gravity = crl.context_gradient(
        env, push_right, context, key=KEY, horizon=50, features=["gravity", "pole_length"]
    )
    assert list(only_gravity) == ["gravity", "length"]


@crl.context_type
class SwitchContext(ContextBase):
    gain: float = crl.feature(1.0, 0.0, 2.0, doc="scale of the push")
    mode: int = crl.feature("soft", 0, 0, kind="categorical", choices=("soft", "hard"))


@dataclasses.dataclass(frozen=True)
class Switch(Env):
    """A one-variable system with a categorical feature, declared differentiable."""

    context_type = SwitchContext
    default_max_steps = 10
    differentiable = True

    @property
    def action_space(self):
        return Box(np.array([-1.0]), np.array([1.0]))

    @property
    def base_observation_space(self):
        return Box(np.array([-10.0]), np.array([10.0]))

    def init(self, key, context):
        return jnp.zeros(1)

    def transition(self, key, state, action, context):
        return state + context.gain * action, -jnp.sum(state**2), jnp.zeros((), bool)

    def observe(self, state, context):
        return state


def refusal(env, policy=push_right, context=None, **options):
    options = {"key": KEY, "horizon": 10, **options}
    context = env.default_context() if context is None else context
    with pytest.raises((ValueError, TypeError)) as caught:
        crl.context_gradient(env, policy, context, **options)
    message = str(caught.value)
    assert "\n" not in message
    return message


CLASSIC_CONTROL = ("Acrobot", "CartPole", "MountainCar", "MountainCarContinuous", "Pendulum")


def test_host_environments_are_refused():
    message = refusal(crl.make("LunarLander"))
    assert "LunarLander is a host environment" in message
    assert "differentiable environments: Acrobot, CartPole, " in message
    assert all(name in message for name in CLASSIC_CONTROL)


def test_jax_environments_not_declared_differentiable_are_refused():
    message = refusal(crl.make("Platformer"), policy=lambda obs: 0)
    assert "Platformer's dynamics are not declared differentiable" in message
    assert all(name in message for name in CLASSIC_CONTROL)


@pytest.mark.parametrize(
    ("env_id", "options"), [("BraxAnt", {}), ("DmcWalker", {"backend": "mjx"})]
)
def test_mjx_tasks_with_contacts_are_refused(env_id, options):
    pytest.importorskip("mujoco.mjx")
    pytest.importorskip("brax" if env_id.startswith("Brax") else "dm_control")
    env = crl.make(env_id, **options)
    message = refusal(env, policy=lambda obs: jnp.zeros(env.action_space.shape))
    assert f"{env.name}'s dynamics are not declared differentiable" in message


def test_a_categorical_feature_is_refused():
    message = refusal(Switch(), policy=lambda obs: obs, features=["gain", "mode"])
    assert "Switch's feature mode is categorical, which has no gradient" in message
    assert "float features: ['gain']" in message
    assert list(
        crl.context_gradient(
            Switch(), lambda obs: obs, Switch().default_context(), key=KEY, horizon=3
        )
    ) == ["gain"]


def test_bad_inputs_are_refused_before_anything_runs():
    env = crl.make("CartPole")
    assert "length: value nan is not finite" in refusal(env, context={"length": math.nan})
    assert "gravity: value inf is not finite" in refusal(env, context={"gravity": math.inf})
    batch = crl.sample(env, {"length": crl.Uniform(0.4, 0.6)}, n=3, key=KEY)
    assert "one context of CartPole, got a batch of shape (3,)" in refusal(env, context=batch)
    assert "key must be one JAX key" in refusal(env, key=0)
    assert "key must be one JAX key" in refusal(env, key=jax.random.split(KEY, 2))
    assert "horizon must be in [1, 500]" in refusal(env, horizon=501)
    assert "horizon must be an integer" in refusal(env, horizon=2.5)
    assert "unknown context feature 'mass'" in refusal(env, features=["mass"])
    assert "feature length given twice" in refusal(env, features=["length", "pole_length"])
    assert "policy must be a function" in refusal(env, policy=1)
    assert "an action is an integer in [0, 2)" in refusal(env, policy=lambda obs: obs)
