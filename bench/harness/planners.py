"""The built-in methods that plan with the signal plans (``bench.oracle``): never trained, run
when named in ``--methods`` (and by default on the generalisation profile).

- ``oracle``: the cost-optimal plan of the departure, replayed open loop in time;
- ``mpc``: re-plans on the DP's cost-to-go in closed loop, keeping the gap to the vehicle ahead;
- ``clairvoyant``: re-plans in closed loop knowing the case's future traffic, and picks its lane:
  the top of the scale (``bench.harness.clairvoyant``).
"""
from __future__ import annotations

from ecodrive_bench.bench.harness.clairvoyant import NAME as CLAIRVOYANT
from ecodrive_bench.bench.harness.clairvoyant import ClairvoyantAgent
from ecodrive_bench.bench.harness.mpc import NAME as MPC
from ecodrive_bench.bench.harness.mpc import MPCAgent
from ecodrive_bench.bench.harness.oracle import NAME as ORACLE
from ecodrive_bench.bench.harness.oracle import OracleAgent

PLANNERS = {ORACLE: OracleAgent, MPC: MPCAgent, CLAIRVOYANT: ClairvoyantAgent}  # name -> agent class, built from the env's config
__all__ = ["CLAIRVOYANT", "MPC", "ORACLE", "PLANNERS"]
