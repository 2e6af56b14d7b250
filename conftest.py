"""Test-session set-up shared by doctests and tests."""

from __future__ import annotations

import os
import tempfile

import numpy as np
import pytest
from hypothesis import settings

# Compiled networks of this test session go to a private folder, never the user's cache.
os.environ.setdefault("MAPMATCH_CACHE_DIR", tempfile.mkdtemp(prefix="mapmatch-test-cache-"))
os.environ.setdefault("MPLBACKEND", "Agg")

settings.register_profile("repo", derandomize=True, deadline=None, print_blob=True)
settings.load_profile("repo")


@pytest.fixture(autouse=True)
def _doctest_namespace(doctest_namespace: dict[str, object]) -> None:
    doctest_namespace["np"] = np
