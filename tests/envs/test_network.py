"""A corridor on any SUMO network (envs.network): the docs' worked example runs as written, a
route drives end to end in the route frame, and every bad spec is one line naming the value."""
from __future__ import annotations

import math
import os
import re
import subprocess
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import sumolib

import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)
from ecodrive_bench.envs import network as nw
from ecodrive_bench.envs.config import ConfigError, ScenarioConfig
from ecodrive_bench.envs.network import NetworkError, NetworkSpec, build_network

DOC = Path(__file__).resolve().parents[2] / "docs" / "networks.md"


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path / "cache"))


def test_the_docs_example_runs_as_written(capsys):
    code = re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S)
    assert len(code) == 1
    exec(compile(code[0], str(DOC), "exec"), {})
    terminated, collisions, metres, unit = capsys.readouterr().out.split()
    assert terminated == "True" and collisions == "0" and unit == "m"
    assert 450 < int(metres) < 600  # two blocks of 250 m and the junctions between


@pytest.fixture(scope="module")
def line(tmp_path_factory):
    """A small hand-built network: a - b (signal) - c - d, an edge closed to cars, a lone edge."""
    out = tmp_path_factory.mktemp("line")
    (out / "n.nod.xml").write_text("""<nodes>
  <node id="a" x="0" y="0"/><node id="b" x="300" y="0" type="traffic_light"/>
  <node id="c" x="600" y="0"/><node id="d" x="900" y="0"/>
  <node id="p" x="0" y="500"/><node id="q" x="300" y="500"/>
</nodes>""")
    (out / "n.edg.xml").write_text("""<edges>
  <edge id="ab" from="a" to="b" numLanes="2" speed="13.89"/><edge id="bc" from="b" to="c" numLanes="2" speed="13.89"/>
  <edge id="cd" from="c" to="d" numLanes="1" speed="13.89" disallow="passenger"/>
  <edge id="pq" from="p" to="q" numLanes="1" speed="13.89"/>
</edges>""")
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "n.net.xml",
                    "--tls.default-type", "static", "--no-warnings", "true"], cwd=out, check=True, capture_output=True)
    (out / "n.rou.xml").write_text('<routes><flow id="f" from="ab" to="bc" begin="0" end="600" '
                                   'vehsPerHour="400"/></routes>')
    return out


def _spec(line, **change) -> dict:
    spec = {"net": str(line / "n.net.xml"), "demand": str(line / "n.rou.xml"), "route": ["ab", "bc"],
            "insert": [100, 200]}
    spec.update(change)
    return spec


def test_a_route_drives_to_its_end_in_the_route_frame(line):
    env = gym.make("EcoDrive-v0", network=_spec(line), action="parameterized")
    plain = gym.make("EcoDrive-v0")
    assert env.observation_space == plain.observation_space and env.action_space == plain.action_space
    obs, info = env.reset(options={"sumo_seed": 1, "insert_time": 150.0})
    assert env.observation_space.contains(obs)
    assert obs["grid"][:, 2:].max() == 0  # a two-lane road: the padded lanes read occupied
    steps, done = 0, False
    while not done:
        obs, r, terminated, truncated, info = env.step((1, np.array([0.0, 1.0, 0.0], np.float32)))
        done, steps = terminated or truncated, steps + 1
    assert terminated and not truncated and info["collisions"] == 0 and info["teleports"] == 0
    assert 280 < info["position"] < 320 + 30  # ab (300 m less the insertion length) and the junction
    assert info["energy"] > 0
    env.close()
    plain.close()


def test_the_same_case_is_the_same_episode(line):
    runs = []
    for _ in range(2):
        env = gym.make("EcoDrive-v0", network=_spec(line), action="sumo")
        env.reset(options={"sumo_seed": 4, "insert_time": 130.0})
        done, trace = False, []
        while not done:
            _, _, term, trunc, info = env.step(0)
            done = term or trunc
            trace.append((info["position"], info["energy"]))
        env.close()
        runs.append(trace)
    assert runs[0] == runs[1]


def _fifo(line, tmp_path):
    os.mkfifo(tmp_path / "net.fifo")
    return {"net": str(tmp_path / "net.fifo")}


BAD = {
    "missing net": (lambda line, tmp: {"net": str(tmp / "none.net.xml")}, "does not exist"),
    "net a FIFO": (_fifo, "not a regular file"),
    "net a device": (lambda line, tmp: {"net": "/dev/zero"}, "not a regular file"),
    "net not XML": (lambda line, tmp: {"net": str(line / "n.nod.xml")}, "not SUMO's XML"),
    "demand not XML": (lambda line, tmp: {"demand": str(line / "n.net.xml")}, "not SUMO's XML"),
    "edge not in the network": (lambda line, tmp: {"route": ["ab", "zz"]}, "route edge 'zz' is not in the network"),
    "edge closed to cars": (lambda line, tmp: {"route": ["bc", "cd"]}, "does not allow the ego's class"),
    "not connected": (lambda line, tmp: {"route": ["ab", "pq"]}, "is not connected"),
    "gap in the edges": (lambda line, tmp: {"route": ["ab", "bc", "pq"]}, "route is not connected"),
    "no signal": (lambda line, tmp: {"route": ["bc"]}, "crosses no signal"),
    "insertion outside the demand": (lambda line, tmp: {"insert": [500, 900]}, "inside the demand's span"),
    "window the wrong way round": (lambda line, tmp: {"insert": [200, 100]}, "lo <= hi"),
    "unknown key": (lambda line, tmp: {"nett": "x"}, "not accepted"),
}


@pytest.mark.parametrize("case", list(BAD))
def test_a_bad_spec_is_one_line_naming_the_value(case, line, tmp_path):
    change, words = BAD[case]
    with pytest.raises(NetworkError) as e:
        build_network(NetworkSpec.from_dict(_spec(line, **change(line, tmp_path))), ScenarioConfig())
    msg = str(e.value)
    assert "\n" not in msg and words in msg
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").iterdir())  # nothing written


def test_an_oversized_file_names_the_cap(line, monkeypatch):
    monkeypatch.setattr(nw, "NET_CAP", 100)
    with pytest.raises(NetworkError, match=r"bytes; accepted: at most 100 bytes"):
        build_network(NetworkSpec.from_dict(_spec(line)), ScenarioConfig())


def test_network_and_family_together_are_refused(line):
    with pytest.raises(ConfigError, match="not accepted together"):
        gym.make("EcoDrive-v0", network=_spec(line), family="train")


def test_an_insertion_time_outside_the_demand_is_refused_at_reset(line):
    env = gym.make("EcoDrive-v0", network=_spec(line), action="sumo")
    with pytest.raises(ValueError, match=r"demand's span \[0, 600\] s"):
        env.reset(options={"sumo_seed": 1, "insert_time": 900.0})
    env.close()


def test_lane_frame_and_route_frame_arithmetic():
    from ecodrive_bench.envs.observation import lane_frame, to_route_frame

    # a lane heading north (SUMO angle 0): a point 10 m along it from (5, 0)
    assert lane_frame([(5.0, 0.0), (5.0, 100.0)], 10.0) == (5.0, 10.0, 0.0, 1.0)
    # past the end of a bent lane: along its last segment
    x, y, dx, dy = lane_frame([(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)], 15.0)
    assert (x, y, dx, dy) == (10.0, 5.0, 0.0, 1.0)
    # a vehicle 20 m ahead of the origin on that northbound lane, heading north, one lane (3.2 m) to its left
    rows = to_route_frame(np.array([[1.8, 20.0, 0.0, 5.0]]), 5.0, 0.0, 0.0, 1.0)
    np.testing.assert_allclose(rows, [[20.0, 3.2, 90.0, 5.0]], atol=1e-12)
    # the compiled transform is numpy's arithmetic, bit for bit, on rows in every direction
    rng = np.random.default_rng(7)
    others = np.column_stack([rng.uniform(-500, 500, (64, 2)), rng.uniform(0, 360, 64), rng.uniform(4, 12, 64)])
    cx, cy, dx, dy = 12.5, -40.25, 0.6, -0.8
    axis = math.degrees(math.atan2(dx, dy))
    rx, ry = others[:, 0] - cx, others[:, 1] - cy
    want = np.column_stack([rx * dx + ry * dy, ry * dx - rx * dy, (others[:, 2] - axis + 90.0) % 360.0, others[:, 3]])
    assert np.array_equal(to_route_frame(others, cx, cy, dx, dy), want)
    assert to_route_frame(np.zeros((0, 4)), cx, cy, dx, dy).shape == (0, 4)
