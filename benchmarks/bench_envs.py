"""Steps per second of batched contextual environments, every copy with its own context.

    python benchmarks/bench_envs.py [--gymnax] [--quick] [--markdown FILE]

Prints CartPole at batch sizes 1 … 65,536, the other classic-control environments at 4,096, and the cost
of choosing a new context at every reset (a context set with round robin, or resampling from a
distribution) against fixed per-copy contexts. ``--gymnax`` also measures gymnax's CartPole in the same
loop, in a separate virtual environment (.venv-gymnax, built on first use), and prints the ratio.
``--markdown FILE`` also writes the tables as Markdown, headed by the date, the machine, its load and the
command: `make bench` writes benchmarks/results/envs.md, which the documentation's benchmarks page
includes.
"""

import argparse
import datetime
import os
import pathlib
import platform
import shlex
import subprocess
import sys

import jax
from _scan import CORES, batched_rollout, observing, random_rollout, steps_per_second

import contextrl as crl

HERE = pathlib.Path(__file__).resolve().parent
GYMNAX_VENV = HERE.parent / ".venv-gymnax"
LENGTHS = {"length": crl.Uniform(0.25, 0.75)}
KEY = jax.random.key(0)


def fixed_contexts(env, n, spec):
    """Plain env.reset/env.step; each copy keeps its own context for the whole run."""
    contexts = crl.sample(env, spec, n, jax.random.key(0))
    return (*observing(env), contexts)


def contextual_rate(env, n, steps, contexts) -> float:
    """Steps/s of ``ContextualEnv.step_copies``: contexts chosen at every reset inside the loop.

    ``contexts``: a set (round robin; with ``n`` contexts copy i keeps context i) or a distribution spec.
    """
    contextual = crl.with_contexts(env, contexts)

    def reset_batch(key):
        state, ts = contextual.reset_copies(key, n)
        return state, ts.obs

    def step_batch(_, state, actions):  # every draw comes from the key given at reset
        state, ts = contextual.step_copies(state, actions)
        return state, ts.obs

    run = batched_rollout(reset_batch, step_batch, env.action_space.n, steps)
    return steps_per_second(run, n, steps)[1]


def measure(env, n, steps, make=fixed_contexts, devices=1, **kwargs):
    spec = LENGTHS if "length" in env.context_space.names else {}
    if not spec:
        name, f = next(iter(env.context_space.features.items()))
        spec = {name: crl.Uniform(f.lower, f.upper)}
    reset, step, params = make(env, n, spec, **kwargs)
    run = random_rollout(reset, step, env.action_space.sample, params, steps, devices)
    return steps_per_second(run, n, steps)


def gymnax_rate(copies: int, steps: int, devices: int, batched: bool = False) -> float:
    python = GYMNAX_VENV / "bin" / "python"
    if not python.exists():
        subprocess.run([sys.executable, "-m", "venv", str(GYMNAX_VENV)], check=True)
        subprocess.run(
            [
                str(python),
                "-m",
                "pip",
                "install",
                "-q",
                "jax==0.10.2",
                "jaxlib==0.10.2",
                "gymnax==1.0.1",
                "six==1.17.0",
            ],
            check=True,
        )
    out = subprocess.run(
        [
            str(python),
            str(HERE / "gymnax_cartpole.py"),
            "--copies",
            str(copies),
            "--steps",
            str(steps),
            "--devices",
            str(devices),
            *(["--batched"] if batched else []),
        ],
        check=True,
        capture_output=True,
        text=True,
        cwd=HERE,
    )
    return float(out.stdout.strip().splitlines()[-1])


def machine() -> str:
    """The CPU's model name and core count, as the benchmarks page states them."""
    model = platform.processor() or platform.machine()
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{model}, {CORES} core(s)"


def load() -> str:
    try:
        return f"{os.getloadavg()[0]:.1f}"
    except OSError:
        return "unknown"


def markdown(command: str, start_load: str, steps: int, sections) -> str:
    """The measured tables as Markdown, headed by when, where and how they were measured."""
    lines = [
        f"Measured {datetime.date.today().isoformat()} with `{command}` on {machine()}, load average "
        f"{start_load} at the start and {load()} at the end; jax {jax.__version__} on "
        f"{jax.devices()[0].platform}, {steps} random steps per copy (four times as many below 64 "
        "copies).",
    ]
    for title, header, rows in sections:
        lines += ["", f"**{title}**", "", "| " + " | ".join(header) + " |"]
        lines.append("|" + "|".join(" --- " for _ in header) + "|")
        lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gymnax", action="store_true", help="also measure gymnax CartPole")
    parser.add_argument("--quick", action="store_true", help="fewer batch sizes and steps")
    parser.add_argument("--markdown", metavar="FILE", help="also write the tables as Markdown")
    args = parser.parse_args()
    command = shlex.join(["python", "benchmarks/bench_envs.py", *sys.argv[1:]])
    start_load = load()
    steps = 200 if args.quick else 1000
    sizes_rows, env_rows, switch_rows, gymnax_rows = [], [], [], []
    print(f"jax {jax.__version__} on {jax.devices()[0].platform}, {steps} random steps per copy\n")

    cartpole = crl.make("CartPole")
    sizes = [1, 64, 4096] if args.quick else [1, 16, 256, 1024, 4096, 16384, 65536]
    print("CartPole, every copy its own pole length")
    print(f"{'copies':>8} {'compile s':>10} {'steps/s':>12}")
    for n in sizes:
        compile_s, rate = measure(cartpole, n, steps if n >= 64 else steps * 4)
        print(f"{n:>8} {compile_s:>10.2f} {rate:>12.3g}")
        sizes_rows.append((f"{n:,}", f"{compile_s:.2f}", f"{rate:.3g}"))

    if CORES > 1:
        compile_s, rate = measure(cartpole, 4096, steps, devices=CORES)
        print(f"{4096:>8} {compile_s:>10.2f} {rate:>12.3g}  split over {CORES} cores")
        sizes_rows.append((f"4,096 split over {CORES} cores", f"{compile_s:.2f}", f"{rate:.3g}"))

    print("\nEvery environment at 4,096 copies")
    print(f"{'env':>22} {'steps/s':>12}")
    for env_id in [i for i in crl.registered("classic_control")]:
        rate = measure(crl.make(env_id), 4096, steps)[1]
        print(f"{env_id:>22} {rate:>12.3g}")
        env_rows.append((env_id, f"{rate:.3g}"))

    print("\nContext switch at reset (CartPole, 4,096 copies)")
    fixed = measure(cartpole, 4096, steps)[1]
    rows = [
        ("fixed per-copy contexts", fixed),
        (
            "set of 64, round robin",
            contextual_rate(cartpole, 4096, steps, crl.sample(cartpole, LENGTHS, 64, KEY)),
        ),
        ("resampled every reset", contextual_rate(cartpole, 4096, steps, LENGTHS)),
    ]
    for label, rate in rows:
        print(f"{label:>28} {rate:>12.3g} steps/s  ({rate / fixed:.2f} × fixed)")
        switch_rows.append((label, f"{rate:.3g}", f"{rate / fixed:.2f}"))

    if args.gymnax:
        print("\ngymnax CartPole in the same loop, 4,096 copies each with its own pole length")
        for devices in sorted({1, CORES}):
            ours = measure(cartpole, 4096, steps, devices=devices)[1]
            theirs = gymnax_rate(4096, steps, devices)
            print(
                f"{devices} device(s), per-copy loop: gymnax {theirs:.3g} steps/s, contextrl "
                f"{ours:.3g} steps/s, contextrl / gymnax = {ours / theirs:.2f}"
            )
            gymnax_rows.append(
                (
                    f"per-copy loop, {devices} device(s)",
                    f"{theirs:.3g}",
                    f"{ours:.3g}",
                    f"{ours / theirs:.2f}",
                )
            )
        own = crl.sample(cartpole, LENGTHS, 4096, KEY)
        ours = contextual_rate(cartpole, 4096, steps, own)
        theirs = gymnax_rate(4096, steps, 1, batched=True)
        print(
            f"batched core (ContextualEnv.step_copies vs vmap of gymnax): gymnax {theirs:.3g} "
            f"steps/s, contextrl {ours:.3g} steps/s, contextrl / gymnax = {ours / theirs:.2f}"
        )
        gymnax_rows.append(
            (
                "batched core (`step_copies`) vs gymnax's vmap",
                f"{theirs:.3g}",
                f"{ours:.3g}",
                f"{ours / theirs:.2f}",
            )
        )

    if args.markdown:
        sections = [
            (
                "CartPole, every copy its own pole length (`jit(vmap(env.step))`, a key per copy per step)",
                ("copies", "compile s", "steps/s"),
                sizes_rows,
            ),
            ("Every classic-control environment at 4,096 copies", ("env", "steps/s"), env_rows),
            (
                "Choosing the context at every reset (`ContextualEnv.step_copies`, CartPole, 4,096 copies)",
                ("contexts", "steps/s", "× fixed"),
                switch_rows,
            ),
        ]
        if gymnax_rows:
            sections.append(
                (
                    "gymnax 1.0.1's CartPole in the same loops, 4,096 copies",
                    ("loop", "gymnax steps/s", "contextrl steps/s", "contextrl / gymnax"),
                    gymnax_rows,
                )
            )
        out = pathlib.Path(args.markdown)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(markdown(command, start_load, steps, sections))
        print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
