"""Run CARL's own test suite against ``contextrl.carl``, with only the import changed.

CARL's tests stay in CARL's checkout: they are read from FOLDER (a checkout of automl/CARL, tag v1.1.1),
written to a temporary folder with ``carl`` rewritten to ``contextrl.carl``, and run there with this
interpreter, so neither CARL's package nor its pytest settings are on the path. Nothing is fetched.

    git clone --depth 1 --branch v1.1.1 https://github.com/automl/CARL /tmp/carl
    .venv/bin/python tools/run_carl_suite.py /tmp/carl

It prints pytest's report and a last line ``CARL suite on contextrl.carl: P of N passed``; the exit status
is pytest's. The migration guide (docs/migration-carl.md) records the count and every test that fails.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from pathlib import Path

# The suite CARL's README points to for the API the face mirrors; the other files in test/ exercise
# simulators and encodings (Mario, Brax goals, ConfigSpace search-space strings) the face does not offer.
SUITE = (
    "test_CARLEnv.py",
    "test_context_sampler.py",
    "test_context_selector.py",
    "test_context_space.py",
    "test_all_envs.py",
)
CARL_IMPORT = re.compile(r"(?<![\w.])carl(?=[.\s]|$)", re.MULTILINE)


def rewrite(source: str) -> str:
    """Code written for CARL with every ``carl`` module path (``import carl``, ``carl.envs``, ``from
    carl.x``) moved under ``contextrl.``."""
    return CARL_IMPORT.sub("contextrl.carl", source)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a checkout of automl/CARL (tag v1.1.1)")
    parser.add_argument("pytest_args", nargs="*", help="passed on to pytest (after --)")
    args = parser.parse_args()
    tests = args.folder / "test"
    missing = [name for name in SUITE if not (tests / name).is_file()]
    if missing:
        parser.error(
            f"folder {args.folder}: no test/{missing[0]}; give a checkout of automl/CARL v1.1.1"
        )
    with tempfile.TemporaryDirectory(prefix="carl-suite-") as work:
        for name in SUITE:
            text = (tests / name).read_text(encoding="utf-8")
            (Path(work) / name).write_text(rewrite(text), encoding="utf-8")
        command = [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-o", "addopts="]
        result = subprocess.run(
            [*command, "--rootdir", work, *args.pytest_args, *SUITE],
            cwd=work,
            capture_output=True,
            text=True,
        )
    print(result.stdout + result.stderr, end="")
    counts = dict(
        (word, int(number))
        for number, word in re.findall(
            r"(\d+) (passed|failed|error)", result.stdout.splitlines()[-1]
        )
    )
    ran = sum(counts.values())
    print(f"CARL suite on contextrl.carl: {counts.get('passed', 0)} of {ran} passed")
    return result.returncode


if __name__ == "__main__":
    raise SystemExit(main())
