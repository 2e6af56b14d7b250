"""``python -m mapmatch``: the command line."""

from __future__ import annotations

import sys

from mapmatch.cli import main

sys.exit(main())
