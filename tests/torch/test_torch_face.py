"""The tensor face (contextrl.torch): views of the compiled step's own buffer, actions read in place,
the gymnasium vector face's trajectory step for step, and one-line refusals."""

import ast
import importlib.util

import gymnasium
import numpy as np
import pytest

torch = pytest.importorskip("torch")

import contextrl.torch as crl_torch  # noqa: E402
from tests.helpers import ROOT  # noqa: E402

_spec = importlib.util.spec_from_file_location("import_graph", ROOT / "tools" / "import_graph.py")
import_graph = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(import_graph)

LENGTHS = [{"length": 0.25}, {"length": 1.0}]


def recording(env):
    """``env`` whose vector env keeps the actions its program was last handed (``env.received``)."""
    step_checked = env.env.step_checked

    def step(actions):
        env.received = actions
        return step_checked(actions)

    env.env.step_checked = step
    return env


@pytest.fixture(scope="module")
def cartpole():
    return recording(
        crl_torch.make_vec("contextrl/CartPole-v0", num_envs=3, contexts=LENGTHS, max_steps=6)
    )


@pytest.fixture(scope="module")
def pendulum():
    return recording(crl_torch.make_vec("Pendulum", num_envs=2, max_steps=4))


def offset_of(env, name: str) -> int:
    """Where a field of the step's rows starts, in bytes from the buffer's start."""
    part, _, _ = getattr(env._layout, name)
    return 4 * part.start


def test_tensors_are_views_of_the_compiled_steps_buffer_and_actions_are_read_in_place(cartpole):
    obs, _ = cartpole.reset(seed=0)
    assert obs.data_ptr() == cartpole.env.rows.unsafe_buffer_pointer()
    actions = torch.tensor([0, 1, 1], dtype=torch.int32)
    obs, reward, terminated, truncated, _ = cartpole.step(actions)
    rows = cartpole.env.rows
    base = rows.unsafe_buffer_pointer()
    assert obs.data_ptr() == base and obs.shape == (3, 4) and obs.dtype == torch.float32
    for name, tensor in [("reward", reward), ("terminated", terminated), ("truncated", truncated)]:
        assert tensor.data_ptr() == base + offset_of(cartpole, name), name
    assert terminated.dtype == truncated.dtype == torch.bool and reward.dtype == torch.float32
    np.testing.assert_array_equal(obs.numpy(), np.asarray(rows)[:, :4].view(np.float32))
    # the int32 actions reached the program as the same memory
    assert cartpole.received.unsafe_buffer_pointer() == actions.data_ptr()
    cartpole.step(torch.tensor([0, 1, 1]))  # int64 is converted: a new (int32) buffer
    assert cartpole.received.dtype == np.int32


def test_float_actions_are_read_in_place_inside_their_bounds_and_clipped_outside(pendulum):
    pendulum.reset(seed=0)
    inside = torch.tensor([[0.5], [-2.0]])
    pendulum.step(inside)
    assert pendulum.received.unsafe_buffer_pointer() == inside.data_ptr()
    outside = torch.tensor([[5.0], [-2.0]])
    pendulum.step(outside)
    assert pendulum.received.unsafe_buffer_pointer() != outside.data_ptr()
    np.testing.assert_array_equal(np.asarray(pendulum.received), [[2.0], [-2.0]])
    # JAX on the CPU reads a buffer in place only at a 64-byte-aligned address; elsewhere it copies
    storage = torch.zeros(32)
    for offset, in_place in [(0, True), (1, False), (16, True)]:
        sliced = storage[offset : offset + 2].reshape(2, 1)
        pendulum.step(sliced)
        assert (pendulum.received.unsafe_buffer_pointer() == sliced.data_ptr()) == in_place


def same(torch_value, numpy_value, where: str):
    """A step (or reset) of the tensor face equals the gymnasium face's, tensors read as arrays."""
    if isinstance(numpy_value, tuple):
        assert len(torch_value) == len(numpy_value), where
        for index, (faced, expected) in enumerate(zip(torch_value, numpy_value, strict=True)):
            same(faced, expected, f"{where}[{index}]")
        return
    if isinstance(numpy_value, dict):
        assert set(torch_value) == set(numpy_value), where
        for key in numpy_value:
            same(torch_value[key], numpy_value[key], f"{where}[{key!r}]")
        return
    if isinstance(torch_value, torch.Tensor):
        torch_value = torch_value.numpy()
    np.testing.assert_array_equal(torch_value, numpy_value, err_msg=where)
    assert np.asarray(torch_value).dtype == np.asarray(numpy_value).dtype, where


def test_the_trajectory_is_the_gymnasium_vector_faces_step_for_step(cartpole):
    """Same seed, same actions: the same observations, rewards, flags and info, through auto-resets
    (max_steps=6) that move copies to their next context (3 copies over 2 contexts)."""
    numpy_envs = gymnasium.make_vec(
        "contextrl/CartPole-v0", num_envs=3, contexts=LENGTHS, max_steps=6
    )
    assert cartpole.metadata["autoreset_mode"] == numpy_envs.metadata["autoreset_mode"]
    assert cartpole.single_observation_space == numpy_envs.single_observation_space
    assert cartpole.single_action_space == numpy_envs.single_action_space
    same(cartpole.reset(seed=3), numpy_envs.reset(seed=3), "reset")
    actions = np.random.default_rng(0).integers(0, 2, size=(14, 3))
    ended = 0
    for step, action in enumerate(actions):
        faced = cartpole.step(torch.from_numpy(action))
        expected = numpy_envs.step(action)
        same(faced, expected, f"step {step}")
        ended += int(np.sum(expected[2] | expected[3]))
        if "final_obs" in expected[4]:
            assert isinstance(faced[4]["final_obs"], torch.Tensor)
    assert ended >= 6  # every copy auto-reset at least twice


def test_bad_actions_are_refused_in_one_line_before_the_step_runs(cartpole, pendulum):
    cartpole.reset(seed=0)
    rows = cartpole.env.rows
    cases = [
        (torch.ones(3), "a float32 tensor of shape (3,)"),
        (torch.ones(4, dtype=torch.int32), "of shape (4,)"),
        (torch.tensor([0, 2, 1]), "holding values from 0 to 2"),
        (torch.tensor([0, 1, 1], dtype=torch.int32).to("meta"), "on meta"),
    ]
    for bad, got in cases:
        with pytest.raises(ValueError) as refused:
            cartpole.step(bad)
        message = str(refused.value)
        assert "\n" not in message and got in message, message
        assert message.startswith("actions must be 3 integers in [0, 2): an int32 or int64 tensor")
    with pytest.raises(ValueError, match=r"^actions must be 3 integers"):  # the vector env inside
        cartpole.env.step(np.array([0, 5, 1]))  # still checks what is handed to it directly
    assert cartpole.env.rows is rows  # nothing ran
    pendulum.reset(seed=0)
    for bad in [torch.tensor([[float("nan")], [0.0]]), torch.zeros(2, 1, dtype=torch.float64)]:
        with pytest.raises(ValueError, match=r"^actions must be finite floats of shape \(2, 1\)"):
            pendulum.step(bad)
    with pytest.raises(ValueError, match="NaN or infinity"):
        pendulum.step(torch.tensor([[float("inf")], [0.0]]))
    with pytest.raises(ValueError, match=r"^actions must be finite floats"):  # the gymnasium rule
        pendulum.step(np.array([[np.nan], [0.0]]))


def test_a_device_jax_does_not_have_and_a_host_env_are_refused_in_one_line():
    with pytest.raises(ValueError, match="device 'cuda:7' has no JAX counterpart"):
        crl_torch.make_vec("CartPole", num_envs=2, device="cuda:7")
    with pytest.raises(TypeError, match="runs on the host"):
        crl_torch.make_vec("contextrl/LunarLander-v0", num_envs=2)


def module_level_imports(path) -> set[str]:
    """The top-level names a module imports when it loads (imports inside functions left out)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = set()
    for node, deferred in import_graph._statements(tree):
        if deferred:
            continue
        if isinstance(node, ast.Import):
            names |= {alias.name.split(".")[0] for alias in node.names}
        elif node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def test_import_contextrl_does_not_import_torch():
    """Read statically (tools/import_graph.py): the modules ``import contextrl`` loads, their packages
    included, and what each imports at load time. Only contextrl.torch imports torch, and it is not
    among them."""
    modules = import_graph.module_names()
    imports: dict[str, list[str]] = {}
    for edge in import_graph.read_imports():
        if not edge.deferred:
            imports.setdefault(edge.importer, []).append(edge.imported)
    loaded, todo = set(), ["contextrl"]
    while todo:
        module = todo.pop()
        if module in loaded:
            continue
        loaded.add(module)
        parts = module.split(".")
        todo += [".".join(parts[:end]) for end in range(1, len(parts))]
        todo += imports.get(module, [])
    assert "contextrl.gymnasium.vector" in loaded and "contextrl.torch" not in loaded
    assert "torch" in module_level_imports(modules["contextrl.torch"])  # the reading sees it
    assert [m for m in sorted(loaded) if "torch" in module_level_imports(modules[m])] == []
