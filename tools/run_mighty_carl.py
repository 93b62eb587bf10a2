"""Run Mighty's CARL code against ``contextrl.carl``, with only the import changed.

Mighty (``mighty-rl`` 1.0.1, the CARL authors' agent library) reaches CARL in two places: its environment
factory ``mighty/mighty_utils/envs.py:make_carl_env`` (context distributions from the config, a
``ContextSampler`` reseeded between the training and evaluation sets, selectors, the environment wrapped
in its ``CARLVectorEnvSimulator``) and its example ``examples/sample_carl_context_sets.py``. Both are read
from FOLDER (the unpacked wheel), ``carl`` becomes ``contextrl.carl``, and they run here: the factory on
two configurations written here and on the one CARL configuration Mighty ships
(``configs/environment/carl_walkers/ant_goals.yaml``: Brax Ant with sampled goals), its training
environment stepped for 600 random actions through Mighty's wrapper, the evaluation one reset; the example writes its context sets to JSON. (A string ``context_selector`` in the
configuration fails on CARL 1.1.1 itself, which builds the evaluation environment before turning the
string into a selector, so none is given.) With ``--original`` and CARL's interpreter, the same code runs
unchanged against CARL 1.1.1, for comparison. Mighty's package ``__init__`` files are
replaced by empty ones (they import its agents: torch and hydra); its agents cannot run on this
interpreter at all, because Mighty pins gymnasium < 1 and numpy < 2. Nothing is fetched.

    pip download --no-deps mighty-rl==1.0.1 && unzip mighty_rl-1.0.1-py3-none-any.whl -d /tmp/mighty
    pip install --target /tmp/mighty-deps --no-deps omegaconf==2.3.0 antlr4-python3-runtime==4.9.3
    .venv/bin/python tools/run_mighty_carl.py /tmp/mighty --path /tmp/mighty-deps
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from run_carl_suite import rewrite

# Mighty's make_carl_env on two configurations as its YAML configs spell them, then its wrapper stepped.
FACTORY = """
import importlib.util
import json
import numpy as np
from omegaconf import OmegaConf
from mighty.mighty_utils.envs import make_carl_env

configs = [
    {"env": "CARLCartPole", "n_episodes_eval": 2, "env_kwargs": {
        "num_contexts": 8, "num_evaluation_contexts": 4,
        "context_feature_args": {"gravity": ["uniform-float", 5.0, 15.0],
                                 "length": ["normal", 0.5, 0.1, 0.3, 0.7]}}},
    {"env": "CARLPendulum", "n_episodes_eval": 1, "env_kwargs": {
        "context_feature_args": {"m": ["uniform-float", 0.5, 1.5]}}},
]
if importlib.util.find_spec("brax"):  # Mighty's own configuration, with Brax installed
    shipped = OmegaConf.load("mighty/configs/environment/carl_walkers/ant_goals.yaml")
    configs.append({"env": shipped.env, "n_episodes_eval": 1, "env_kwargs": shipped.env_kwargs})
for config in configs:
    env, make_eval_env, eval_default = make_carl_env(OmegaConf.create(config))
    rng = np.random.default_rng(0)
    obs, info = env.reset(seed=0)
    ends = 0
    for _ in range(600):
        action = np.array([env.single_action_space.sample()])
        obs, reward, terminated, truncated, info = env.step(action)
        ends += int(terminated[0] or truncated[0])
    eval_env = make_eval_env()
    eval_obs, _ = eval_env.reset(seed=1)
    inner = env.envs[0]
    print(json.dumps({"env": config["env"], "episodes_ended": ends, "contexts": len(inner.contexts),
                      "eval_episodes": eval_default, "obs_keys": sorted(obs[0]),
                      "first_context": inner.contexts[0]}))
"""


def prepared(folder: Path, work: Path, original: bool) -> None:
    """Mighty's envs.py and wrappers.py (``carl`` rewritten unless ``original``) under empty package
    files, and its example."""

    def changed(text: str) -> str:
        return text if original else rewrite(text)

    package = work / "mighty" / "mighty_utils"
    package.mkdir(parents=True)
    (work / "mighty" / "__init__.py").write_text("")
    (package / "__init__.py").write_text("")
    for name in ("envs.py", "wrappers.py"):
        text = (folder / "mighty" / "mighty_utils" / name).read_text(encoding="utf-8")
        (package / name).write_text(changed(text), encoding="utf-8")
    configs = work / "mighty" / "configs" / "environment" / "carl_walkers"
    configs.mkdir(parents=True)
    shipped = folder / "mighty" / "configs" / "environment" / "carl_walkers" / "ant_goals.yaml"
    (configs / "ant_goals.yaml").write_text(shipped.read_text(encoding="utf-8"))
    example = (folder / "examples" / "sample_carl_context_sets.py").read_text(encoding="utf-8")
    (work / "sample_carl_context_sets.py").write_text(changed(example))
    (work / "factory.py").write_text(FACTORY)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="the unpacked mighty-rl 1.0.1 wheel")
    parser.add_argument("--path", action="append", default=[], help="a folder with omegaconf")
    parser.add_argument("--python", default=sys.executable, help="the interpreter to run them with")
    parser.add_argument("--original", action="store_true", help="keep ``carl`` (run against CARL)")
    args = parser.parse_args()
    if not (args.folder / "mighty" / "mighty_utils" / "envs.py").is_file():
        parser.error(
            f"folder {args.folder}: no mighty/mighty_utils/envs.py; unpack mighty-rl 1.0.1"
        )
    failures = 0
    with tempfile.TemporaryDirectory(prefix="mighty-carl-") as work:
        prepared(args.folder, Path(work), args.original)
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([work, *args.path])}
        env["PYTHONWARNINGS"] = "ignore"
        for script in ("factory.py", "sample_carl_context_sets.py"):
            result = subprocess.run(
                [str(Path(args.python).absolute()), script],
                cwd=work,
                capture_output=True,
                text=True,
                env=env,
            )
            failures += result.returncode != 0
            lines = (result.stdout + result.stderr).strip().splitlines()
            print(f"{script}: {'ran' if result.returncode == 0 else 'FAILED'}")
            for line in lines[-4:] if result.returncode else lines:
                print(f"  {line}")
        written = sorted(p.name for p in Path(work).rglob("context_sets/*.json"))
        print(f"  context sets written: {written}")
    target = "CARL 1.1.1" if args.original else "contextrl.carl"
    print(f"Mighty's CARL code on {target}: {2 - failures} of 2 ran")
    return 1 if failures else 0


if __name__ == "__main__":
    raise SystemExit(main())
