"""``python -m contextrl``: the ``contextrl`` command, for environments where its script is not on PATH."""

import sys

from contextrl.cli import main

sys.exit(main())
