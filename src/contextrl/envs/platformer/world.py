"""The platformer's world in JAX (the paper's Mario): its context, procedural levels and physics.

:mod:`env` makes it an environment and :mod:`sprites` draws it; both build on this module, which
imports neither.

The level is never stored. Every tile is a pure function of the context and its column: the level is cut
into segments of ``SEGMENT`` columns, and each segment's layout (gap, ground height, pipe, floating
bricks, enemy) is drawn from an integer hash of (``noise_seed``, ``level_index``, segment). So thousands
of copies each play their own level at no memory cost, a reset regenerates nothing, and the same
context gives the same level in every copy and every episode. A step hashes only the few segments around
the agent (:func:`level_window`) and reads every column it looks at from them. Enemies patrol their segment back and forth
as a closed-form function of the episode clock, so the state only records which were stomped.

Every level is playable: the widest gap, the highest step and the tallest pipe are computed from the
context's own jump physics (gravity, jump speed, run speed, inertia), for a jump from rest after the
shortest run-up the generator leaves before a gap, landing on the highest step it allows.

Units are tiles and steps. Actions are CARL's ten button combinations; speed (``run``) also throws a
fireball in the fire form. The reward is the progress to the right in tiles, plus a bonus at the flag
and minus a penalty for dying; ``info`` says whether the level was completed or the agent died, and how
far it came.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from contextrl.context.features import ContextBase, context_type, feature

# ---- the world ---------------------------------------------------------------------------------------
ROWS = 16  # tiles high
SEGMENT = 8  # columns per generated segment
BASE_HEIGHT = 2  # ground height of the start and of the lowest segments
MAX_GAP = 4  # widest gap: leaves a run-up of SEGMENT - MAX_GAP columns before the next gap
RUN_UP = SEGMENT - MAX_GAP
MAX_RISE = 3  # highest step between neighbouring segments
MAX_PIPE = 4  # tallest pipe
FLAT_END = 6  # the last columns before the end are flat ground, the flag stands on them
FLAG_FROM_END = 3  # the flag pole's column, counted from the level's end
MAX_WIDTH = 1000
START_AREA = SEGMENT // 2  # flat columns before the first generated segment
MAX_SEGMENTS = (MAX_WIDTH + START_AREA) // SEGMENT + 1
DEFEATED_WORDS = -(-MAX_SEGMENTS // 32)  # one bit per segment's enemy
CEILING_ROW = ROWS - 1  # the underground's brick ceiling

HASH_OFFSET = 116  # chosen so that the default level opens with a gap, an enemy and a pipe

# ---- the agent and its physics -----------------------------------------------------------------------
AGENT_WIDTH = 0.75
SMALL_HEIGHT = 0.9
LARGE_HEIGHT = 1.8
START_X = 1.0
MAX_SPEED = 0.9  # tiles per step, below one tile so nothing is ever stepped through
MAX_FALL = 1.0
DEFAULT_INERTIA = 0.89  # at this inertia the speed keeps 0.89 of itself per step, as in Mario
WALK_FRACTION = 0.5  # walking aims at half the running speed
INVULNERABLE_STEPS = 30  # after a hit that only shrinks the agent
STOMP_BOUNCE = 0.5  # fraction of the jump speed an agent bounces off a stomped enemy
JUMP_MARGIN = 0.6  # tiles kept between the highest jump and the highest step or pipe
GAP_MARGIN = 0.25  # tiles kept between the widest clearable gap and the widest generated one
AIR_STEPS_MARGIN = 1  # whole steps of airtime not counted on
REACH_STEPS = 32  # steps of running from rest the run-up is searched over

# ---- enemies and fireballs ---------------------------------------------------------------------------
ENEMY_SIZE = 0.9
ENEMY_SPEED = 0.06
FIREBALL_SPEED = 0.6
FIREBALL_SIZE = 0.4
FIREBALL_STEPS = 24

# ---- rewards -----------------------------------------------------------------------------------------
FLAG_BONUS = 20.0
DEATH_PENALTY = 20.0

# ---- tiles -------------------------------------------------------------------------------------------
EMPTY, GROUND, BRICK, PIPE, LAVA, FLAG = range(6)
TILE_NAMES = ("empty", "ground", "brick", "pipe", "lava", "flag")
OBS_CHANNELS = ("solid", "hazard", "enemy", "flag")
VIEW_BEHIND, VIEW_AHEAD = 3, 8  # columns seen behind and ahead of the agent's column
VIEW_BELOW, VIEW_ABOVE = 5, 4  # rows seen below and above the agent's row
VIEW_COLS = VIEW_BEHIND + 1 + VIEW_AHEAD
VIEW_ROWS = VIEW_BELOW + 1 + VIEW_ABOVE
AGENT_FEATURES = (
    "vx",
    "vy",
    "x_in_tile",
    "y_in_tile",
    "large",
    "fire",
    "invulnerable",
    "on_ground",
)

# ---- styles: per level_index, the probability of each segment kind and of an enemy per segment -------
STYLES = ("overworld", "underground", "castle", "sky")
STYLE_GAP = np.array([0.3, 0.2, 0.4, 0.5], np.float32)
STYLE_PIPE = np.array([0.2, 0.15, 0.3, 0.05], np.float32)
STYLE_PLATFORM = np.array([0.2, 0.35, 0.1, 0.3], np.float32)
STYLE_ENEMY = np.array([0.35, 0.5, 0.3, 0.2], np.float32)
UNDERGROUND, CASTLE, SKY = 1, 2, 3

# ---- the ten actions of CARL's Mario: (horizontal direction, run, jump, down) -------------------------
ACTIONS = (
    ("noop", 0, 0, 0, 0),
    ("down", 0, 0, 0, 1),
    ("right", 1, 0, 0, 0),
    ("right+run", 1, 1, 0, 0),
    ("right+jump", 1, 0, 1, 0),
    ("right+run+jump", 1, 1, 1, 0),
    ("left", -1, 0, 0, 0),
    ("left+jump", -1, 0, 1, 0),
    ("left+run+jump", -1, 1, 1, 0),
    ("jump", 0, 0, 1, 0),
)
ACTION_NAMES = tuple(a[0] for a in ACTIONS)
_ACTION_TABLE = np.array([a[1:] for a in ACTIONS], np.int32)


@context_type
class PlatformerContext(ContextBase):
    """Context features of the platformer: the level (style, layout, difficulty) and the physics."""

    level_width: int = feature(
        100,
        16,
        MAX_WIDTH,
        kind="int",
        unit="tiles",
        doc="columns from the start to the level's end; the flag stands 3 before it",
        affects=("dynamics", "observation"),
    )
    level_index: int = feature(
        "overworld",
        0,
        0,
        kind="categorical",
        choices=STYLES,
        doc="level style: tile mix and how often gaps, pipes, bricks and enemies appear",
        affects=("dynamics", "observation"),
    )
    noise_seed: int = feature(
        0,
        0,
        1_000_000,
        kind="int",
        doc="the level generator's seed: the layout",
        affects=("dynamics", "observation"),
        aliases=("noise",),
    )
    gap_width: float = feature(
        0.5,
        0.0,
        1.0,
        doc="widest gap as a fraction of the widest the context's jump can clear (at most 4 tiles)",
        affects=("dynamics", "observation"),
    )
    gap_frequency: float = feature(
        1.0,
        0.0,
        2.0,
        doc="scales the style's probability that a segment starts with a gap",
        affects=("dynamics", "observation"),
    )
    enemy_density: float = feature(
        1.0,
        0.0,
        2.0,
        doc="scales the style's probability that a segment holds an enemy",
        affects=("dynamics", "observation"),
    )
    platform_height_variation: float = feature(
        0.5,
        0.0,
        1.0,
        doc="highest step between segments as a fraction of what the jump can climb (at most 3)",
        affects=("dynamics", "observation"),
    )
    mario_state: int = feature(
        "small",
        0,
        0,
        kind="categorical",
        choices=("small", "large", "fire"),
        doc="the form the agent starts in: large survives one hit, fire also throws fireballs",
        affects=("dynamics", "observation"),
    )
    mario_inertia: float = feature(
        DEFAULT_INERTIA,
        0.5,
        1.5,
        doc="how slowly the horizontal speed changes: it keeps 1 - 0.11·0.89/inertia of itself a step",
        affects=("dynamics", "observation"),
    )
    gravity: float = feature(
        0.12,
        0.06,
        0.2,
        unit="tiles/step²",
        doc="downward acceleration (gaps, steps and pipes adapt to what the jump can clear)",
        affects=("dynamics", "observation"),
    )
    jump_speed: float = feature(
        1.0,
        0.8,
        1.4,
        unit="tiles/step",
        doc="upward speed a jump starts with (the level adapts, as to gravity)",
        affects=("dynamics", "observation"),
    )
    run_speed: float = feature(
        0.5,
        0.2,
        0.8,
        unit="tiles/step",
        doc="top running speed, walking reaches half of it (gap widths adapt)",
        affects=("dynamics", "observation"),
    )


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class PlatformerState:
    """The agent (feet at ``y``, left side at ``x``), hits taken, one fireball and the stomped enemies."""

    x: jax.Array
    y: jax.Array
    vx: jax.Array
    vy: jax.Array
    on_ground: jax.Array
    facing: jax.Array  # +1 right, -1 left
    hits: jax.Array  # hits taken: each one drops the form mario_state by one (fire → large → small)
    invulnerable: jax.Array  # steps left
    clock: jax.Array  # steps since the episode started: enemies patrol by it
    defeated: jax.Array  # (DEFEATED_WORDS,) uint32, bit per segment: its enemy was stomped or burnt
    fireball: jax.Array  # (x, y, direction) of the fireball
    fireball_steps: jax.Array  # steps the fireball still flies (0: none)
    completed: jax.Array
    died: jax.Array


# ---- the level ---------------------------------------------------------------------------------------
def _mix(x):
    """A 32-bit integer hash (a murmur-style finaliser)."""
    x = (x ^ (x >> 16)) * jnp.uint32(0x7FEB352D)
    x = (x ^ (x >> 15)) * jnp.uint32(0x846CA68B)
    return x ^ (x >> 16)


def _uniforms(seed, style, segment):
    """Eight uniform numbers in (0, 1) per segment (resolution 1/256) from two hashes of
    (seed, style, segment): one byte each."""
    x = (
        jnp.asarray(seed).astype(jnp.uint32) * jnp.uint32(0x9E3779B1)
        + jnp.asarray(style).astype(jnp.uint32) * jnp.uint32(0x632BE5AB)
        + jnp.asarray(segment).astype(jnp.uint32) * jnp.uint32(0x85EBCA77)
        + jnp.uint32(HASH_OFFSET)
    )
    words = (_mix(x), _mix(x ^ jnp.uint32(0xC2B2AE3D)))
    return [
        ((words[i // 4] >> (8 * (i % 4))) & 255).astype(jnp.float32) / 256 + 1 / 512
        for i in range(8)
    ]


def speed_kept(context):
    """Fraction of the horizontal speed kept each step; the rest moves towards the pressed speed.

    At the default inertia this is Mario's 0.89; a larger inertia changes speed more slowly, a smaller
    one faster, and the top speed stays ``run_speed`` (CARL's bounds reach 1.5, where Mario's own rule,
    keeping ``inertia`` of the speed, would let it grow without end).
    """
    return 1.0 - (1.0 - DEFAULT_INERTIA) * DEFAULT_INERTIA / context.mario_inertia


def jump_reach(context) -> dict[str, jax.Array]:
    """What the context's physics can clear: highest climb, widest gap (tiles), and the headroom used.

    The agent jumps from rest after a run-up of ``RUN_UP`` tiles (minus its width and a margin): its
    speed follows the step's update ``vx ← keep·vx + (1 − keep)·run_speed`` on the ground and in the
    air, whose sum is closed-form. The airtime to come down onto a step of the highest rise follows the
    step's update ``vy ← vy − g, y ← y + vy`` exactly (``y_n = n·J − g·n(n+1)/2``), cut by the underground's ceiling.
    """
    g, jump = context.gravity, context.jump_speed
    keep, run = speed_kept(context), context.run_speed

    def travelled(steps):  # tiles covered in ``steps`` steps of running from rest
        return run * (steps - keep * (1.0 - keep**steps) / (1.0 - keep))

    # Steps still on the run-up: the powers of ``keep`` by products (``keep**steps`` for every step
    # would cost more than the rest of the step; this runs in every step, the level being no state).
    room = RUN_UP - AGENT_WIDTH - 0.5
    take_off, kept, lag = jnp.zeros_like(keep), jnp.ones_like(keep), keep / (1.0 - keep)
    for steps in range(1, REACH_STEPS + 1):
        kept = kept * keep
        take_off = take_off + (run * (steps - lag * (1.0 - kept)) <= room)

    launch = jump - g / 2  # the discrete arc is the continuous one launched at J − g/2
    apex = launch**2 / (2 * g)
    underground = context.level_index == UNDERGROUND
    lowest_ceiling = CEILING_ROW - (BASE_HEIGHT + MAX_RISE) - LARGE_HEIGHT
    reach = jnp.where(underground, jnp.minimum(apex, lowest_ceiling), apex)
    climb = jnp.floor(reach - JUMP_MARGIN)
    rise = jnp.clip(jnp.floor(context.platform_height_variation * climb), 0, MAX_RISE)

    # Time above the landing step: rising (to the apex, or to the ceiling where it cuts the arc), then
    # falling from there; a fall is never faster than free fall, so the speed cap only adds time.
    ceiling_cut = underground & (apex > lowest_ceiling)
    top = jnp.where(ceiling_cut, lowest_ceiling, apex)
    rising = jnp.where(
        ceiling_cut,
        (launch - jnp.sqrt(jnp.maximum(launch**2 - 2 * g * top, 0.0))) / g,
        launch / g,
    )
    falling = jnp.sqrt(2 * jnp.maximum(top - rise, 0.0) / g)
    airtime = jnp.floor(rising + falling) - AIR_STEPS_MARGIN
    # In the air the agent keeps accelerating as on the ground (holding right).
    clearable = travelled(take_off + airtime) - travelled(take_off) - AGENT_WIDTH - GAP_MARGIN
    widest_gap = jnp.clip(jnp.floor(context.gap_width * clearable), 0, MAX_GAP)
    tallest_pipe = jnp.clip(climb, 0, MAX_PIPE)
    return {"rise": rise, "gap": widest_gap, "pipe": tallest_pipe}


def segment_of(column):
    """The segment a column (int array) belongs to; segment 0 is the flat start area."""
    return jnp.floor_divide(column + START_AREA, SEGMENT)


def segments(context, reach, segment):
    """The layout of segments (an int array): gap width, ground height, pipe, bricks and enemy."""
    seed, style = context.noise_seed, context.level_index
    u = _uniforms(seed, style, segment).__getitem__

    inside = (segment >= 1) & (segment < MAX_SEGMENTS)
    p_gap = jnp.clip(jnp.asarray(STYLE_GAP)[style] * context.gap_frequency, 0.0, 0.9)
    p_pipe = jnp.asarray(STYLE_PIPE)[style]
    p_platform = jnp.asarray(STYLE_PLATFORM)[style]
    p_enemy = jnp.clip(jnp.asarray(STYLE_ENEMY)[style] * context.enemy_density, 0.0, 1.0)
    kind = u(0)
    gap = inside & (kind < p_gap) & (reach["gap"] >= 1)
    pipe = inside & ~gap & (kind >= p_gap) & (kind < p_gap + p_pipe) & (reach["pipe"] >= 1)
    bricks = inside & ~gap & ~pipe & (kind >= p_gap + p_pipe) & (kind < p_gap + p_pipe + p_platform)
    gap_width = jnp.where(gap, 1 + jnp.floor(u(1) * reach["gap"]), 0).astype(jnp.int32)
    height = BASE_HEIGHT + jnp.where(inside, jnp.floor(u(2) * (reach["rise"] + 1)), 0)
    pipe_height = jnp.where(pipe, 1 + jnp.floor(u(3) * reach["pipe"]), 0).astype(jnp.int32)
    pipe_at = 1 + (u(4) < 0.5).astype(jnp.int32)
    brick_row = height.astype(jnp.int32) + 3 + (u(7) < 0.5).astype(jnp.int32)
    last_full = segment_of(context.level_width - FLAT_END - SEGMENT)  # wholly before the flat end
    enemy = inside & (segment <= last_full) & (u(5) < p_enemy)
    start = segment * SEGMENT - START_AREA
    patrol_from = start + jnp.where(gap, gap_width, jnp.where(pipe, pipe_at + 2, 0))
    return {
        "gap": gap_width,
        "height": height.astype(jnp.int32),
        "pipe_height": pipe_height,
        "pipe_at": pipe_at,
        "bricks": bricks,
        "brick_row": brick_row,
        "enemy": enemy,
        "patrol_from": patrol_from.astype(jnp.float32),
        "patrol_span": (start + SEGMENT - ENEMY_SIZE - patrol_from).astype(jnp.float32),
        "phase": u(6),
    }


def enemy_x(layout, clock):
    """Where each segment's enemy is at ``clock``: walking back and forth over its patrol span."""
    span = jnp.maximum(layout["patrol_span"], 1e-3)
    walked = jnp.mod(layout["phase"] * 2 * span + ENEMY_SPEED * clock, 2 * span)
    return layout["patrol_from"] + jnp.where(walked < span, walked, 2 * span - walked)


def level_window(context, reach, first_column, width: int):
    """The layouts of the segments that columns ``first_column`` … ``first_column + width - 1`` span.

    A step looks at a few neighbouring columns (the collision patch, the observation window): their
    segments are hashed once here, and :func:`window_columns` gives each column its segment's layout
    by choosing among them, instead of hashing its segment again per column.
    Returns (first segment, layouts with one entry per segment).
    """
    first = segment_of(first_column)
    count = (width + SEGMENT - 2) // SEGMENT + 1  # the most segments ``width`` columns can span
    return first, segments(context, reach, first + jnp.arange(count))


def window_columns(window, columns):
    """Each column's segment layout (arrays shaped like ``columns``), chosen from ``window``'s."""
    first, layout = window
    index = segment_of(columns) - first
    count = layout["gap"].shape[-1]

    def choose(values):
        chosen = values[count - 1]
        for k in range(count - 2, -1, -1):
            chosen = jnp.where(index == k, values[k], chosen)
        return chosen

    return {name: choose(values) for name, values in layout.items()}


def column_profile(context, layout, columns):
    """Each column's vertical extents (int arrays shaped like ``columns``): ground, pipe, bricks,
    flag pole (empty extents are [0, 0)), and whether it is lava-floored or wall. ``layout`` holds each
    column's segment layout (from :func:`segments` or :func:`window_columns`)."""
    offset = columns - (segment_of(columns) * SEGMENT - START_AREA)
    width = context.level_width
    shaped = ~(columns >= width - FLAT_END)  # gaps, pipes and bricks only before the flat end
    style = context.level_index
    in_gap = (offset < layout["gap"]) & shaped
    height = layout["height"]
    pipe = (offset >= layout["pipe_at"]) & (offset < layout["pipe_at"] + 2) & shaped
    bricks = layout["bricks"] & shaped & (offset >= 2) & (offset < 6)
    flag = columns == width - FLAG_FROM_END
    wall = (columns >= width) | (columns < 0)
    zero = jnp.zeros_like(height)
    return {
        "ground_from": jnp.where(wall, -(1 << 20), jnp.where(style == SKY, height - 1, 0)),
        "ground_to": jnp.where(wall, 1 << 20, jnp.where(in_gap, zero, height)),
        "pipe_to": jnp.where(pipe, height + layout["pipe_height"], zero),
        "pipe_from": height,
        "brick_row": jnp.where(bricks, layout["brick_row"], -(1 << 20)),
        "flag_to": jnp.where(flag, height + 9, zero),
        "lava": (style == CASTLE) & in_gap,
        "ceiling": jnp.broadcast_to(style == UNDERGROUND, jnp.shape(height)),
    }


def tile_kinds(profile, rows):
    """Tile kinds at ``rows`` (int array broadcasting with the profile's columns)."""
    inside = (rows >= 0) & (rows < ROWS)
    ground = (rows >= profile["ground_from"]) & (rows < profile["ground_to"])
    pipe = (rows >= profile["pipe_from"]) & (rows < profile["pipe_to"])
    bricks = (rows == profile["brick_row"]) | (profile["ceiling"] & (rows == CEILING_ROW))
    lava = profile["lava"] & (rows == 0)
    flag = (rows >= profile["pipe_from"]) & (rows < profile["flag_to"])
    kind = jnp.where(flag & inside, FLAG, EMPTY)
    kind = jnp.where(lava, LAVA, kind)
    kind = jnp.where(bricks, BRICK, kind)
    kind = jnp.where(pipe & inside, PIPE, kind)
    return jnp.where(ground, GROUND, kind)


def window_tiles(context, window, columns, rows):
    """Tile kinds at (columns, rows) (broadcast int arrays), the columns inside ``window``.

    Each column's profile is computed once and kept apart from the per-tile tests by an optimisation
    barrier: fused into them, the compiler would compute it again for every tile.
    """
    profile = column_profile(context, window_columns(window, columns), columns)
    return tile_kinds(jax.lax.optimization_barrier(profile), rows)


def tiles(context, reach, columns, rows):
    """Tile kinds at (columns, rows) (broadcast int arrays), any columns: the level as a pure function."""
    layout = segments(context, reach, segment_of(columns))
    return tile_kinds(column_profile(context, layout, columns), rows)


def _solid(kind):
    return (kind == GROUND) | (kind == BRICK) | (kind == PIPE)


def level_map(context, width: int | None = None) -> np.ndarray:
    """The whole level as a (ROWS, width) array of tile kinds, row 0 at the bottom (for tests, pictures)."""
    width = int(context.level_width) if width is None else width
    reach = jump_reach(context)
    columns = jnp.arange(width)[None, :]
    rows = jnp.arange(ROWS)[:, None]
    return np.asarray(tiles(context, reach, columns, rows))


# ---- physics -----------------------------------------------------------------------------------------
def is_defeated(defeated, segment) -> jax.Array:
    """Whether the enemy of ``segment`` (int array) was defeated, from the bits ``defeated``."""
    segment = jnp.asarray(segment)
    words = jnp.arange(DEFEATED_WORDS)
    word = jnp.sum(
        jnp.where(words == (segment[..., None] >> 5), defeated, jnp.uint32(0)), axis=-1
    ).astype(jnp.uint32)
    return ((word >> (segment & 31).astype(jnp.uint32)) & 1) == 1


def _defeat(defeated, segment, hit):
    """``defeated`` with the bit of each ``segment`` (1-d) set where ``hit``."""
    bits = hit.astype(jnp.uint32) << (segment & 31).astype(jnp.uint32)
    # Added into their words (distinct segments: distinct bits) by a scatter, which the compiler keeps
    # apart: a select per word would repeat the whole stomp test for each of them.
    gained = jnp.zeros_like(defeated).at[segment >> 5].add(bits, mode="drop")
    return defeated | gained


def current_form(state, context) -> jax.Array:
    """0 small, 1 large, 2 fire: the context's ``mario_state`` less the hits taken."""
    return jnp.maximum(context.mario_state - state.hits, 0)


def agent_height(form):
    return jnp.where(form > 0, LARGE_HEIGHT, SMALL_HEIGHT)


def _box_hits_solid(patch, corner, x, y, height) -> jax.Array:
    """Whether the box [x, x + AGENT_WIDTH) × [y, y + height) overlaps a solid tile of ``patch``.

    ``patch`` holds the tile kinds around the agent, its lowest row and leftmost column at ``corner``.
    """
    column, row = jnp.floor(x).astype(jnp.int32), jnp.floor(y).astype(jnp.int32)
    columns = column + jnp.array([0, 1])
    rows = row + jnp.array([0, 1, 2])
    inside_x = columns.astype(jnp.float32) < x + AGENT_WIDTH
    inside_y = rows.astype(jnp.float32) < y + height
    kinds = patch[
        jnp.clip(rows - corner[1], 0, patch.shape[0] - 1)[:, None],
        jnp.clip(columns - corner[0], 0, patch.shape[1] - 1)[None, :],
    ]
    return jnp.any(_solid(kinds) & inside_x[None, :] & inside_y[:, None])


def step_physics(state: PlatformerState, action, context):
    """One step: input, gravity, moves with tile collisions, enemies, fireball, flag and death."""
    reach = jump_reach(context)
    direction, run, jump, down = (jnp.asarray(_ACTION_TABLE)[action, i] for i in range(4))
    ducking = (down == 1) & state.on_ground
    form = current_form(state, context)
    height = jnp.where(ducking, SMALL_HEIGHT, agent_height(form))

    # Horizontal: the speed moves towards the pressed direction's speed (zero without one), as fast as
    # the inertia lets it.
    target = context.run_speed * jnp.where(run == 1, 1.0, WALK_FRACTION) * direction
    target = jnp.where(ducking, 0.0, target)
    keep = speed_kept(context)
    vx = jnp.clip(keep * state.vx + (1.0 - keep) * target, -MAX_SPEED, MAX_SPEED)
    facing = jnp.where(direction != 0, direction, state.facing)

    # Vertical: a jump from the ground, then gravity (falls capped).
    vy = jnp.where((jump == 1) & state.on_ground, context.jump_speed, state.vy)
    vy = jnp.maximum(vy - context.gravity, -MAX_FALL)

    # Move along x, stop at a wall; then along y, land or bump the head. Moves are under one tile
    # across and 1.4 up, so the tiles they can touch are all in a patch of 4 × 7 around the agent.
    corner = jnp.stack([jnp.floor(state.x), jnp.floor(state.y)]).astype(jnp.int32) - jnp.array(
        [1, 2]
    )
    # The patch's columns and the enemies the agent can touch after the move (those of the segment
    # it stands in and the next) lie in three segments from the patch's first column on.
    near = level_window(context, reach, corner[0], 2 * SEGMENT)
    patch = window_tiles(
        context, near, corner[0] + jnp.arange(4)[None, :], corner[1] + jnp.arange(7)[:, None]
    )
    x = state.x + vx
    blocked_x = _box_hits_solid(patch, corner, x, state.y, height)
    wall_x = jnp.where(vx > 0, jnp.floor(x + AGENT_WIDTH) - AGENT_WIDTH - 1e-4, jnp.floor(x) + 1)
    x = jnp.where(blocked_x, wall_x, x)
    vx = jnp.where(blocked_x, 0.0, vx)
    y = state.y + vy
    blocked_y = _box_hits_solid(patch, corner, x, y, height)
    landed = blocked_y & (vy < 0)
    y = jnp.where(blocked_y, jnp.where(vy < 0, jnp.floor(y) + 1, jnp.floor(y + height) - height), y)
    vy = jnp.where(blocked_y, 0.0, vy)

    # Enemies of the segments the agent overlaps (two) and the fireball's (one), laid out at once.
    clock = state.clock + 1
    throw = (form == 2) & (run == 1) & (state.fireball_steps == 0)
    fireball = jnp.where(
        throw,
        jnp.stack([x + AGENT_WIDTH / 2, y + height * 0.5, facing.astype(jnp.float32)]),
        state.fireball,
    )
    fireball_steps = jnp.where(throw, FIREBALL_STEPS, state.fireball_steps)
    flying = fireball_steps > 0
    fx = fireball[0] + fireball[2] * FIREBALL_SPEED * flying
    fy = fireball[1]
    # Enemies stay inside their segment, so only those of the window can touch the agent.
    first, layout = near
    segment = first + jnp.arange(layout["enemy"].shape[-1])
    alive = layout["enemy"] & ~is_defeated(state.defeated, segment)
    ex = enemy_x(layout, clock.astype(jnp.float32))
    ey = layout["height"].astype(jnp.float32)

    # Stomp from above, otherwise get hurt.
    touch = (
        alive
        & (x < ex + ENEMY_SIZE)
        & (x + AGENT_WIDTH > ex)
        & (y < ey + ENEMY_SIZE)
        & (y + height > ey)
    )
    stomp = touch & (vy < 0) & (state.y >= ey + ENEMY_SIZE * 0.5)
    hurt = jnp.any(touch & ~stomp) & (state.invulnerable == 0)
    vy = jnp.where(jnp.any(stomp), STOMP_BOUNCE * context.jump_speed, vy)
    defeated = _defeat(state.defeated, segment, stomp)

    # The fire form throws a fireball with the run button; it flies straight and burns one enemy.
    fire_column = jnp.floor(fx).astype(jnp.int32)
    fire_window = level_window(context, reach, fire_column, 1)
    fire_segment = fire_window[0][None]
    fire_layout = fire_window[1]
    fire_ex = enemy_x(fire_layout, clock.astype(jnp.float32))[0]
    fire_ey = fire_layout["height"][0].astype(jnp.float32)
    burn = (
        flying
        & fire_layout["enemy"][0]
        & ~is_defeated(defeated, fire_segment)[0]
        & (jnp.abs(fx - (fire_ex + ENEMY_SIZE / 2)) < (ENEMY_SIZE + FIREBALL_SIZE) / 2)
        & (jnp.abs(fy - (fire_ey + ENEMY_SIZE / 2)) < (ENEMY_SIZE + FIREBALL_SIZE) / 2)
    )
    defeated = _defeat(defeated, fire_segment, burn[None])
    hits_wall = _solid(
        window_tiles(context, fire_window, fire_column, jnp.floor(fy).astype(jnp.int32))
    )
    fireball_steps = jnp.where(flying & ~burn & ~hits_wall, fireball_steps - 1, 0)
    fireball = jnp.stack([fx, fy, fireball[2]])

    # A hit shrinks a large or fire agent (fire → large → small) and kills a small one.
    hits = state.hits + hurt.astype(jnp.int32)
    invulnerable = jnp.where(hurt, INVULNERABLE_STEPS, jnp.maximum(state.invulnerable - 1, 0))
    lava = (context.level_index == CASTLE) & (y < 1.0)
    fell = y + agent_height(jnp.maximum(form - hurt, 0)) < 0
    over_lava = (patch[jnp.clip(-corner[1], 0, 6)] == LAVA) & (corner[1] <= 0)  # row 0 of the patch
    lava_below = over_lava[
        jnp.clip(jnp.floor(x).astype(jnp.int32) - corner[0] + jnp.array([0, 1]), 0, 3)
    ]
    covered = jnp.floor(x) + jnp.array([0.0, 1.0]) < x + AGENT_WIDTH
    died = (hurt & (form == 0)) | fell | (lava & jnp.any(lava_below & covered))
    flag = (context.level_width - FLAG_FROM_END).astype(jnp.float32) + 0.5
    completed = (x + AGENT_WIDTH >= flag) & ~died

    next_state = PlatformerState(
        x=x,
        y=y,
        vx=vx,
        vy=vy,
        on_ground=landed,
        facing=facing,
        hits=hits,
        invulnerable=invulnerable,
        clock=clock,
        defeated=defeated,
        fireball=fireball,
        fireball_steps=fireball_steps,
        completed=completed,
        died=died,
    )
    reward = (
        (x - state.x) + FLAG_BONUS * completed.astype(jnp.float32) - DEATH_PENALTY * died
    ).astype(jnp.float32)
    return next_state, reward, completed | died


def tile_observation(state: PlatformerState, context) -> jax.Array:
    """The window of tiles around the agent (solid, hazard, enemy, flag channels) and its own state."""
    reach = jump_reach(context)
    column = jnp.floor(state.x + AGENT_WIDTH / 2).astype(jnp.int32)
    row = jnp.floor(state.y).astype(jnp.int32)
    columns = column - VIEW_BEHIND + jnp.arange(VIEW_COLS)
    rows = row - VIEW_BELOW + jnp.arange(VIEW_ROWS)
    window = level_window(context, reach, columns[0], VIEW_COLS)
    # Materialised once: fused, each channel below would compute the tiles again.
    kinds = jax.lax.optimization_barrier(
        window_tiles(context, window, columns[None, :], rows[:, None])
    )
    first, layout = window
    segment = first + jnp.arange(layout["enemy"].shape[-1])
    alive = layout["enemy"] & ~is_defeated(state.defeated, segment)
    enemy_column = jnp.floor(enemy_x(layout, state.clock.astype(jnp.float32)) + ENEMY_SIZE / 2)
    enemy_row = layout["height"]
    enemy = jnp.any(
        alive[:, None, None]
        & (enemy_column.astype(jnp.int32)[:, None, None] == columns[None, None, :])
        & (enemy_row[:, None, None] == rows[None, :, None]),
        axis=0,
    )
    planes = [_solid(kinds), kinds == LAVA, enemy, kinds == FLAG]  # (channel, row, column) order
    own = jnp.stack(
        [
            state.vx / MAX_SPEED,
            jnp.clip(state.vy / MAX_FALL, -1.0, 1.0),
            state.x - jnp.floor(state.x),
            state.y - jnp.floor(state.y),
            (current_form(state, context) >= 1).astype(jnp.float32),
            (current_form(state, context) == 2).astype(jnp.float32),
            (state.invulnerable > 0).astype(jnp.float32),
            state.on_ground.astype(jnp.float32),
        ]
    )
    return jnp.concatenate([plane.reshape(-1).astype(jnp.float32) for plane in planes] + [own])
