"""One display name per method, the paper's where it has one (DQN-27, DDPG+LC2013), and a few
words on what each method is for a table's or a legend's first use, as the method registry holds
them (``bench.registry``). The method ids (``prl``, ``mpc``) stay the data's: the CLI, the
results tables and the CSVs use them; the README headline, the report's tables, captions and
figures show these names. A method the registry does not know (a run's ``--agent``) is shown by
its id."""
from __future__ import annotations

from ecodrive_bench.bench import registry


def name(method: str) -> str:
    """The method's display name; a method the registry does not know: its id."""
    return registry.display(method)


def label(method: str, inside: bool = False) -> str:
    """The display name with what the method is, where a reader needs it: ``MPC (re-plans ...)``;
    ``inside`` parentheses already: ``MPC, re-plans ...``."""
    entry = registry.method(method)
    what = entry.what if entry is not None else ""
    return name(method) if not what else f"{name(method)}, {what}" if inside else f"{name(method)} ({what})"


def seeded(method: str, seed: int | None) -> str:
    """The name of one training seed's policy (``PRL, training seed 0``); a method without
    training seeds (seed None or negative): its name."""
    return name(method) if seed is None or seed < 0 else f"{name(method)}, training seed {seed}"
