"""One display name per method, the paper's where it has one (DQN-27, DDPG+LC2013), and a few
words on what each method is for a table's or a legend's first use. The method ids (``prl``,
``mpc``) stay the data's: the CLI, the results tables and the CSVs use them; the README
headline, the report's tables, captions and figures show these names. A user's own method is
shown by its id."""
from __future__ import annotations

NAME = {
    "baseline": "Baseline", "baseline0": "Baseline0", "glosa": "GLOSA",
    "prl": "PRL", "mpdqn": "MP-DQN", "ddpg": "DDPG+LC2013", "dqn": "DQN-27",
    "prl-family": "PRL-family", "mpdqn-family": "MP-DQN-family",
    "oracle": "Oracle", "mpc": "MPC", "clairvoyant": "Clairvoyant",
}
WHAT = {
    "baseline": "SUMO's Krauss driver and LC2013",
    "baseline0": "SUMO's driver, imperfection sigma 0",
    "glosa": "SUMO's GLOSA device",
    "prl-family": "trained on the corridor family",
    "mpdqn-family": "trained on the corridor family",
    "oracle": "the cost-optimal plan replayed in traffic",
    "mpc": "re-plans with the signal plans, closed loop",
    "clairvoyant": "knows the signal plans and the case's future traffic",
}


def name(method: str) -> str:
    """The method's display name; a user's method: its id."""
    return NAME.get(method, method)


def label(method: str, inside: bool = False) -> str:
    """The display name with what the method is, where a reader needs it: ``MPC (re-plans ...)``;
    ``inside`` parentheses already: ``MPC, re-plans ...``."""
    what = WHAT.get(method)
    return name(method) if not what else f"{name(method)}, {what}" if inside else f"{name(method)} ({what})"


def seeded(method: str, seed: int | None) -> str:
    """The name of one training seed's policy (``PRL, training seed 0``); a method without
    training seeds (seed None or negative): its name."""
    return name(method) if seed is None or seed < 0 else f"{name(method)}, training seed {seed}"
