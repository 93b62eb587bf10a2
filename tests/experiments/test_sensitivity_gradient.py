"""The return's gradient beside the sensitivity sweep: a trained agent's policy, which may see the
context, differentiated through its context input, and which specs ask for it (a run's gradient
table is checked in test_registry.py's sensitivity run)."""

import jax
import jax.numpy as jnp
import pytest

import contextrl as crl
from contextrl.core.gradient import return_of_context
from contextrl.experiments.spec import parse_spec

WEIGHTS = jnp.array([0.3, -1.0, -0.5])


def context_policy(params, obs, ctx, key):
    """A smooth torque that reads the context (gravity) as a visible agent would."""
    return 2.0 * jnp.tanh(params @ obs + 0.05 * ctx.g)[None]


def blind_policy(params, obs, ctx, key):
    return context_policy(params, obs, jax.lax.stop_gradient(ctx), key)


def test_a_policy_that_sees_the_context_is_differentiated_through_it():
    env = crl.make("Pendulum")
    context = env.context_space.default().replace(g=6.0)
    options = {"key": jax.random.key(3), "horizon": 40, "features": ["g"], "params": WEIGHTS}
    seen = crl.context_gradient(env, context_policy, context, **options)["g"]
    blind = crl.context_gradient(env, blind_policy, context, **options)["g"]
    return_of, values = return_of_context(env, context_policy, context, **options)
    step = 1e-2
    difference = (return_of({"g": values["g"] + step}) - return_of({"g": values["g"] - step})) / (
        2 * step
    )
    assert seen == pytest.approx(float(difference), rel=2e-2)
    assert abs(seen - blind) > 0.05 * abs(seen)  # the context input's own part is not dropped


def test_no_gradient_where_the_dynamics_are_not_differentiable_or_it_is_switched_off():
    def spec(env, **options):
        return parse_spec({"protocol": "sensitivity", "env": env, **options})

    pendulum = crl.make("Pendulum")
    assert spec("Pendulum", features=["g", "l"]).gradient_features(pendulum) == ("g", "l")
    assert spec("Pendulum", gradient=False).gradient_features(pendulum) == ()
    lander = spec("LunarLander", agent="dqn")
    assert lander.gradient_features(lander.make_env()) == ()  # a host simulator
