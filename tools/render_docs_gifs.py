"""Render the animations the family pages show: `make docs-gifs` (or `python tools/render_docs_gifs.py
[Id ...]`) writes docs/images/<Id>.gif with `contextrl render`, each one the same random actions under
two or three contexts side by side. The docs build (tools/docs_hooks.py) shows an environment's GIF
under its feature table when the file exists.

Only environments whose frames compress well are listed: MuJoCo's shaded frames (dm_control, Brax) make
GIFs of megabytes, so those pages show no animation; `contextrl render DmcWalker --grid gravity=2,9.81`
draws one locally.
"""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "docs" / "images"

# environment id -> (grid argument, steps)
GIFS = {
    "CartPole": ("length=0.25,0.5,1.0", 100),
    "Pendulum": ("l=0.5,1.0,1.5", 100),
    "MountainCar": ("goal_position=0.2,0.5", 100),
    "MountainCarContinuous": ("gravity=0.0015,0.0035", 100),
    "Acrobot": ("LINK_LENGTH_1=0.5,1.0,1.5", 100),
    "LunarLander": ("GRAVITY_Y=-1.63,-10,-23.1", 100),
    "LunarLanderContinuous": ("wind_power=0,20", 100),
    "BipedalWalker": ("hardcore=off,on", 100),
    "RnaDesign": ("dataset=eterna100_v2,rfam_taneda", 40),
}


def main(ids: list[str]) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    for env_id in ids or list(GIFS):
        grid, steps = GIFS[env_id]
        command = ["contextrl", "render", env_id, "--grid", grid, "--steps", str(steps)]
        subprocess.run([*command, "--out", str(OUT / f"{env_id}.gif")], check=True)


if __name__ == "__main__":
    main(sys.argv[1:])
