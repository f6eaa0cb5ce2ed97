from __future__ import annotations

import os
import tempfile
from pathlib import Path

import pytest

import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)

# keep Rerun's config/data out of the user's home during tests
_XDG = Path(tempfile.mkdtemp(prefix="ecodrive-xdg-"))
os.environ.setdefault("XDG_CONFIG_HOME", str(_XDG / "config"))
os.environ.setdefault("XDG_DATA_HOME", str(_XDG / "data"))


@pytest.fixture(scope="session")
def cases():
    from ecodrive_bench.bench.harness.cases import load

    return load()
