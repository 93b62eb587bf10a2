"""The platformer as a contextual environment: :class:`Platformer` observes the world of :mod:`world`
(its tiles, or the pictures of :mod:`sprites`) and steps it with its physics."""

from __future__ import annotations

import dataclasses
from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.core.env import Env
from contextrl.core.spaces import Box, Discrete
from contextrl.envs.platformer.sprites import PIXELS, TILE_PIXELS, draw_view
from contextrl.envs.platformer.world import (
    ACTIONS,
    AGENT_FEATURES,
    BASE_HEIGHT,
    DEFEATED_WORDS,
    FLAG_FROM_END,
    OBS_CHANNELS,
    START_X,
    VIEW_COLS,
    VIEW_ROWS,
    PlatformerContext,
    PlatformerState,
    step_physics,
    tile_observation,
)


@dataclasses.dataclass(frozen=True)
class Platformer(Env):
    """Run right to the flag over gaps, steps and pipes, stomping or avoiding enemies (CARL's Mario).

    ``obs="tiles"`` (default): the tiles around the agent, one channel per kind (solid, hazard, enemy,
    flag) in a window of 12 columns × 10 rows, then the agent's speed, position in its tile and form.
    ``obs="pixels"``: an 84×84 RGB picture around the agent, flattened, values in [0, 1].
    """

    obs: str = "tiles"

    context_type = PlatformerContext
    default_max_steps = 2000
    observation_kinds: ClassVar[tuple[str, ...]] = ("tiles", "pixels")

    def __post_init__(self):
        if self.obs not in self.observation_kinds:
            raise ValueError(f"obs must be one of {list(self.observation_kinds)}, got {self.obs!r}")
        super().__post_init__()

    @property
    def action_space(self) -> Discrete:
        return Discrete(len(ACTIONS))

    @property
    def base_observation_space(self) -> Box:
        if self.obs == "pixels":
            size = PIXELS * PIXELS * 3
            return Box(np.zeros(size), np.ones(size))
        size = VIEW_COLS * VIEW_ROWS * len(OBS_CHANNELS)
        low = np.concatenate([np.zeros(size), [-1, -1, 0, 0, 0, 0, 0, 0]])
        return Box(low, np.ones(size + len(AGENT_FEATURES)))

    def init(self, key, context) -> PlatformerState:
        zero = jnp.zeros((), jnp.float32)
        false = jnp.zeros((), bool)
        return PlatformerState(
            x=jnp.float32(START_X),
            y=jnp.float32(BASE_HEIGHT),
            vx=zero,
            vy=zero,
            on_ground=jnp.ones((), bool),
            facing=jnp.ones((), jnp.int32),
            hits=jnp.zeros((), jnp.int32),
            invulnerable=jnp.zeros((), jnp.int32),
            clock=jnp.zeros((), jnp.int32),
            defeated=jnp.zeros((DEFEATED_WORDS,), jnp.uint32),
            fireball=jnp.zeros((3,), jnp.float32),
            fireball_steps=jnp.zeros((), jnp.int32),
            completed=false,
            died=false,
        )

    def transition(self, key, state: PlatformerState, action, context):
        return step_physics(state, action, context)

    def observe(self, state: PlatformerState, context) -> jax.Array:
        if self.obs == "pixels":
            view = PIXELS // TILE_PIXELS
            frame = draw_view(state, context, view, view, TILE_PIXELS)
            return frame.reshape(-1).astype(jnp.float32) / 255.0
        return tile_observation(state, context)

    def step_info(self, state: PlatformerState, context) -> dict:
        """Whether the level was completed or the agent died, and how far it came (tiles and fraction)."""
        distance = state.x - START_X
        flag = context.level_width - FLAG_FROM_END - START_X
        return {
            "completed": state.completed,
            "died": state.died,
            "distance": distance,
            "progress": jnp.clip(distance / flag, 0.0, 1.0),
        }
