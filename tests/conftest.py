from __future__ import annotations

import atexit
import os
import shutil
import signal
import tempfile
from pathlib import Path

import pytest

import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)

# The suite tests Ctrl-C handling. A pytest started with SIGINT ignored (under nohup, or as a
# background job of a non-interactive shell) gets Python's handler back, so the pool tests can
# interrupt it, and its subprocesses start with SIGINT's default action (a caught signal is reset
# at exec; an ignored one would stay ignored).
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# keep Rerun's config/data out of the user's home during tests; the folder goes with the session
_XDG = Path(tempfile.mkdtemp(prefix="ecodrive-xdg-"))
atexit.register(shutil.rmtree, _XDG, True)
os.environ.setdefault("XDG_CONFIG_HOME", str(_XDG / "config"))
os.environ.setdefault("XDG_DATA_HOME", str(_XDG / "data"))


@pytest.fixture(scope="session")
def cases():
    from ecodrive_bench.bench.cases.case import load

    return load()


@pytest.fixture(scope="module")
def two_ray_nodes():
    """A Ray cluster of two nodes (raylets) of one CPU each on this machine; shut down after the module."""
    ray = pytest.importorskip("ray")
    from ray.cluster_utils import Cluster

    cluster = Cluster()
    for _ in range(2):
        cluster.add_node(num_cpus=1, include_dashboard=False)
    yield cluster
    ray.shutdown()
    cluster.shutdown()
