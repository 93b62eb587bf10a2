"""The vector gymnasium environment of host simulators: copies stepped in slices, a slice per core.

    envs = gymnasium.make_vec("contextrl/LunarLander-v0", num_envs=64, contexts=...)  # core slices

This process steps the first contiguous slice of the copies and each worker process one more:
single adapters with their copy indices, so copy ``i`` still asks the selector for global episode
``i + e × num_envs`` and resets with seed ``seed + i``, exactly as in gymnasium's
``SyncVectorEnv`` of the same adapters (the results are equal, step by step). Observations travel
in shared memory; a step sends each worker its actions and gets back rewards, flags and, only for
copies whose episode ended, the ended episode's last observation and info and the new episode's
context. ``info`` keeps gymnasium's vector layout (``info["context"][name][i]``, masks,
``final_obs``/``final_info`` with ``SAME_STEP`` auto-reset), and its context part is rebuilt only
for the copies whose episode changed.

gymnasium's ``AsyncVectorEnv`` runs one process per copy and merges every copy's info dict at every
step; its worker protocol (one env per pipe, scalar ``terminated``) does not carry a slice of
copies, so the workers here are our own, built from its shared-memory helpers and its spawn-safe
pickling.
"""

from __future__ import annotations

import functools
import multiprocessing
import os
import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import (
    CloudpickleWrapper,
    batch_space,
    create_empty_array,
    create_shared_memory,
    read_from_shared_memory,
)

from contextrl.gymnasium.backends import action_check
from contextrl.gymnasium.env import ContextualGymEnv, check_count

# An episode's own keys of a copy's ``info``; the others are the environment's facts of the step.
_CONTEXT_KEYS = ("context_id", "context")


# Copies a slice needs before a worker pays off: a step's round trip to a worker costs about
# 0.2-0.3 ms on a 2-core machine, as much as stepping 8 LunarLanders (bench_host_vector.py).
MIN_COPIES_PER_SLICE = 8
# How long a worker polls for the next command, and the caller for an answer, before sleeping,
# while there is a core per slice: the next step's command usually comes within a millisecond, and
# waking a sleeping process costs 0.1-0.2 ms. With more slices than cores, polling would take a
# core from a slice.
_WORKER_SPIN, _CALLER_SPIN = 0.001, 0.002


def default_workers(num_envs: int) -> int:
    """Worker processes beside this one: one per further core it may use, while every slice keeps
    ``MIN_COPIES_PER_SLICE`` copies (this process steps the first slice itself)."""
    slices = min(len(os.sched_getaffinity(0)), num_envs // MIN_COPIES_PER_SLICE)
    return max(0, slices - 1)


def _wait(pipe, spin: float) -> None:
    """Return once ``pipe`` has a message: polled for ``spin`` seconds, then waited for asleep (a
    sleeping process takes 0.1-0.2 ms to wake, as long as stepping a few copies)."""
    deadline = time.perf_counter() + spin
    while not pipe.poll():
        if time.perf_counter() > deadline:
            pipe.poll(None)
            return


def _put(buffer: Any, index: int, value: Any) -> None:
    """Write one copy's observation into row ``index`` of a batch (a Dict space's key by key)."""
    if isinstance(buffer, dict):
        for key, part in buffer.items():
            _put(part, index, value[key])
    else:
        buffer[index] = value


def _copied(buffer: Any) -> Any:
    if isinstance(buffer, dict):
        return {key: _copied(part) for key, part in buffer.items()}
    return np.array(buffer)


def _facts(info: dict[str, Any]) -> dict[str, Any]:
    return {key: value for key, value in info.items() if key not in _CONTEXT_KEYS}


def _nested_copy(info: dict[str, Any]) -> dict[str, Any]:
    """New dicts around the same arrays: a caller may add keys to the dict it got."""
    return {key: _nested_copy(v) if isinstance(v, dict) else v for key, v in info.items()}


def _deep_copy(info: dict[str, Any]) -> dict[str, Any]:
    """New dicts and new arrays: what is about to be changed in place."""
    return {
        key: _deep_copy(v) if isinstance(v, dict) else np.array(v, copy=True)
        for key, v in info.items()
    }


class Slice:
    """Copies ``start … start + k − 1`` of a vector env, stepped one after another with
    ``SAME_STEP`` auto-reset; observations go into ``buffer`` (the batch, or its shared memory)."""

    def __init__(self, factories: Sequence[Callable[[], ContextualGymEnv]], start: int, buffer):
        self.envs = [factory() for factory in factories]
        self.start = start
        self.buffer = buffer

    def reset(self, seeds, options, mask) -> list[tuple[int, dict]]:
        """Reset the copies where ``mask`` is True; (copy, info) for each."""
        infos = []
        for j, env in enumerate(self.envs):
            if mask[j]:
                obs, info = env.reset(seed=seeds[j], options=options)
                _put(self.buffer, self.start + j, obs)
                infos.append((self.start + j, info))
        return infos

    def step(self, actions):
        """Rewards, flags, the ended episodes (copy, final obs, final info, new info) and, where the
        environment reports any, every copy's step facts."""
        count = len(self.envs)
        rewards = np.zeros(count, np.float64)
        terminated = np.zeros(count, np.bool_)
        truncated = np.zeros(count, np.bool_)
        ended, facts = [], []
        for j, env in enumerate(self.envs):
            obs, rewards[j], terminated[j], truncated[j], info = env.step(actions[j])
            if terminated[j] or truncated[j]:
                final_obs, final_info = obs, info
                obs, info = env.reset()
                ended.append((self.start + j, final_obs, final_info, info))
            _put(self.buffer, self.start + j, obs)
            facts.append(_facts(info))
        return rewards, terminated, truncated, ended, facts if any(facts) else None

    def call(self, name: str, args, kwargs) -> list:
        results = []
        for env in self.envs:
            attribute = getattr(env, name)
            results.append(attribute(*args, **kwargs) if callable(attribute) else attribute)
        return results

    def set_attr(self, name: str, values: Sequence) -> None:
        for env, value in zip(self.envs, values, strict=True):
            setattr(env, name, value)

    def close(self) -> None:
        for env in self.envs:
            env.close()


def _worker(pipe, parent_pipe, factories, start, memory, space, num_envs, spin) -> None:
    """A worker process: builds its slice, then answers (command, data) until "close"."""
    parent_pipe.close()
    part = None
    try:
        buffer = read_from_shared_memory(space, memory, n=num_envs)
        part = Slice(factories.fn, start, buffer)
        pipe.send((True, None))
        while True:
            _wait(pipe, spin)
            command, data = pipe.recv()
            if command == "close":
                pipe.send((True, None))
                break
            try:
                result = getattr(part, command)(*data)
                pipe.send((True, result))
            except Exception as error:  # handed to the caller, raised there
                pipe.send((False, error))
    except (KeyboardInterrupt, EOFError):
        pass
    except Exception as error:
        pipe.send((False, error))
    finally:
        if part is not None:
            part.close()
        pipe.close()


class HostVectorEnv(gymnasium.vector.VectorEnv):
    """``num_envs`` copies of a host environment: this process steps the first slice, each of
    ``num_workers`` worker processes one more (0: every copy in this process).

    ``env_kwargs`` are the single adapter's arguments (contexts, selector, context observation…);
    ``num_workers=None`` uses every core this process may use, a worker per further core, as long as
    each slice keeps ``MIN_COPIES_PER_SLICE`` copies. Stepping a slice here, instead of waiting
    for one more worker, keeps this process busy while the workers step: no step waits for it to
    wake.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": ["rgb_array"]}

    def __init__(
        self, env_id: str, num_envs: int = 1, num_workers: int | None = None, **env_kwargs: Any
    ):
        self._local: Slice | None = None
        self._pipes: list = []
        self._processes: list = []
        check_count("num_envs", num_envs)
        if num_workers is None:
            num_workers = default_workers(num_envs)
        elif isinstance(num_workers, bool) or not isinstance(num_workers, (int, np.integer)):
            raise ValueError(f"num_workers must be an integer or None, got {num_workers!r}")
        elif not 0 <= num_workers < num_envs:
            raise ValueError(
                f"num_workers must lie in [0, num_envs - 1 = {num_envs - 1}] (this process steps "
                f"a slice too; 0: every copy here), got {num_workers}"
            )
        probe = ContextualGymEnv(env_id, **env_kwargs)  # every argument checked here, once
        probe.close()
        self.num_envs, self.num_workers = int(num_envs), int(num_workers)
        self.context_space = probe.context_space
        self.render_mode = probe.render_mode
        self.metadata = {**probe.metadata, **self.metadata}
        self.single_observation_space = probe.observation_space
        self.single_action_space = probe.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.check = action_check(self.single_action_space, self.num_envs)
        factories = [
            functools.partial(
                ContextualGymEnv, env_id, copy_index=i, num_copies=self.num_envs, **env_kwargs
            )
            for i in range(self.num_envs)
        ]
        self._standing: dict[str, Any] = {}  # every copy's context part of ``info``
        # The first slice is stepped here, the others by one worker each.
        self._slices = np.array_split(np.arange(self.num_envs), self.num_workers + 1)
        if self.num_workers == 0:
            self._buffer = create_empty_array(self.single_observation_space, self.num_envs)
        else:
            spawn = multiprocessing.get_context("spawn")  # JAX is multithreaded: never fork it
            memory = create_shared_memory(self.single_observation_space, self.num_envs, ctx=spawn)
            self._buffer = read_from_shared_memory(
                self.single_observation_space, memory, self.num_envs
            )
        polls = len(self._slices) <= len(os.sched_getaffinity(0))
        self._spin = _CALLER_SPIN if polls else 0.0
        for copies in self._slices[1:]:
            parent, child = spawn.Pipe()
            process = spawn.Process(
                target=_worker,
                name=f"contextrl-{env_id}-copies-{copies[0]}-{copies[-1]}",
                args=(
                    child,
                    parent,
                    CloudpickleWrapper([factories[i] for i in copies]),
                    int(copies[0]),
                    memory,
                    self.single_observation_space,
                    self.num_envs,
                    _WORKER_SPIN if polls else 0.0,
                ),
                daemon=True,
            )
            process.start()
            child.close()
            self._pipes.append(parent)
            self._processes.append(process)
        first = self._slices[0]
        self._local = Slice([factories[i] for i in first], 0, self._buffer)
        self._gather()  # every worker built its copies

    # ---- talking to the slices ------------------------------------------------------------------
    def _gather(self) -> list:
        """Each worker's answer, in slice order; the first error is raised once all answered."""
        answers, error = [], None
        for index, pipe in enumerate(self._pipes):
            try:
                _wait(pipe, self._spin)
                ok, value = pipe.recv()
            except EOFError:
                ok, value = False, self._stopped(index)
            if not ok and error is None:
                error = value
            answers.append(value)
        if error is not None:
            raise error
        return answers

    def _stopped(self, index: int) -> RuntimeError:
        process = self._processes[index]
        process.join(timeout=5)
        return RuntimeError(
            f"worker {index} of {self} stopped (exit code {process.exitcode}); a script that "
            "creates host vector envs with workers must do so under `if __name__ == '__main__':` "
            "(workers are spawned, and import the script)"
        )

    def _each(self, command: str, per_slice: Callable[[np.ndarray], tuple]) -> list:
        """Run ``command`` on every slice with arguments ``per_slice(copies)``, this process's slice
        while the workers run theirs; the answers in slice order."""
        for pipe, copies in zip(self._pipes, self._slices[1:], strict=True):
            pipe.send((command, per_slice(copies)))
        try:
            here = getattr(self._local, command)(*per_slice(self._slices[0]))
        finally:  # the workers' answers are read even when this slice failed: pipes stay in step
            answers = self._gather()
        return [here, *answers]

    def _observations(self) -> Any:
        return _copied(self._buffer)

    # ---- the vector API -------------------------------------------------------------------------
    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        """Reset every copy (copy ``i`` with seed ``seed + i``), or those in
        ``options["reset_mask"]``."""
        if seed is None or isinstance(seed, (int, np.integer)):
            seeds = [None if seed is None else int(seed) + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
            if len(seeds) != self.num_envs:
                raise ValueError(f"give one seed per copy ({self.num_envs}), got {len(seeds)}")
        options = dict(options or {})
        mask = options.pop("reset_mask", None)
        if mask is None:
            mask = np.ones(self.num_envs, np.bool_)
        elif (
            not isinstance(mask, np.ndarray)
            or mask.dtype != np.bool_
            or mask.shape != (self.num_envs,)
            or not mask.any()
        ):
            raise ValueError(
                f"options['reset_mask'] must be a boolean array of shape ({self.num_envs},) with "
                f"at least one True, got {mask!r}"
            )
        answers = self._each(
            "reset", lambda copies: ([seeds[i] for i in copies], options or None, mask[copies])
        )
        info: dict[str, Any] = {}
        standing = _deep_copy(self._standing) if self._standing else {}
        for copy, copy_info in (entry for answer in answers for entry in answer):
            self._add_info(info, copy_info, copy)
            self._add_info(standing, {k: copy_info[k] for k in _CONTEXT_KEYS}, copy)
        self._standing = standing
        return self._observations(), info

    def step(self, actions):
        actions = self.check(actions)
        answers = self._each("step", lambda copies: (actions[copies],))
        rewards = np.concatenate([answer[0] for answer in answers])
        terminated = np.concatenate([answer[1] for answer in answers])
        truncated = np.concatenate([answer[2] for answer in answers])
        ended = [event for answer in answers for event in answer[3]]
        if ended:  # the arrays handed out before stay as they were
            self._standing = _deep_copy(self._standing)
            for copy, _, _, new_info in ended:
                self._add_info(self._standing, {k: new_info[k] for k in _CONTEXT_KEYS}, copy)
        info = _nested_copy(self._standing)
        for answer, copies in zip(answers, self._slices, strict=True):
            if answer[4] is not None:
                for copy, facts in zip(copies, answer[4], strict=True):
                    self._add_info(info, facts, int(copy))
        for copy, final_obs, final_info, _ in ended:
            self._add_info(info, {"final_obs": final_obs, "final_info": final_info}, copy)
        return self._observations(), rewards, terminated, truncated, info

    def render(self) -> tuple | None:
        """Every copy's frame (``render_mode="rgb_array"``; None without a render mode)."""
        return None if self.render_mode is None else self.call("render")

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple:
        """``name`` of every copy (called with the arguments where it is a method)."""
        answers = self._each("call", lambda copies: (name, args, kwargs))
        return tuple(result for answer in answers for result in answer)

    def get_attr(self, name: str) -> tuple:
        return self.call(name)

    def set_attr(self, name: str, values: Any) -> None:
        """Set ``name`` on every copy: one value for all, or a list with one per copy."""
        if not isinstance(values, (list, tuple)):
            values = [values] * self.num_envs
        if len(values) != self.num_envs:
            raise ValueError(f"give one value per copy ({self.num_envs}), got {len(values)}")
        self._each("set_attr", lambda copies: (name, [values[i] for i in copies]))

    def close_extras(self, **kwargs: Any) -> None:
        if self._local is not None:
            self._local.close()
        for pipe in self._pipes:
            try:
                pipe.send(("close", ()))
            except (BrokenPipeError, OSError):
                pass
        for pipe in self._pipes:
            try:
                pipe.recv()
                pipe.close()
            except (EOFError, OSError):
                pass
        for process in self._processes:
            process.join(timeout=30)
            if process.is_alive():
                process.terminate()

    def __del__(self):
        if not getattr(self, "closed", True):
            self.close()


__all__ = ["HostVectorEnv", "default_workers"]
