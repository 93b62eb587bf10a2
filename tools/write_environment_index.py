"""Write src/contextrl/environments.json, the rows `contextrl list` prints, from the environments
themselves (every one built once). Run it after adding or changing an environment; the tests check
that the file equals what the environments give.

    .venv/bin/python tools/write_environment_index.py
"""

import json

from contextrl.cli import ENVIRONMENT_INDEX, environment_rows

rows = {row["id"]: row for row in environment_rows(build=True)}
ENVIRONMENT_INDEX.write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
print(f"wrote {ENVIRONMENT_INDEX} ({len(rows)} environments)")
