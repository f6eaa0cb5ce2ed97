"""The harness's errors, at the bottom of ``bench.harness``: every module may raise them and no
import runs back up to a runner for them. Each message is one line; the ``ecodrive`` commands
print it and exit 2."""
from __future__ import annotations


class AgentError(ValueError):
    """A user agent that cannot be loaded or acts outside its space; one line."""


class UsageError(Exception):
    """Bad input to ``ecodrive run`` found after parsing; printed as one line, nothing touched."""


class Terminated(BaseException):
    """SIGTERM, raised in the main thread by ``ecodrive run``'s handler: the run ends as on Ctrl-C
    (a ``BaseException``, as ``KeyboardInterrupt``: no ``except Exception`` swallows it)."""


def install_hint(extra: str) -> str:
    """The command that adds the optional ``extra``, as the README installs the package (editable,
    from the checkout)."""
    return f'pip install -e ".[{extra}]" in the checkout'
