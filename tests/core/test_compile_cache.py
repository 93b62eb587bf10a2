"""contextrl's compilation cache: where it lives, that a process compiling with it on writes programs
there, that a cache the user chose wins, and ``contextrl cache`` shows and clears it.

Each case runs in a fresh process without the suite's own cache (``JAX_COMPILATION_CACHE_DIR``), so
the folder the library picks is the one observed and the suite's cache is never touched.
"""

import os
import subprocess
import sys

COMPILE = """
import jax, jax.numpy as jnp
from contextrl.compile_cache import use_compilation_cache
print(use_compilation_cache())
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
jax.jit(lambda x: jnp.sin(x) * 2)(jnp.ones(3)).block_until_ready()
"""


def run(args, tmp_path, **env):
    environment = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}
    environment |= {"HOME": str(tmp_path / "home"), "XDG_CACHE_HOME": "", **env}
    done = subprocess.run(args, env=environment, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


def test_programs_go_to_the_user_cache_folder(tmp_path):
    folder = tmp_path / "home" / ".cache" / "contextrl" / "jax"
    assert run([sys.executable, "-c", COMPILE], tmp_path) == str(folder)
    assert any(p.is_file() for p in folder.rglob("*"))


def test_contextrl_cache_dir_then_jax_own_variable_decide(tmp_path):
    mine = tmp_path / "mine"
    assert run([sys.executable, "-c", COMPILE], tmp_path, CONTEXTRL_CACHE_DIR=str(mine)) == str(
        mine / "jax"
    )
    theirs = tmp_path / "theirs"
    printed = run(
        [sys.executable, "-c", COMPILE],
        tmp_path,
        CONTEXTRL_CACHE_DIR=str(mine),
        JAX_COMPILATION_CACHE_DIR=str(theirs),
    )
    assert printed == str(theirs) and any(theirs.iterdir())


def test_cache_command_shows_and_clears(tmp_path):
    folder = tmp_path / "c" / "jax"
    run([sys.executable, "-c", COMPILE], tmp_path, CONTEXTRL_CACHE_DIR=str(tmp_path / "c"))
    files = sum(p.is_file() for p in folder.rglob("*"))
    command = [sys.executable, "-m", "contextrl", "cache"]
    shown = run(command, tmp_path, CONTEXTRL_CACHE_DIR=str(tmp_path / "c"))
    assert shown.startswith(f"{folder}: {files} files") and files > 0
    cleared = run([*command, "clear"], tmp_path, CONTEXTRL_CACHE_DIR=str(tmp_path / "c"))
    assert cleared.startswith(f"removed {files} files") and not folder.exists()
    assert (
        run(command, tmp_path, CONTEXTRL_CACHE_DIR=str(tmp_path / "c"))
        == f"{folder}: 0 files, 0.0 MB"
    )
