"""Rendering: every classic-control env draws its context; animations and grids are written."""

import numpy as np
import pytest

import contextrl as crl
from contextrl.gymnasium import ContextualGymEnv
from contextrl.render import draw, union_box
from contextrl.render.animation import side_by_side, write_gif

CLASSIC = crl.registered(family="classic_control")


def _ink(frame: np.ndarray) -> int:
    return int((frame != 255).any(axis=2).sum())


@pytest.mark.parametrize(
    ("env_id", "feature", "small", "large"),
    [
        ("CartPole", "length", 0.25, 1.5),
        ("Pendulum", "l", 0.5, 1.8),
        ("Acrobot", "LINK_LENGTH_2", 0.3, 1.0),
        ("MountainCar", "max_position", 0.5, 1.2),
        ("MountainCarContinuous", "max_position", 0.5, 1.2),
    ],
)
def test_a_larger_context_is_drawn_larger(env_id, feature, small, large):
    env = crl.make(env_id)
    physics = np.asarray(env.init(crl_key(), env.default_context()))
    contexts = [env.context(**{feature: v}) for v in (small, large)]
    renderer_box = union_box([_box(env, c) for c in contexts])
    frames = [draw(env, physics, c, world_box=renderer_box) for c in contexts]
    assert frames[0].shape == frames[1].shape and frames[0].dtype == np.uint8
    assert _ink(frames[1]) > _ink(frames[0]) * 1.2


@pytest.mark.parametrize("env_id", CLASSIC)
def test_rgb_array_render_follows_the_state(env_id):
    env = ContextualGymEnv(env_id, render_mode="rgb_array")
    env.reset(seed=0)
    first = env.render()
    action = 1 if env_id != "MountainCarContinuous" and env_id != "Pendulum" else [1.0]
    for _ in range(15):
        env.step(np.asarray(action, np.float32) if isinstance(action, list) else action)
    later = env.render()
    assert first.ndim == 3 and first.shape[2] == 3 and first.dtype == np.uint8
    assert _ink(first) > 100
    assert not np.array_equal(first, later)


def test_side_by_side_and_gif_round_trip(tmp_path):
    from PIL import Image

    red = np.zeros((10, 20, 3), np.uint8)
    red[..., 0] = 255
    blue = np.zeros((8, 30, 3), np.uint8)
    blue[..., 2] = 255
    image = side_by_side([red, blue])
    assert image.shape == (10, 20 + 4 + 30, 3)
    assert tuple(image[0, 0]) == (255, 0, 0) and tuple(image[0, -1]) == (0, 0, 255)
    assert tuple(image[9, -1]) == (255, 255, 255)  # the shorter panel is padded with white
    path = write_gif([red, red * 0], tmp_path / "out" / "a.gif", fps=10)
    with Image.open(path) as gif:
        assert gif.n_frames == 2 and gif.size == (20, 10)
    assert list((tmp_path / "out").iterdir()) == [path]  # no temporary file left behind
    with pytest.raises(ValueError, match="at least one frame"):
        write_gif([], tmp_path / "b.gif", fps=10)


def test_panel_labels_are_readable_on_dark_frames():
    """A caption is black on a white box, so it shows on a black frame (LunarLander's sky) too."""
    dark = np.zeros((60, 120, 3), np.uint8)
    image = side_by_side([dark, dark], ["length 0.25", "length 0.75"])
    for left in (0, 124):
        caption = image[2:24, left : left + 100]
        assert (caption == 255).all(axis=-1).sum() > 100  # the box
        assert (caption == 0).all(axis=-1).sum() > 20  # the letters on it
    assert (image[40:, :120] == 0).all() and (image[40:, 124:] == 0).all()  # frames untouched


def _box(env, context):
    from contextrl.render import renderer_for

    return renderer_for(env).world_box(context)


def crl_key():
    import jax

    return jax.random.key(0)
