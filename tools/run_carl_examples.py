"""Run CARL's examples against ``contextrl.carl``, with only the import changed.

Each example is read from FOLDER/examples (a checkout of automl/CARL, tag v1.1.1): a script as it is, a
notebook as its code cells in order (IPython's ``%``/``!`` lines left out). ``carl.`` becomes
``contextrl.carl.`` and nothing else changes; each runs in a fresh interpreter with no screen (Matplotlib's
Agg backend, SDL's dummy video driver), so an example whose point is a window is run where it only draws
into memory. Nothing is fetched.

    git clone --depth 1 --branch v1.1.1 https://github.com/automl/CARL /tmp/carl
    .venv/bin/python tools/run_carl_examples.py /tmp/carl [NAME ...]

It prints one line per example (ran, or the error it stopped on) and a last line with the count; the
migration guide (docs/migration-carl.md) records them.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from run_carl_suite import rewrite

# A window (render_mode "human") opens on SDL's dummy driver, or, for a host environment, becomes
# frames. demo_carracing steers by the keyboard, so it is left out; carl_with_sb3 ends by showing frames through OpenCV's window, which needs a
# screen, so it runs up to that loop (training and evaluation).
NEEDS_KEYBOARD = {"demo_carracing.py"}
ENDS_IN_A_WINDOW = {"carl_with_sb3.py": "# Enjoy trained agent"}


def source_of(path: Path) -> str:
    """The Python an example runs: a script's text, or a notebook's code cells joined in order."""
    if path.suffix != ".ipynb":
        return path.read_text(encoding="utf-8")
    cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
    code = ["".join(cell["source"]) for cell in cells if cell["cell_type"] == "code"]
    magic = ("%", "!")
    lines = [
        line for cell in code for line in cell.splitlines() if not line.lstrip().startswith(magic)
    ]
    return "\n".join(lines) + "\n"


def run_example(path: Path, work: Path, timeout: float) -> tuple[bool, str, float]:
    """Run one example with the import changed; (ran, last error line, seconds)."""
    script = work / (path.stem + ".py")
    source = source_of(path)
    if path.name in ENDS_IN_A_WINDOW:
        source = source[: source.index(ENDS_IN_A_WINDOW[path.name])]
    script.write_text(rewrite(source), encoding="utf-8")
    screenless = {"MPLBACKEND": "Agg", "SDL_VIDEODRIVER": "dummy", "SDL_AUDIODRIVER": "dummy"}
    start = time.perf_counter()
    try:
        result = subprocess.run(
            [sys.executable, script.name],
            cwd=work,
            capture_output=True,
            text=True,
            timeout=timeout,
            env={**os.environ, **screenless, "PYTHONWARNINGS": "ignore"},
        )
    except subprocess.TimeoutExpired:
        return False, f"still running after {timeout:.0f} s", time.perf_counter() - start
    seconds = time.perf_counter() - start
    errors = [line for line in result.stderr.splitlines() if line and not line.startswith(" ")]
    return result.returncode == 0, (errors[-1] if errors else ""), seconds


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a checkout of automl/CARL (tag v1.1.1)")
    parser.add_argument("names", nargs="*", help="only these examples (file names)")
    parser.add_argument("--timeout", type=float, default=900.0, help="seconds per example")
    args = parser.parse_args()
    examples = sorted((args.folder / "examples").glob("*.py")) + sorted(
        (args.folder / "examples").glob("*.ipynb")
    )
    if not examples:
        parser.error(f"folder {args.folder}: no examples/; give a checkout of automl/CARL v1.1.1")
    chosen = [p for p in examples if p.name not in NEEDS_KEYBOARD]
    if args.names:
        chosen = [p for p in chosen if p.name in args.names]
    ran = 0
    with tempfile.TemporaryDirectory(prefix="carl-examples-") as work:
        for path in chosen:
            ok, error, seconds = run_example(path, Path(work), args.timeout)
            ran += ok
            part = " up to its window loop" if path.name in ENDS_IN_A_WINDOW else ""
            outcome = f"ran{part}" if ok else "FAILED"
            print(f"{path.name:58s} {outcome} ({seconds:.0f} s) {error}", flush=True)
    left_out = ", ".join(sorted(NEEDS_KEYBOARD))
    print(
        f"CARL examples on contextrl.carl: {ran} of {len(chosen)} ran ({left_out} needs a keyboard)"
    )
    return 0 if ran == len(chosen) else 1


if __name__ == "__main__":
    raise SystemExit(main())
