"""A user agent's module for the plug-in tests: ``Cruise``, which holds lane and asks for
0.5 m/s^2 every step after running a test's own lines (``body``, with ``self.mode``, ``self.step``
and ``info`` in scope), and one factory per mode; ``install`` writes it where ``--agent`` finds it
(the current folder, the path, and the pool's workers' ``PYTHONPATH``)."""
from __future__ import annotations

import sys
import textwrap
from collections.abc import Iterable
from pathlib import Path

_MODULE = '''\
import os, signal, time
from pathlib import Path
import numpy as np

HERE = Path(__file__).parent
VERSION = 1


class Cruise:
    name = "cruise"
    action_interface = "parameterized"
    env_overrides = {{}}

    def __init__(self, mode):
        self.mode, self.step = mode, 0

    def act(self, obs, info, explore=False):
        self.step = 0 if info["travel_time"] == 0 else self.step + 1
{body}
        return 1, np.full(3, 0.5, dtype=np.float32)

    def observe(self, *args):
        return {{}}

    def state_dict(self):
        return {{}}

    def load_state_dict(self, state):
        pass
'''


def source(body: str, modes: Iterable[str]) -> str:
    """The module's text: ``body`` inside ``act``, and a factory ``<mode>(observation_space,
    action_space)`` per mode."""
    factories = "".join(f"\n\ndef {m}(observation_space, action_space):\n    return Cruise({m!r})\n" for m in modes)
    return _MODULE.format(body=textwrap.indent(textwrap.dedent(body).strip("\n"), " " * 8)) + factories


def install(folder: Path, module: str, text: str, monkeypatch) -> Path:
    """Write ``module``.py into ``folder`` and make it importable here and in spawned workers."""
    (folder / f"{module}.py").write_text(text)
    monkeypatch.syspath_prepend(str(folder))
    monkeypatch.setenv("PYTHONPATH", str(folder))
    monkeypatch.chdir(folder)
    sys.modules.pop(module, None)
    return folder
