from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from ecodrive_bench.envs.config import ScenarioConfig
from ecodrive_bench.envs.scenario import build


def test_build_is_deterministic_and_cached(tmp_path, monkeypatch):
    cfg = ScenarioConfig(signals="coordinated")
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path / "a"))
    a = build(cfg)
    mtime = a.net.stat().st_mtime_ns
    assert build(cfg).net.stat().st_mtime_ns == mtime  # second call reuses the cache
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path / "b"))
    b = build(cfg)
    for name in ("net", "routes", "additional"):
        assert getattr(a, name).read_bytes() == getattr(b, name).read_bytes()


def test_network_matches_the_paper(tmp_path, monkeypatch):
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path))
    files = build(ScenarioConfig(signals="coordinated"))
    net = ET.parse(files.net).getroot()
    assert len(net.findall("./junction[@type='traffic_light']")) == 5
    for edge in files.arterial_edges:
        lanes = net.findall(f"./edge[@id='{edge}']/lane")
        assert len(lanes) == 5 and all(abs(float(l.get("speed")) - 50 / 3.6) < 0.01 for l in lanes)
    add = ET.parse(files.additional).getroot()
    for tl in add.findall("tlLogic"):
        assert sum(float(p.get("duration")) for p in tl.findall("phase")) == 90.0
    offsets = [float(tl.get("offset")) for tl in add.findall("tlLogic")]
    assert offsets[0] == 0.0 and len(set(offsets)) == 5
    unco = ET.parse(build(ScenarioConfig(signals="uncoordinated")).additional).getroot()
    assert {float(tl.get("offset")) for tl in unco.findall("tlLogic")} == {0.0}


def test_the_cache_is_the_users_cache_folder_unless_ecodrive_cache_is_set(tmp_path, monkeypatch):
    import platformdirs

    from ecodrive_bench.envs.scenario import cache_root

    monkeypatch.delenv("ECODRIVE_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))  # platformdirs' folder on Linux
    root = cache_root()
    assert root == Path(platformdirs.user_cache_dir("ecodrive-bench")) / "scenarios"
    assert root.is_relative_to(tmp_path / "xdg")
    assert not root.resolve().is_relative_to(Path(__file__).resolve().parents[2])  # never in the checkout
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path / "mine"))
    assert cache_root() == tmp_path / "mine"


def test_a_netconvert_failure_is_one_line_naming_the_scenario(tmp_path, monkeypatch):
    import ecodrive_bench.envs.scenario as scenario

    fake = tmp_path / "netconvert"
    fake.write_text("#!/bin/sh\necho 'Error: the first line of the complaint' >&2\necho 'more detail' >&2\nexit 1\n")
    fake.chmod(0o755)
    monkeypatch.setattr(scenario, "_netconvert", lambda: str(fake))
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path / "cache"))
    with pytest.raises(scenario.ScenarioBuildError) as e:
        build(ScenarioConfig(lanes=3))
    msg = str(e.value)
    assert "\n" not in msg and "Error: the first line of the complaint" in msg and "more detail" not in msg
    assert "3 lanes" in msg and "netconvert failed (exit 1)" in msg
    assert list((tmp_path / "cache").iterdir()) == []  # nothing half-built is left in the cache
    monkeypatch.setattr(scenario, "_netconvert", lambda: str(tmp_path / "missing"))
    with pytest.raises(scenario.ScenarioBuildError, match="netconvert could not start"):
        build(ScenarioConfig(lanes=3))


def test_a_yellow_of_a_fraction_of_a_second_builds(tmp_path, monkeypatch):
    """netconvert takes whole seconds for its yellow: 2.5 s failed in netconvert before."""
    monkeypatch.setenv("ECODRIVE_CACHE", str(tmp_path))
    add = ET.parse(build(ScenarioConfig(yellow=2.5)).additional).getroot()
    for tl in add.findall("tlLogic"):
        assert [float(p.get("duration")) for p in tl.findall("phase")] == [42.0, 2.5, 43.0, 2.5]
