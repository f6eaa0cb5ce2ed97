"""The harness's errors, at the bottom of ``bench.harness``: every module may raise them and no
import runs back up to a runner for them (an agent's own, ``AgentError``, is ``bench.methods.errors``). Each message is one line; the ``ecodrive`` commands
print it and exit 2."""
from __future__ import annotations

from ecodrive_bench.bench.args import Terminated  # noqa: F401  (SIGTERM's exception, re-exported: its home is bench.args)


class UsageError(Exception):
    """Bad input to ``ecodrive run`` found after parsing; printed as one line, nothing touched."""

