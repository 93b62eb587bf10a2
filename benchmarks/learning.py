"""The agents beside the libraries a user would pick instead: final return at equal budgets, curves, time.

    python benchmarks/learning.py --purejaxrl FOLDER [--seeds 5] [--only ppo_cartpole]

Each row trains the same environment for the same number of environment steps with the same settings
(stated per row) in every library, ``--seeds`` seeds each, every library in a process of its own: the
project's agents and Stable-Baselines3 in the project's environment (SB3 is the ``sb3`` extra, and it
trains on the project's gymnasium id), PureJaxRL in ``.venv-purejaxrl``, created here on first use with
the project's pins of JAX, flax, optax, gymnax and brax (its code is not on PyPI: FOLDER is a checkout
of luchris429/purejaxrl, whose ``purejaxrl/ppo.py`` is imported unchanged and its ``make_train``
called). The final return is the deterministic policy's mean over 10 episodes at the default context
(the greedy action), one value per seed; the table gives their IQM with a 95% interval over seeds
(``contextrl.analysis``), the wall time of the whole run with compilation, and steps per second
(seeds × steps / wall time; the JAX libraries train their seeds in one vmapped call, SB3 one after
another). The curves are the mean return of the training episodes that ended in each update, the
median over seeds with the band from the lowest to the highest seed.

Prints the table and writes it to ``--markdown`` (benchmarks/results/learning.md), each row's raw
runs beside it (``learning_<row>.json``: per seed the final return and the curve) and its curves to
docs/images/learning_<row>.png; the agents page shows them. ``--libraries`` runs some of a row's
libraries only (``--libraries contextrl PureJaxRL --seeds 16``: the JAX ones at more seeds).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import pathlib
import shlex
import string
import subprocess
import sys

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from _peers import ROOT  # noqa: E402

# PureJaxRL's own requirements (its requirements.txt; navix imports wandb) at the project's pins
# (constraints.txt: JAX, flax, optax, gymnax, brax). distrax goes in without its dependencies and
# on tensorflow-probability's nightly: the release fails under this JAX (tools/run_purejaxrl.py).
PUREJAXRL_VENV = ".venv-purejaxrl"
PUREJAXRL_REQUIREMENTS = (
    ("jax", "jaxlib", "flax", "optax", "gymnax", "brax", "navix", "wandb", "chex", "dm-tree"),
    ("--no-deps", "distrax", "tfp-nightly", "decorator", "cloudpickle", "gast"),
)
PUREJAXRL_PROBE = "import distrax, gymnax, brax, navix, flax, optax"


def purejaxrl_python() -> pathlib.Path:
    """The interpreter of PureJaxRL's environment, created on first use."""
    python = ROOT / PUREJAXRL_VENV / "bin" / "python"
    probe = [str(python), "-c", PUREJAXRL_PROBE]
    if python.exists() and subprocess.run(probe, capture_output=True).returncode == 0:
        return python
    print(f"preparing {PUREJAXRL_VENV} (once)...", file=sys.stderr)
    if not python.exists():
        subprocess.run([sys.executable, "-m", "venv", str(ROOT / PUREJAXRL_VENV)], check=True)
    for group in PUREJAXRL_REQUIREMENTS:
        pip = [str(python), "-m", "pip", "install", "-q", "-c", str(ROOT / "constraints.txt")]
        subprocess.run([*pip, *group], check=True)
    subprocess.run(probe, check=True)
    return python


# Every library's XLA runs with the setting contextrl's runner applies (contextrl.xla_flags): without
# it, jaxlib 0.10's concurrency-optimised CPU scheduler can wedge a vmapped training program forever,
# every pool thread idle (PureJaxRL's five vmapped seeds did, here).
XLA_FLAGS = "--xla_cpu_enable_concurrency_optimized_scheduler=false"

# PureJaxRL's ppo.py defaults (its __main__ config): the settings every PPO row shares.
PPO_SETTINGS = {
    "learning_rate": 2.5e-4,
    "num_envs": 4,
    "num_steps": 128,
    "update_epochs": 4,
    "num_minibatches": 4,
    "gamma": 0.99,
    "gae_lambda": 0.95,
    "clip_eps": 0.2,
    "ent_coef": 0.01,
    "vf_coef": 0.5,
    "max_grad_norm": 0.5,
    "anneal_lr": True,
}

# contextrl's run: the agent's seeds in one compiled call, then each seed's final return. $env is the
# environment, $agent the module, $config the lines that build ``config`` from steps and settings.
OURS = string.Template("""
import json, sys, time
import jax, numpy as np
from contextrl.xla_flags import xla_cpu_workaround
xla_cpu_workaround()
import contextrl as crl
from contextrl.agents import evaluate, $agent
steps, seeds, settings = int(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3])
env = crl.make("$env")
context = env.default_context()
$config
start = time.perf_counter()
train = jax.jit(jax.vmap($agent.make_train(config, env, context)))
result = jax.block_until_ready(train(jax.random.split(jax.random.key(0), seeds)))
wall = time.perf_counter() - start
policy = $agent.make_policy(config, env, context)
final = jax.jit(jax.vmap(lambda params, key: evaluate(policy, params, env, context, 10, key)))(
    result.params, jax.random.split(jax.random.key(1), seeds))
curves = np.asarray(result.metrics["episode_return"], float)
print(json.dumps({"final": np.asarray(final).reshape(seeds).tolist(), "wall_s": wall,
                  "steps": np.asarray(result.metrics["step"])[0].tolist(),
                  "curves": np.where(np.isfinite(curves), curves, None).tolist()}))
""")

OURS_PPO = OURS.substitute(
    env="CartPole",
    agent="ppo",
    config="config = ppo.PPOConfig(total_timesteps=steps, hidden_sizes=(64, 64), activation='tanh', "
    "**settings)",
)

PUREJAXRL_PPO = """
import json, sys, time
import jax, jax.numpy as jnp, numpy as np
folder, steps, seeds, settings = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), json.loads(sys.argv[4])
sys.path.insert(0, folder + "/purejaxrl")
import gymnax
import ppo as purejaxrl  # PureJaxRL's own module, unchanged
names = {"learning_rate": "LR", "num_envs": "NUM_ENVS", "num_steps": "NUM_STEPS",
         "update_epochs": "UPDATE_EPOCHS", "num_minibatches": "NUM_MINIBATCHES", "gamma": "GAMMA",
         "gae_lambda": "GAE_LAMBDA", "clip_eps": "CLIP_EPS", "ent_coef": "ENT_COEF",
         "vf_coef": "VF_COEF", "max_grad_norm": "MAX_GRAD_NORM", "anneal_lr": "ANNEAL_LR"}
config = {names[k]: v for k, v in settings.items()}
config.update({"TOTAL_TIMESTEPS": steps, "ACTIVATION": "tanh", "ENV_NAME": "CartPole-v1",
               "DEBUG": False})
start = time.perf_counter()
train = jax.jit(jax.vmap(purejaxrl.make_train(config)))
out = jax.block_until_ready(train(jax.random.split(jax.random.PRNGKey(0), seeds)))
wall = time.perf_counter() - start
env, env_params = gymnax.make("CartPole-v1")
network = purejaxrl.ActorCritic(env.action_space(env_params).n, activation="tanh")
params = out["runner_state"][0].params

def episode(params, key):
    # the greedy action until the first end (gymnax resets inside step; later rewards are ignored)
    reset_key, key = jax.random.split(key)
    obs, state = env.reset(reset_key, env_params)
    def step(carry, step_key):
        obs, state, total, alive = carry
        pi, _ = network.apply(params, obs)
        obs, state, reward, done, _ = env.step(step_key, state, jnp.argmax(pi.logits), env_params)
        return (obs, state, total + reward * alive, alive * (1.0 - done)), None
    carry = (obs, state, jnp.float32(0.0), jnp.float32(1.0))
    (_, _, total, _), _ = jax.lax.scan(step, carry, jax.random.split(key, env_params.max_steps_in_episode))
    return total

def final_return(params, key):
    return jax.vmap(lambda k: episode(params, k))(jax.random.split(key, 10)).mean()

final = jax.jit(jax.vmap(final_return))(params, jax.random.split(jax.random.PRNGKey(1), seeds))
metrics = out["metrics"]  # per seed, update, step and copy
ended = np.asarray(metrics["returned_episode"], bool)
returns = np.asarray(metrics["returned_episode_returns"], float)
count = ended.sum(axis=(2, 3))
curves = np.where(count > 0, (returns * ended).sum(axis=(2, 3)) / np.maximum(count, 1), np.nan)
batch = config["NUM_ENVS"] * config["NUM_STEPS"]
print(json.dumps({"final": np.asarray(final).reshape(seeds).tolist(), "wall_s": wall,
                  "steps": [batch * (i + 1) for i in range(curves.shape[1])],
                  "curves": np.where(np.isfinite(curves), curves, None).tolist()}))
"""

# Stable-Baselines3's final return: the deterministic policy's mean over 10 episodes.
SB3_GREEDY = """def greedy_return(model, env_id, seed):
    env = gymnasium.make(env_id)
    discrete = not env.action_space.shape
    returns = []
    for episode in range(10):
        obs, _ = env.reset(seed=seed * 100 + episode)
        total, done = 0.0, False
        while not done:
            action, _ = model.predict(obs, deterministic=True)
            obs, reward, terminated, truncated, _ = env.step(int(action) if discrete else action)
            total += reward
            done = terminated or truncated
        returns.append(total)
    return float(np.mean(returns))
"""

SB3_PPO = string.Template("""
ENV_ID = "contextrl/CartPole-v0"
import json, sys, time
import gymnasium, numpy as np, torch
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.env_util import make_vec_env
import contextrl  # registers contextrl/CartPole-v0
steps, seeds, settings = int(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3])
torch.set_num_threads(1)

class Episodes(BaseCallback):
    # the mean return of the training episodes that ended in each rollout
    def _on_rollout_end(self):
        ended = [info["r"] for info in self.model.ep_info_buffer][-self.new:] if self.new else []
        self.rows.append((self.num_timesteps, float(np.mean(ended)) if ended else None))
    def _on_rollout_start(self):
        self.new = 0
    def _on_step(self):
        self.new += int(np.sum(self.locals["dones"]))
        return True

$greedy
batch = settings["num_envs"] * settings["num_steps"]
start_lr = settings["learning_rate"]
schedule = (lambda remaining: remaining * start_lr) if settings["anneal_lr"] else start_lr
final, curves, wall = [], [], 0.0
for seed in range(seeds):
    start = time.perf_counter()
    envs = make_vec_env("contextrl/CartPole-v0", n_envs=settings["num_envs"], seed=seed)
    model = PPO("MlpPolicy", envs, n_steps=settings["num_steps"],
                batch_size=batch // settings["num_minibatches"], n_epochs=settings["update_epochs"],
                learning_rate=schedule, gamma=settings["gamma"], gae_lambda=settings["gae_lambda"],
                clip_range=settings["clip_eps"], ent_coef=settings["ent_coef"],
                vf_coef=settings["vf_coef"], max_grad_norm=settings["max_grad_norm"],
                policy_kwargs={"net_arch": [64, 64], "activation_fn": torch.nn.Tanh},
                seed=seed, device="cpu")
    log = Episodes()
    log.rows = []
    model.learn(total_timesteps=steps, callback=log)
    wall += time.perf_counter() - start
    final.append(greedy_return(model, ENV_ID, seed))
    curves.append([value for _, value in log.rows])
    steps_axis = [step for step, _ in log.rows]
print(json.dumps({"final": final, "wall_s": wall, "steps": steps_axis, "curves": curves}))
""").substitute(greedy=SB3_GREEDY)


# Stable-Baselines3's SAC defaults where both libraries have the setting (one learning rate for actor,
# critics and temperature; an actor update every gradient step; the entropy target -dim(A)), with
# 1,000 warm-up steps and a 100,000-transition buffer.
SAC_SETTINGS = {
    "learning_rate": 3e-4,
    "buffer_size": 100_000,
    "learning_starts": 1_000,
    "batch_size": 256,
    "tau": 0.005,
    "gamma": 0.99,
    "log_every": 1_000,
    "torch_threads": 2,  # SB3's torch on both cores, as XLA runs
}

OURS_SAC = OURS.substitute(
    env="Pendulum",
    agent="sac",
    config="""rate = settings.pop("learning_rate")
settings.pop("torch_threads")
config = sac.SACConfig(total_timesteps=steps, num_envs=1, hidden_sizes=(256, 256), activation="relu",
                       policy_lr=rate, q_lr=rate, policy_frequency=1, autotune=True, **settings)""",
)

SB3_SAC = string.Template("""
ENV_ID = "contextrl/Pendulum-v0"
import json, sys, time
import gymnasium, numpy as np, torch
from stable_baselines3 import SAC
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor
import contextrl  # registers contextrl/Pendulum-v0
steps, seeds, settings = int(sys.argv[1]), int(sys.argv[2]), json.loads(sys.argv[3])
torch.set_num_threads(int(settings.pop("torch_threads")))
every = settings.pop("log_every")

class Episodes(BaseCallback):
    # each training episode's return and the step it ended at
    def _on_step(self):
        for info in self.locals["infos"]:
            if "episode" in info:
                self.ended.append((self.num_timesteps, info["episode"]["r"]))
        return True

$greedy
edges = list(range(every, steps + 1, every))
final, curves, wall = [], [], 0.0
for seed in range(seeds):
    start = time.perf_counter()
    env = Monitor(gymnasium.make("contextrl/Pendulum-v0"))
    model = SAC("MlpPolicy", env, policy_kwargs={"net_arch": [256, 256]}, seed=seed, device="cpu",
                **settings)
    log = Episodes()
    log.ended = []
    model.learn(total_timesteps=steps, callback=log)
    wall += time.perf_counter() - start
    final.append(greedy_return(model, ENV_ID, seed))
    curve = []
    for edge in edges:  # the mean return of the episodes that ended in each logging period
        inside = [r for step, r in log.ended if edge - every < step <= edge]
        curve.append(float(np.mean(inside)) if inside else None)
    curves.append(curve)
print(json.dumps({"final": final, "wall_s": wall, "steps": edges, "curves": curves}))
""").substitute(greedy=SB3_GREEDY)


@dataclasses.dataclass(frozen=True)
class Library:
    """One library's run of a row: a script that takes steps, seeds and the settings as JSON (after
    the PureJaxRL checkout, for its runs) and prints one JSON line: each seed's final return, the
    wall time, and the training curves."""

    name: str
    script: str
    needs_purejaxrl: bool = False  # runs in PureJaxRL's environment, on its checkout


@dataclasses.dataclass(frozen=True)
class Row:
    title: str
    steps: int
    settings: dict
    libraries: tuple[Library, ...]
    note: str


ROWS = {
    "ppo_cartpole": Row(
        "PPO, CartPole",
        200_000,
        PPO_SETTINGS,
        (
            Library("contextrl", OURS_PPO),
            Library("PureJaxRL", PUREJAXRL_PPO, needs_purejaxrl=True),
            Library("Stable-Baselines3", SB3_PPO),
        ),
        "PureJaxRL's ppo.py settings in every library: 4 copies × 128 steps, 4 epochs of 4 "
        "minibatches, learning rate 2.5e-4 annealed to 0, entropy 0.01, 64×64 tanh networks; "
        "gymnax's CartPole-v1 for PureJaxRL, contextrl/CartPole-v0 at the default context (the "
        "same dynamics, 500 steps) for the others; SB3's torch on one thread",
    ),
    "sac_pendulum": Row(
        "SAC, Pendulum",
        10_000,
        SAC_SETTINGS,
        (Library("contextrl", OURS_SAC), Library("Stable-Baselines3", SB3_SAC)),
        "Stable-Baselines3's SAC settings in both: one learning rate 3e-4 for actor, critics and "
        "the temperature (tuned towards entropy -1), an actor update every step, batch 256, "
        "τ 0.005, γ 0.99, 256×256 ReLU networks, one copy; 1,000 warm-up steps, a 100,000-step "
        "buffer; contextrl/Pendulum-v0 at the default context (200-step episodes); torch on both cores",
    ),
}


def run_library(library: Library, row: Row, seeds: int, purejaxrl: pathlib.Path | None) -> dict:
    python = purejaxrl_python() if library.needs_purejaxrl else pathlib.Path(sys.executable)
    arguments = [str(row.steps), str(seeds), json.dumps(row.settings)]
    if library.needs_purejaxrl:
        arguments.insert(0, str(purejaxrl))
    result = subprocess.run(
        [str(python), "-c", library.script, *arguments],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONWARNINGS": "ignore", "XLA_FLAGS": XLA_FLAGS},
        cwd=ROOT,
    )
    if result.returncode:
        raise RuntimeError(f"{library.name}: {result.stderr.strip()[-2000:]}")
    return json.loads(result.stdout.strip().splitlines()[-1])


def summary(final: list[float], seed: int) -> str:
    """IQM of the per-seed final returns with its 95% interval over seeds."""
    from contextrl.analysis import SEEDS, aggregate_iqm, bootstrap_ci

    interval = bootstrap_ci(np.asarray(final, float)[:, None], aggregate_iqm, unit=SEEDS, seed=seed)
    return str(interval)


def smoothed(curves: np.ndarray) -> np.ndarray:
    """Each seed's curve averaged over a window of about 1/20 of training (an update's mean return
    is noisy), skipping updates in which no episode ended."""
    import pandas as pd

    window = max(1, curves.shape[1] // 20)
    return pd.DataFrame(curves.T).rolling(window, min_periods=1).mean().to_numpy().T


def draw(path: pathlib.Path, row: Row, runs: dict[str, dict]) -> pathlib.Path:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.ticker import FuncFormatter

    figure = Figure(figsize=(5.5, 3.4), layout="constrained")
    axes = figure.add_subplot()
    for library, run in runs.items():
        steps = np.asarray(run["steps"], float)
        curves = smoothed(np.asarray(run["curves"], float))  # None became NaN: nothing ended
        axes.fill_between(steps, np.nanmin(curves, 0), np.nanmax(curves, 0), alpha=0.2, lw=0)
        axes.plot(steps, np.nanmedian(curves, 0), lw=1.5, label=library)
    seeds = len(next(iter(runs.values()))["final"])
    axes.set_title(f"{row.title}: training return ({seeds} seeds)", fontsize=10)
    axes.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x / 1000:g}k"))
    axes.set_xlabel("environment steps")
    axes.set_ylabel("episode return")
    axes.grid(alpha=0.3)
    axes.legend(fontsize=8)
    path.parent.mkdir(parents=True, exist_ok=True)
    FigureCanvasAgg(figure).print_png(str(path))
    return path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--only", nargs="+", choices=list(ROWS), default=list(ROWS))
    parser.add_argument("--libraries", nargs="+", help="only these libraries (default: every one)")
    parser.add_argument("--purejaxrl", type=pathlib.Path, help="a checkout of luchris429/purejaxrl")
    parser.add_argument("--markdown", default=str(ROOT / "benchmarks" / "results" / "learning.md"))
    args = parser.parse_args()
    chosen = {
        name: [lib for lib in ROWS[name].libraries if lib.name in (args.libraries or [lib.name])]
        for name in args.only
    }
    if any(lib.needs_purejaxrl for libs in chosen.values() for lib in libs) and not (
        args.purejaxrl and (args.purejaxrl / "purejaxrl" / "ppo.py").is_file()
    ):
        parser.error("--purejaxrl: give a checkout of luchris429/purejaxrl (purejaxrl/ppo.py)")
    markdown = pathlib.Path(args.markdown)
    command = shlex.join(["python", "benchmarks/learning.py", *sys.argv[1:]])
    start_load = f"{os.getloadavg()[0]:.1f}"
    lines = []
    for name, libraries in chosen.items():
        row = ROWS[name]
        runs = {}
        for library in libraries:
            runs[library.name] = run_library(library, row, args.seeds, args.purejaxrl)
            final = runs[library.name]["final"]
            print(f"{row.title}, {library.name}: final {np.round(final, 1).tolist()}", flush=True)
        raw = markdown.with_name(f"{markdown.stem}_{name}.json")
        raw.write_text(json.dumps(runs) + "\n")
        image = draw(ROOT / "docs" / "images" / f"{markdown.stem}_{name}.png", row, runs)
        print(f"wrote {raw} and {image}")
        ours = runs.get("contextrl", {}).get("wall_s")
        lines += [
            f"**{row.title}, {row.steps:,} steps, {args.seeds} seeds.** {row.note}.",
            "",
            "| library | final return, IQM (95% CI over seeds) | per seed | wall time | steps/s | "
            "its time / contextrl's |",
            "| --- | --- | --- | --- | --- | --- |",
        ]
        for library, run in runs.items():
            rate = args.seeds * row.steps / run["wall_s"]
            per_seed = ", ".join(f"{v:.0f}" for v in run["final"])
            ratio = f"{run['wall_s'] / ours:.2f}" if ours else "–"
            lines.append(
                f"| {library} | {summary(run['final'], 0)} | {per_seed} | "
                f"{run['wall_s']:.0f} s | {rate:,.0f} | {ratio} |"
            )
        lines.append("")
    cpu = next(
        (
            line.split(":", 1)[1].strip()
            for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines()
            if line.startswith("model name")
        ),
        "CPU",
    )
    header = (
        f"Measured {datetime.date.today().isoformat()} with `{command}` on {cpu}, {os.cpu_count()} "
        f"core(s), load average {start_load} at the start and {os.getloadavg()[0]:.1f} at the end."
    )
    text = "\n".join([header, "", *lines])
    print(text)
    markdown.write_text(text)
    print(f"wrote {markdown}")


if __name__ == "__main__":
    main()
