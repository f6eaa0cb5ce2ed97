"""``SumoSession.present`` against SUMO's vehicle list, on both session kinds (its own module: no
other test's env holds libsumo here)."""
from __future__ import annotations

import gymnasium as gym
import pytest

import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)
from ecodrive_bench.envs.scenario import EGO_ROUTE, HDV_TYPE

B = {"sumo_seed": 99, "insert_time": 160.0}  # a fixed case (as tests/envs/test_sessions.py)



@pytest.mark.parametrize("backend", ["libsumo", "traci"])
def test_present_is_membership_of_the_vehicle_list(backend):
    """``SumoSession.present`` (one query) agrees with ``vid in vehicle_ids()`` (the whole list) for
    vehicles driving, waiting to be inserted, removed and unknown, on both session kinds."""
    holder = gym.make("EcoDrive-v0", signals="uncoordinated").unwrapped
    e = gym.make("EcoDrive-v0", signals="uncoordinated").unwrapped
    try:
        if backend == "traci":  # a second session of the process runs through TraCI
            holder.reset(options=B)
        e.reset(options=B)
        s = e.session
        assert s.backend == backend
        api = s._api
        for i in range(30):  # more than the entry lane takes at once: some wait to be inserted
            api.vehicle.add(f"extra{i}", EGO_ROUTE, typeID=HDV_TYPE, depart="now")
        s.step()
        driving = list(s.vehicle_ids())
        api.vehicle.remove(driving[0])
        s.step()
        ids = set(s.vehicle_ids())
        probe = driving + [f"extra{i}" for i in range(30)] + ["nobody"]
        assert any(v not in ids for v in probe[1:-1])  # some vehicle known to SUMO but not listed
        for vid in probe:
            assert s.present(vid) == (vid in ids), vid
    finally:
        e.close()
        holder.close()
