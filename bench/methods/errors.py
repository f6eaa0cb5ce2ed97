"""The methods' errors, at the bottom of ``bench.methods``: an agent that cannot be loaded or acts
outside its space, and the hint for an optional extra a method needs. Each message is one line; the
``ecodrive`` commands print it and exit 2."""
from __future__ import annotations


class AgentError(ValueError):
    """A user agent that cannot be loaded or acts outside its space; one line."""


class ShippedMismatch(RuntimeError):
    """A shipped drive or plan whose replay does not give what its row says (an edited or damaged
    file whose digest was recomputed): the episode fails with this one line, and is no row."""


def install_hint(extra: str) -> str:
    """The command that adds the optional ``extra``, as the README installs the package (editable,
    from the checkout)."""
    return f'pip install -e ".[{extra}]" in the checkout'
