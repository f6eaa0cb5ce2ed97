"""The harness's errors, at the bottom of ``bench.harness``: every module may raise them and no
import runs back up to a runner for them (an agent's own, ``AgentError``, is ``bench.methods.errors``). Each message is one line; the ``ecodrive`` commands
print it and exit 2."""
from __future__ import annotations


class UsageError(Exception):
    """Bad input to ``ecodrive run`` found after parsing; printed as one line, nothing touched."""


class Terminated(BaseException):
    """SIGTERM, raised in the main thread by ``ecodrive run``'s handler: the run ends as on Ctrl-C
    (a ``BaseException``, as ``KeyboardInterrupt``: no ``except Exception`` swallows it)."""
