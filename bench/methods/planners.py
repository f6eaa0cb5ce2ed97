"""The built-in methods that plan with the signal plans (``bench.oracle``): never trained, run
when named in ``--methods`` (and by default on the generalisation profile).

- ``oracle``: the cost-optimal plan of the departure, replayed open loop in time;
- ``mpc``: re-plans on the DP's cost-to-go in closed loop, keeping the gap to the vehicle ahead;
- ``clairvoyant``: re-plans in closed loop knowing the case's future traffic, and picks its lane:
  the top of the scale (``bench.methods.clairvoyant_agent``).

Their names only: the agents (``bench.methods.oracle_agent.OracleAgent``, ``bench.methods.mpc_agent.MPCAgent``,
``bench.methods.clairvoyant_agent.ClairvoyantAgent``, built from the env's config) import the DP, which
the options and a command's ``--help`` need not.
"""
from __future__ import annotations

from ecodrive_bench.bench import registry

PLANNERS = registry.names("planner", installed=False)
ORACLE, MPC, CLAIRVOYANT = PLANNERS  # the registry's planners, in its order


def identity(method: str) -> str:
    """What a planner's step logs record as their ``agent_sha256``, so that a run reuses a log only
    if the same planner wrote it: the sha256 of the versions its episodes follow (the DP's plans,
    ``bench.oracle.dp.VERSION``; ``mpc``'s first plans and re-plans, ``bench.oracle.mpc.VERSION``;
    ``clairvoyant``'s drives, ``bench.cases.clairvoyant_drives.VERSION``; each bumped with any
    change that moves one); "" for a method that is not a planner."""
    if method not in PLANNERS:
        return ""
    import hashlib

    from ecodrive_bench.bench.cases.clairvoyant_drives import VERSION as DRIVES
    from ecodrive_bench.bench.oracle.dp import VERSION as DP
    from ecodrive_bench.bench.oracle.mpc import VERSION as REPLANS

    versions = {ORACLE: f"dp {DP}", MPC: f"dp {DP} mpc {REPLANS}",
                CLAIRVOYANT: f"dp {DP} mpc {REPLANS} drives {DRIVES}"}[method]
    return hashlib.sha256(f"{method} {versions}".encode()).hexdigest()
