"""Where the shared real data lies for the tests: ``shared/external`` beside the clone (as the brief lays it out).

``AEROBENCH_EXTERNAL`` names another folder. Tests that read it are skipped, saying why, where it is absent.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

EXTERNAL = Path(os.environ.get("AEROBENCH_EXTERNAL") or Path(__file__).resolve().parents[2] / "shared" / "external")
needs_external = pytest.mark.skipif(not EXTERNAL.is_dir(), reason=f"no external data at {EXTERNAL}")
