"""CleanRL's own ``ppo_continuous_action.py`` (PyTorch) trained on contextrl's tensor face, or on the
gymnasium vector face (NumPy), with nothing of the script rewritten but its environment lines.

    pip download --no-deps cleanrl==0.4.8 -d /tmp/cleanrl && tar xzf /tmp/cleanrl/cleanrl-0.4.8.tar.gz -C /tmp/cleanrl
    taskset -c 0 python benchmarks/cleanrl_torch_ppo.py \\
        --script /tmp/cleanrl/cleanrl-0.4.8/cleanrl/ppo_continuous_action.py --face torch \\
        -- --gym-id contextrl/Pendulum-v0 --num-envs 4 --num-steps 256 --n-minibatch 16 \\
        --learning-rate 1e-3 --anneal-lr false --gamma 0.9 --ent-coef 0 --total-timesteps 1000000 \\
        --cuda false --capture-video false

Nothing is downloaded here: ``--script`` is the path to the user's copy. The script is CleanRL 0.4.8's
(the version on PyPI; its API is old gym's and stable-baselines3's vector env). Its text is read, the
lines below are swapped (each must match exactly once, or the runner stops naming the line: another
version of the script), and it runs as ``__main__`` with the arguments after ``--``:

==========================================================================  ==========================================
line of the script                                                          becomes
==========================================================================  ==========================================
``from torch.utils.tensorboard import SummaryWriter``                       ``SummaryWriter = _contextrl.RecordingWriter``
``from distutils.util import strtobool``                                    ``strtobool = _contextrl.strtobool``
``import gym``                                                              ``import gymnasium as gym``
``from gym.wrappers import TimeLimit, Monitor``                             (removed)
``import pybullet_envs``                                                    (removed)
``from gym.spaces import Discrete, Box, MultiBinary, MultiDiscrete, Space`` ``from gymnasium.spaces import (the same)``
``from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv,  ``DummyVecEnv = SubprocVecEnv =
VecEnvWrapper``                                                             VecEnvWrapper = object``
``envs = VecPyTorch(DummyVecEnv([make_env(args.gym_id, args.seed+i, i) for  ``envs = _contextrl.make_envs(args,
i in range(args.num_envs)]), device)``                                      device)``
==========================================================================  ==========================================

The imports swapped are those of packages the environment lines used (old gym, pybullet, Monitor, SB3's
vector env, tensorboard for the log) or that Python 3.12 dropped (distutils); the classes of the script
that subclass them are defined but not used. ``make_envs`` returns what ``VecPyTorch(DummyVecEnv(...))``
handed the training loop: ``reset() -> obs`` and ``step(action) -> (obs, reward (n, 1), done, infos)``
with ``infos[i]["episode"]["r"]`` where copy ``i``'s episode ended (as RecordEpisodeStatistics did),
single-copy ``observation_space`` and ``action_space``. Over ``--face torch`` that is
``contextrl.torch.make_vec`` (tensors in and out, no conversion); over ``--face numpy`` it is
``gymnasium.make_vec`` with the conversions VecPyTorch made (``torch.from_numpy(obs).float()``,
``action.cpu().numpy()``). Both clip actions to the bounds, as the script's ClipActionsWrapper did; the
script's ``NormalizedEnv`` (running observation and return normalization) is left out on both faces,
so the returns are the environment's own. One JSON line reports the episode returns and the speed.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import types
from pathlib import Path

import numpy as np

SWAPS = [
    (
        "from torch.utils.tensorboard import SummaryWriter",
        "SummaryWriter = _contextrl.RecordingWriter",
    ),
    ("from distutils.util import strtobool", "strtobool = _contextrl.strtobool"),
    ("import gym", "import gymnasium as gym"),
    ("from gym.wrappers import TimeLimit, Monitor", ""),
    ("import pybullet_envs", ""),
    (
        "from gym.spaces import Discrete, Box, MultiBinary, MultiDiscrete, Space",
        "from gymnasium.spaces import Discrete, Box, MultiBinary, MultiDiscrete, Space",
    ),
    (
        "from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnvWrapper",
        "DummyVecEnv = SubprocVecEnv = VecEnvWrapper = object",
    ),
    (
        "envs = VecPyTorch(DummyVecEnv([make_env(args.gym_id, args.seed+i, i) for i in range(args.num_envs)]), device)",
        "envs = _contextrl.make_envs(args, device)",
    ),
]


def swapped(source: str) -> str:
    """The script with :data:`SWAPS` applied, each line matched exactly once (whole lines)."""
    lines = source.splitlines()
    for old, new in SWAPS:
        where = [index for index, line in enumerate(lines) if line == old]
        if len(where) != 1:
            sys.exit(f"the script has {len(where)} lines {old!r}, not one: not CleanRL 0.4.8's")
        lines[where[0]] = new
    return "\n".join(lines) + "\n"


def strtobool(value: str) -> int:
    """distutils' ``strtobool``: 1 for y/yes/t/true/on/1, 0 for n/no/f/false/off/0."""
    lowered = value.lower()
    if lowered in ("y", "yes", "t", "true", "on", "1"):
        return 1
    if lowered in ("n", "no", "f", "false", "off", "0"):
        return 0
    raise ValueError(f"invalid truth value {value!r}")


class RecordingWriter:
    """The script's SummaryWriter, keeping the scalars in memory (no tensorboard)."""

    scalars: dict[str, list[tuple[int, float]]] = {}

    def __init__(self, *args, **kwargs):
        pass

    def add_scalar(self, tag, value, step):
        RecordingWriter.scalars.setdefault(tag, []).append((int(step), float(value)))

    def add_text(self, *args, **kwargs):
        pass

    def close(self):
        pass


class Run:
    """What one run measured: every episode's return, and the seconds spent inside ``step``."""

    face = "torch"
    returns: list[float] = []
    step_seconds = 0.0
    step_cpu_seconds = 0.0  # this process's CPU time: steadier than the clock on a shared core
    steps = 0


class OldVecEnv:
    """The vector env API the script's loop calls (VecPyTorch over DummyVecEnv), over either face."""

    def __init__(self, envs, seed: int, device, as_tensors: bool):
        import torch

        self.torch = torch
        self.envs, self.seed, self.device, self.as_tensors = envs, seed, device, as_tensors
        self.observation_space = envs.single_observation_space
        self.action_space = envs.single_action_space
        self.num_envs = envs.num_envs
        self.running = np.zeros(self.num_envs)

    def _tensor(self, array):
        if self.as_tensors:
            return array.to(self.device)
        return self.torch.from_numpy(array).float().to(self.device)

    def reset(self):
        obs, _ = self.envs.reset(seed=self.seed)
        return self._tensor(obs)

    def step(self, action):
        start, cpu = time.perf_counter(), time.process_time()
        if not self.as_tensors:
            action = action.cpu().numpy()
        obs, reward, terminated, truncated, _ = self.envs.step(action)
        obs, reward = self._tensor(obs), self._tensor(reward)
        Run.step_seconds += time.perf_counter() - start
        Run.step_cpu_seconds += time.process_time() - cpu
        Run.steps += self.num_envs
        done = np.asarray(terminated | truncated)
        self.running += reward.cpu().numpy()
        infos = [{} for _ in range(self.num_envs)]
        for index in np.flatnonzero(done):
            infos[index]["episode"] = {"r": float(self.running[index])}
            Run.returns.append(float(self.running[index]))
        self.running[done] = 0.0
        return obs, reward.unsqueeze(1), self.torch.as_tensor(done, dtype=self.torch.float32), infos

    def close(self):
        self.envs.close()


def make_envs(args, device) -> OldVecEnv:
    """The ``envs`` of the script: ``args.num_envs`` copies of ``args.gym_id`` on the chosen face."""
    if Run.face == "torch":
        import contextrl.torch

        envs = contextrl.torch.make_vec(args.gym_id, num_envs=args.num_envs, device=str(device))
        return OldVecEnv(envs, args.seed, device, as_tensors=True)
    import gymnasium

    import contextrl  # noqa: F401  (registers the gymnasium ids)

    envs = gymnasium.make_vec(args.gym_id, num_envs=args.num_envs)
    return OldVecEnv(envs, args.seed, device, as_tensors=False)


def main(argv: list[str] | None = None) -> dict:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--script", required=True, help="path to CleanRL's ppo_continuous_action.py"
    )
    parser.add_argument("--face", choices=["torch", "numpy"], default="torch")
    parser.add_argument("--json", help="also write the summary here")
    parser.add_argument("script_args", nargs=argparse.REMAINDER, help="-- then the script's own")
    args = parser.parse_args(argv)
    script = Path(args.script)
    forwarded = args.script_args[1:] if args.script_args[:1] == ["--"] else args.script_args
    code = compile(swapped(script.read_text(encoding="utf-8")), str(script), "exec")
    Run.face = args.face
    runner = types.ModuleType("_contextrl")
    runner.__dict__.update(
        make_envs=make_envs, RecordingWriter=RecordingWriter, strtobool=strtobool
    )
    sys.argv = [str(script), *forwarded]
    start, cpu = time.perf_counter(), time.process_time()
    exec(code, {"__name__": "__main__", "__file__": str(script), "_contextrl": runner})
    seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
    last = Run.returns[-20:]
    summary = {
        "face": args.face,
        "script_args": forwarded,
        "env_steps": Run.steps,
        "episodes": len(Run.returns),
        "first_20_mean_return": float(np.mean(Run.returns[:20])) if Run.returns else None,
        "last_20_mean_return": float(np.mean(last)) if last else None,
        "seconds": round(seconds, 1),
        "steps_per_second": round(Run.steps / seconds, 1),
        "cpu_seconds": round(cpu_seconds, 1),
        "steps_per_cpu_second": round(Run.steps / cpu_seconds, 1),
        "env_step_seconds": round(Run.step_seconds, 2),
        "env_steps_per_second_in_step": round(Run.steps / Run.step_seconds, 1),
        "env_step_cpu_seconds": round(Run.step_cpu_seconds, 2),
        "env_steps_per_cpu_second_in_step": round(Run.steps / Run.step_cpu_seconds, 1),
    }
    print(json.dumps(summary))
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1) + "\n", encoding="utf-8")
    return summary


if __name__ == "__main__":
    main()
