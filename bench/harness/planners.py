"""The built-in methods that plan with the signal plans (``bench.oracle``): never trained, run
when named in ``--methods`` (and by default on the generalisation profile).

- ``oracle``: the energy-optimal plan of the departure, replayed open loop in time;
- ``mpc``: re-plans on the DP's cost-to-go in closed loop, keeping the gap to the vehicle ahead.
"""
from __future__ import annotations

from ecodrive_bench.bench.harness.mpc import NAME as MPC
from ecodrive_bench.bench.harness.mpc import MPCAgent
from ecodrive_bench.bench.harness.oracle import NAME as ORACLE
from ecodrive_bench.bench.harness.oracle import OracleAgent

PLANNERS = {ORACLE: OracleAgent, MPC: MPCAgent}  # name -> agent class, built from the env's config
__all__ = ["MPC", "ORACLE", "PLANNERS"]
