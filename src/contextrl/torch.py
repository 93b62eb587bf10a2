"""The vector environment for PyTorch trainers: tensors in and out, shared with JAX through DLPack.

    import contextrl.torch
    envs = contextrl.torch.make_vec("contextrl/CartPole-v0", num_envs=64, contexts=batch, device="cpu")
    obs, info = envs.reset(seed=0)                         # obs: a (64, 4) float32 tensor
    obs, reward, terminated, truncated, info = envs.step(actions)   # actions: a tensor

This is the gymnasium vector environment (:class:`contextrl.gymnasium.ContextualVectorEnv`) with a
tensor face: the same compiled program steps the copies (the core's ``ContextualEnv.step_copies``), with
the same same-step auto-reset (``metadata["autoreset_mode"]``), contexts, ``info`` and refusals. What
differs is how the arrays cross. The program returns one uint32 array, a row per copy packed from
:class:`contextrl.gymnasium.frames.CopySteps`; the observation, reward, flags and ``info["final_obs"]``
are torch views of that JAX buffer (``torch.from_dlpack``: no copy), and an action tensor on the
environment's device is handed to the program as it is (``jax.dlpack.from_dlpack``: no copy). The
``info`` dict stays as the gymnasium face builds it (NumPy, from the step's rows on the host). The face
views the vector env's ``rows`` (the last call's, on the device) and steps it through ``step_checked``
with the actions it has checked itself.

On the CPU the saving is memory, not time: with a few copies, importing an action through DLPack costs
more Python than the NumPy face's copy (benchmarks/results/cleanrl_torch_ppo.md); the copies it avoids
matter on a GPU, where the NumPy path moves every observation and action through the host.

Copies are made only where the values must change or JAX needs them: an int64 discrete action becomes
int32 (what the program takes), a Box action outside its bounds is clipped into a new tensor (as the
gymnasium face clips it), a non-contiguous action tensor is made contiguous, and on the CPU JAX copies a
tensor whose address is not 64-byte aligned (every tensor torch allocates is; a slice of one at another
offset may not be). ``import contextrl`` imports neither this module nor torch (``pip install
contextrl[torch]``).
"""

from __future__ import annotations

import math
import sys
from typing import Any

import gymnasium
import jax
import numpy as np
import torch

from contextrl.core.registry import spec
from contextrl.gymnasium.backends import ActionRule
from contextrl.gymnasium.registration import NAMESPACE
from contextrl.gymnasium.vector import ContextualVectorEnv

# How a row's 32-bit words read as each field's dtype (a bool is its word's first byte).
_VIEWS = {np.dtype(np.float32): torch.float32, np.dtype(np.int32): torch.int32}


def jax_device(device: str | torch.device) -> jax.Device:
    """The JAX device sharing memory with torch's ``device`` (CPU, or the CUDA device of that index);
    refused in one line where JAX has none."""
    device = torch.device(device)
    platforms = {"cpu": "cpu", "cuda": "gpu"}
    if device.type not in platforms:
        raise ValueError(f"device must be 'cpu' or 'cuda[:index]', got {str(device)!r}")
    try:
        devices = jax.devices(platforms[device.type])
    except RuntimeError:
        devices = []
    index = device.index or 0
    if index >= len(devices):
        raise ValueError(
            f"device {str(device)!r} has no JAX counterpart (JAX's devices: "
            f"{', '.join(str(d) for d in jax.devices())}); install JAX for that platform or pass "
            "device='cpu'"
        )
    return devices[index]


def _describe(tensor: torch.Tensor) -> str:
    dtype = str(tensor.dtype).removeprefix("torch.")
    article = "an" if dtype[0] in "aeiou" else "a"
    return f"{article} {dtype} tensor of shape {tuple(tensor.shape)} on {tensor.device}"


class TorchVectorEnv(gymnasium.vector.VectorWrapper):
    """``num_envs`` copies of a JAX environment whose observations, rewards and flags are torch tensors
    on ``device`` and whose actions may be (arguments otherwise as
    :class:`contextrl.gymnasium.ContextualVectorEnv`; ``env_id`` also as a gymnasium id).

    ``step`` takes a tensor on ``device``, float32 for a Box space or int32 (read in place) or int64 for
    a discrete one, of shape ``(num_envs, *single_action_space.shape)``; or anything the gymnasium
    vector face takes, checked by its rule. Anything else is refused in one line before the step runs.
    """

    def __init__(
        self,
        env_id: str | Any,
        num_envs: int = 1,
        device: str | torch.device = "cpu",
        **kwargs: Any,
    ):
        if sys.byteorder != "little":
            raise RuntimeError("the tensor face reads packed rows as little-endian words")
        if kwargs.get("obs_context_as_dict"):
            raise ValueError(
                "obs_context_as_dict=True is not offered by the tensor face; leave it False to get "
                "the context features at the end of the flat observation"
            )
        name = env_id
        if isinstance(env_id, str) and env_id.startswith(f"{NAMESPACE}/"):
            entry = gymnasium.registry.get(env_id)
            name = entry.kwargs["env_id"] if entry is not None else env_id
        if isinstance(name, str) and spec(name).runs_on_host(kwargs):
            raise TypeError(
                f"{name} runs on the host, not in one compiled call; use gymnasium.make_vec with "
                "gymnasium.wrappers.vector.NumpyToTorch for it"
            )
        self.device = torch.device(device)
        self.jax_device = jax_device(self.device)
        vector = ContextualVectorEnv(name, num_envs, **kwargs)
        super().__init__(vector)
        # The same programs, run on the device the tensors live on.
        vector.table = jax.device_put(vector.table, self.jax_device)
        frame = vector.programs.frame
        fields = list(zip(frame.slices, frame.dtypes, frame.shapes, strict=True))
        self._layout = jax.tree_util.tree_unflatten(frame.treedef, fields)
        self._rule = ActionRule(self.single_action_space, self.num_envs)
        space = self.single_action_space
        self._action_shape = (self.num_envs, *space.shape)
        if isinstance(space, gymnasium.spaces.Box):
            self._dtypes = (torch.float32,)
            self._low = torch.as_tensor(space.low, dtype=torch.float32, device=self.device)
            self._high = torch.as_tensor(space.high, dtype=torch.float32, device=self.device)
        elif isinstance(space, gymnasium.spaces.Discrete):
            self._dtypes = (torch.int32, torch.int64)
        else:
            self._dtypes = ()

    # ---- actions ----------------------------------------------------------------------------------
    def _refusal(self, got: str) -> ValueError:
        dtypes = " or ".join(str(d).removeprefix("torch.") for d in self._dtypes)
        article = "an" if dtypes.startswith("int") else "a"
        return ValueError(
            f"actions must be {self._rule.expected}: {article} {dtypes} tensor on {self.device} "
            f"(or a NumPy array), got {got}"
        )

    def _device_actions(self, actions: Any) -> jax.Array:
        """The actions as the program takes them, on its device; refused in one line if invalid."""
        if not isinstance(actions, torch.Tensor):
            return jax.device_put(self.env.check(actions), self.jax_device)
        if not self._dtypes:  # a space with no tensor rule: the gymnasium face's, on the host
            return jax.device_put(self.env.check(actions.cpu().numpy()), self.jax_device)
        if (
            actions.dtype not in self._dtypes
            or tuple(actions.shape) != self._action_shape
            or actions.device != self.device
        ):
            raise self._refusal(_describe(actions))
        actions = actions.detach()
        # One reduction and one read for the whole check: per dimension, the least and the greatest
        # value (NaN where any is NaN), compared with the bounds in Python.
        if actions.dtype == torch.float32:
            least, greatest = torch.stack(torch.aminmax(actions.reshape(self.num_envs, -1), dim=0))
            least, greatest = least.tolist(), greatest.tolist()
            if not all(math.isfinite(value) for value in least + greatest):
                raise self._refusal(f"{_describe(actions)} holding NaN or infinity")
            lows, highs = self._rule.bounds
            inside = zip(least, greatest, lows, highs, strict=True)
            if not all(low <= small and big <= high for small, big, low, high in inside):
                actions = torch.minimum(torch.maximum(actions, self._low), self._high)
        else:
            least, greatest = torch.stack(torch.aminmax(actions)).tolist()
            if least < self._rule.low or greatest >= self._rule.high:
                raise self._refusal(
                    f"{_describe(actions)} holding values from {least} to {greatest}"
                )
            actions = actions.to(torch.int32)
        return jax.dlpack.from_dlpack(actions.contiguous())

    # ---- observations -----------------------------------------------------------------------------
    def _tensors(self, names: tuple[str, ...]) -> tuple[torch.Tensor, ...]:
        """Fields of every row of the last call's words, as views (no copy): each 32-bit field read
        in its dtype, a bool as its word's first byte."""
        words = torch.from_dlpack(self.env.rows)
        typed: dict[torch.dtype, torch.Tensor] = {}
        fields = []
        for name in names:
            part, dtype, shape = getattr(self._layout, name)
            as_type = torch.uint8 if dtype == np.bool_ else _VIEWS[dtype]
            if as_type not in typed:
                typed[as_type] = words.view(as_type)
            if dtype == np.bool_:
                fields.append(typed[as_type][:, 4 * part.start].view(torch.bool))
            elif shape == ():
                fields.append(typed[as_type][:, part.start])
            elif len(shape) == 1:
                fields.append(typed[as_type][:, part])
            else:
                fields.append(typed[as_type][:, part].unflatten(1, shape))
        return tuple(fields)

    # ---- the gymnasium API ------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int] | None = None, options: dict[str, Any] | None = None):
        """Start every copy's first episode: ``(obs, info)``, ``obs`` a (num_envs, dim) tensor."""
        _, info = self.env.reset(seed=seed, options=options)
        (obs,) = self._tensors(("obs",))
        return obs, info

    def step(self, actions: Any):
        """One step of every copy: ``(obs, reward, terminated, truncated, info)``, the first four
        tensors; where a copy's episode ended, ``info["final_obs"]`` is a tensor too."""
        _, _, _, _, info = self.env.step_checked(self._device_actions(actions))
        ended = "final_obs" in info
        names = ("obs", "reward", "terminated", "truncated") + (("final_obs",) if ended else ())
        obs, reward, terminated, truncated, *final_obs = self._tensors(names)
        if ended:
            (info["final_obs"],) = final_obs
        return obs, reward, terminated, truncated, info


def make_vec(
    env_id: str | Any, num_envs: int = 1, device: str | torch.device = "cpu", **kwargs: Any
) -> TorchVectorEnv:
    """``num_envs`` copies of ``env_id`` (``"contextrl/CartPole-v0"`` or ``"CartPole"``) as a
    :class:`TorchVectorEnv` on ``device``; the keyword arguments are those of ``gymnasium.make_vec``
    for a contextrl id (``contexts``, ``context_selector``, ``obs_context_features``, ``max_steps``…)."""
    return TorchVectorEnv(env_id, num_envs, device=device, **kwargs)


__all__ = ["TorchVectorEnv", "jax_device", "make_vec"]
