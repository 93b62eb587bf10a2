"""The platformer's pictures, drawn in JAX from 8×8 sprites of our own: observations and full frames.

Each tile kind, the agent, the enemies and the fireball are 8×8 patterns of palette entries; a style
(``level_index``) picks the palette, so overworld, underground, castle and sky look different. A view is a
window of tiles following the agent, ``tile_pixels`` pixels per tile.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from contextrl.envs.platformer import world

PIXELS = 84  # the pixel observation is PIXELS × PIXELS RGB
TILE_PIXELS = 6  # … showing 14 × 14 tiles
SPRITE = 8


def _pattern(rows: list[str]) -> np.ndarray:
    """An 8×8 pattern from text: '.' transparent, digits palette entries."""
    return np.array([[-1 if c == "." else int(c) for c in row] for row in rows], np.int32)


TILE_PATTERNS = np.stack(
    [
        _pattern(["00000000"] * 8),  # empty: background
        _pattern(
            [
                "22222222",
                "01000100",
                "01000100",
                "11111111",
                "00010001",
                "00010001",
                "11111111",
                "01000100",
            ]
        ),  # ground
        _pattern(
            [
                "22222221",
                "20000001",
                "20000001",
                "11111111",
                "00012000",
                "00012000",
                "00012000",
                "11111111",
            ]
        ),  # brick
        _pattern(
            [
                "12200221",
                "12200221",
                "12200221",
                "12200221",
                "12200221",
                "12200221",
                "12200221",
                "12200221",
            ]
        ),  # pipe
        _pattern(
            [
                "22002200",
                "00220022",
                "11111111",
                "11011101",
                "11111111",
                "10111011",
                "11111111",
                "11111111",
            ]
        ),  # lava
        _pattern(["00022000"] * 8),  # flag pole (2: the pole)
    ]
)

# Palettes per style: background, then three colours for each solid or hazard kind.
BACKGROUND = np.array([[92, 148, 252], [0, 0, 0], [40, 24, 24], [160, 210, 255]], np.uint8)
TILE_COLORS = np.array(
    [
        # ground, brick, pipe, lava (colour 0, 1, 2 of each)
        [
            [[200, 76, 12], [112, 40, 0], [252, 188, 176]],
            [[200, 76, 12], [0, 0, 0], [252, 160, 68]],
            [[0, 168, 0], [0, 80, 0], [128, 208, 16]],
            [[252, 116, 96], [200, 40, 0], [252, 216, 168]],
        ],
        [
            [[0, 88, 136], [0, 40, 72], [60, 188, 252]],
            [[0, 120, 168], [0, 0, 0], [60, 188, 252]],
            [[0, 168, 0], [0, 80, 0], [128, 208, 16]],
            [[252, 116, 96], [200, 40, 0], [252, 216, 168]],
        ],
        [
            [[120, 120, 120], [60, 60, 60], [188, 188, 188]],
            [[120, 120, 120], [40, 40, 40], [188, 188, 188]],
            [[100, 100, 100], [50, 50, 50], [160, 160, 160]],
            [[252, 80, 0], [180, 20, 0], [252, 200, 60]],
        ],
        [
            [[252, 252, 252], [188, 188, 220], [255, 255, 255]],
            [[228, 160, 60], [140, 80, 20], [252, 216, 140]],
            [[0, 168, 0], [0, 80, 0], [128, 208, 16]],
            [[252, 116, 96], [200, 40, 0], [252, 216, 168]],
        ],
    ],
    np.uint8,
)
FLAG_COLOR = np.array([240, 240, 240], np.uint8)

AGENT_PATTERN = _pattern(
    [
        "..000...",
        ".00000..",
        ".1121...",
        ".11111..",
        "..000...",
        ".02020..",
        ".00000..",
        ".1..1...",
    ]
)
# form → colours 0 (cap, body), 1 (skin, boots), 2 (overall buttons / eyes)
AGENT_COLORS = np.array(
    [
        [[216, 40, 0], [136, 112, 0], [252, 216, 168]],
        [[216, 40, 0], [0, 60, 200], [252, 216, 168]],
        [[252, 252, 252], [216, 40, 0], [252, 216, 168]],
    ],
    np.uint8,
)
ENEMY_PATTERN = _pattern(
    [
        "..0000..",
        ".000000.",
        "00200200",
        "00211200",
        "00000000",
        "..1111..",
        ".111111.",
        "00....00",
    ]
)
ENEMY_COLORS = np.array([[160, 60, 20], [252, 216, 168], [0, 0, 0]], np.uint8)
FIREBALL_PATTERN = _pattern(
    [
        "........",
        "..0000..",
        ".011110.",
        ".012210.",
        ".012210.",
        ".011110.",
        "..0000..",
        "........",
    ]
)
FIREBALL_COLORS = np.array([[216, 40, 0], [252, 152, 56], [252, 252, 200]], np.uint8)


def _sprite(image, px, py, left, bottom, width, height, pattern, colors):
    """Draw a pattern stretched over the world box (left, bottom, width, height) onto ``image``."""
    u = (px - left) / width
    v = 1.0 - (py - bottom) / height
    inside = (u >= 0) & (u < 1) & (v >= 0) & (v < 1)
    index = jnp.asarray(pattern)[
        jnp.clip((v * SPRITE).astype(jnp.int32), 0, SPRITE - 1),
        jnp.clip((u * SPRITE).astype(jnp.int32), 0, SPRITE - 1),
    ]
    color = jnp.asarray(colors)[jnp.maximum(index, 0)]
    return jnp.where((inside & (index >= 0))[..., None], color, image)


def draw_view(state, context, cols: int, rows: int, tile_pixels: int):
    """An RGB picture (rows·tile_pixels, cols·tile_pixels, 3) uint8 of the level around the agent."""
    reach = world.jump_reach(context)
    height_px, width_px = rows * tile_pixels, cols * tile_pixels
    camera_x = jnp.maximum(state.x - cols / 3, 0.0)  # never left of the level start
    camera_y = jnp.clip(state.y - rows / 2, 0.0, max(world.ROWS - rows, 0))
    # Pixel centres in world (tile) coordinates, snapped to the pixel grid so scrolling is crisp.
    left = jnp.floor(camera_x * tile_pixels) / tile_pixels
    bottom = jnp.floor(camera_y * tile_pixels) / tile_pixels
    px = left + (jnp.arange(width_px)[None, :] + 0.5) / tile_pixels
    py = bottom + (height_px - 1 - jnp.arange(height_px)[:, None] + 0.5) / tile_pixels

    first_column = jnp.floor(left).astype(jnp.int32)
    first_row = jnp.floor(bottom).astype(jnp.int32)
    columns = first_column + jnp.arange(cols + 1)
    grid_rows = first_row + jnp.arange(rows + 1)
    window = world.level_window(context, reach, first_column, cols + 1)
    kinds = world.window_tiles(context, window, columns[None, :], grid_rows[:, None])
    column = jnp.floor(px).astype(jnp.int32) - first_column
    row = jnp.floor(py).astype(jnp.int32) - first_row
    kind = kinds[jnp.clip(row, 0, rows), jnp.clip(column, 0, cols)]
    within_x = ((px - jnp.floor(px)) * SPRITE).astype(jnp.int32)
    within_y = (SPRITE - 1 - ((py - jnp.floor(py)) * SPRITE)).astype(jnp.int32)
    entry = jnp.asarray(TILE_PATTERNS)[kind, within_y, within_x]
    style = context.level_index
    solid_colors = jnp.asarray(TILE_COLORS)[style]  # (4 kinds, 3 entries, RGB)
    colored = solid_colors[jnp.clip(kind - world.GROUND, 0, 3), jnp.maximum(entry, 0)]
    background = jnp.broadcast_to(jnp.asarray(BACKGROUND)[style], colored.shape)
    image = jnp.where(
        ((kind >= world.GROUND) & (kind <= world.LAVA))[..., None], colored, background
    )
    pole = (kind == world.FLAG) & (entry == 2)
    image = jnp.where(pole[..., None], jnp.asarray(FLAG_COLOR), image)

    # Enemies of the segments in view (none leaves its segment), the fireball, then the agent
    # (blinking while invulnerable).
    first_segment, layout = window
    segment = first_segment + jnp.arange(layout["enemy"].shape[-1])
    alive = layout["enemy"] & ~world.is_defeated(state.defeated, segment)
    enemy_x = world.enemy_x(layout, state.clock.astype(jnp.float32))
    for i in range(segment.shape[0]):
        drawn = _sprite(
            image,
            px,
            py,
            enemy_x[i],
            layout["height"][i].astype(jnp.float32),
            world.ENEMY_SIZE,
            world.ENEMY_SIZE,
            ENEMY_PATTERN,
            ENEMY_COLORS,
        )
        image = jnp.where(alive[i], drawn, image)
    half = world.FIREBALL_SIZE / 2
    burning = _sprite(
        image,
        px,
        py,
        state.fireball[0] - half,
        state.fireball[1] - half,
        world.FIREBALL_SIZE,
        world.FIREBALL_SIZE,
        FIREBALL_PATTERN,
        FIREBALL_COLORS,
    )
    image = jnp.where(state.fireball_steps > 0, burning, image)
    agent = _sprite(
        image,
        px,
        py,
        state.x,
        state.y,
        world.AGENT_WIDTH,
        world.agent_height(world.current_form(state, context)),
        AGENT_PATTERN,
        jnp.asarray(AGENT_COLORS)[world.current_form(state, context)],
    )
    visible = (state.invulnerable // 3) % 2 == 0
    return jnp.where(visible, agent, image)
