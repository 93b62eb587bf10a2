"""Run PureJaxRL's own ``ppo.py`` on ``contextrl.gymnax``, with only ``import gymnax`` changed.

``purejaxrl/ppo.py`` and ``purejaxrl/wrappers.py`` are read from FOLDER (a checkout of
luchris429/purejaxrl), ``import gymnax`` becomes ``import contextrl.gymnax as gymnax`` (the five-value
step PureJaxRL is written for), and ``ppo.py`` runs as its ``__main__`` does: CartPole-v1, 500,000 steps,
its seed. Its episode returns are printed as it trains; the last line gives the first and last ten
episodes' mean. PureJaxRL's own imports (distrax, and navix through its wrappers) need folders of their
own; nothing is fetched here.

    git clone https://github.com/luchris429/purejaxrl /tmp/purejaxrl
    pip install --target /tmp/pjx --no-deps distrax chex toolz navix dm-tree decorator \\
        cloudpickle gast tfp-nightly rlax      # tensorflow_probability 0.25 fails under jax 0.10
    pip install --target /tmp/pjx-wandb wandb==0.22.3   # navix imports wandb
    .venv/bin/python tools/run_purejaxrl.py /tmp/purejaxrl --path /tmp/pjx --path /tmp/pjx-wandb
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
from pathlib import Path

RETURN = re.compile(r"episodic return=([-\d.]+)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a checkout of luchris429/purejaxrl")
    parser.add_argument("--path", action="append", default=[], help="a folder of its dependencies")
    args = parser.parse_args()
    source = args.folder / "purejaxrl"
    if not (source / "ppo.py").is_file():
        parser.error(f"folder {args.folder}: no purejaxrl/ppo.py; give a checkout of purejaxrl")
    with tempfile.TemporaryDirectory(prefix="purejaxrl-") as work:
        ppo = (source / "ppo.py").read_text(encoding="utf-8")
        changed = re.sub(r"^import gymnax$", "import contextrl.gymnax as gymnax", ppo, flags=re.M)
        (Path(work) / "ppo.py").write_text(changed, encoding="utf-8")
        (Path(work) / "wrappers.py").write_text((source / "wrappers.py").read_text("utf-8"))
        result = subprocess.run(
            [sys.executable, "ppo.py"],
            cwd=work,
            capture_output=True,
            text=True,
            env={**os.environ, "PYTHONPATH": os.pathsep.join(args.path)},
        )
    returns = [float(r) for r in RETURN.findall(result.stdout)]
    if result.returncode or not returns:
        print((result.stdout + result.stderr)[-3000:])
        return result.returncode or 1
    first, last = returns[:10], returns[-10:]
    print(
        f"PureJaxRL ppo.py on contextrl.gymnax: {len(returns)} episodes; mean return of the first "
        f"ten {sum(first) / len(first):.1f}, of the last ten {sum(last) / len(last):.1f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
