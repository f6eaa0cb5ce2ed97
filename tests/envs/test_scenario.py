from __future__ import annotations

import xml.etree.ElementTree as ET

from envs.config import ScenarioConfig
from envs.scenario import build


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
