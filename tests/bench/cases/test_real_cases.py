"""The real case set (bench.cases.real): the shipped file is its generator's output on the installed
sumo-rl's files, its cases lie in their windows, and the route choice is the one documented."""
from __future__ import annotations

import subprocess

import pytest
import sumolib

from ecodrive_bench.bench.cases import real
from ecodrive_bench.bench.shipped import real_cases
from ecodrive_bench.envs.network import real_corridors, real_spec
from ecodrive_bench.envs.route import read_net as _read_net


def test_the_shipped_file_is_the_generators_output(capsys):
    assert real_cases.main(write=False) == 0
    assert "matches the generator" in capsys.readouterr().out


def test_every_corridor_has_its_cases_inside_its_window():
    corridors = real_corridors()
    assert list(corridors) == list(real.SCENARIOS)
    for c in corridors.values():
        lo, hi = c["insert"]
        assert c["begin"] + real.INSERT_AFTER[0] == lo and hi == c["begin"] + real.INSERT_AFTER[1] <= c["end"]
        assert len(c["cases"]) == real.CASES_PER_CORRIDOR >= 30
        assert all(lo <= k["insert_time"] <= hi for k in c["cases"])
        assert len({k["sumo_seed"] for k in c["cases"]}) == len(c["cases"])
        assert c["junctions"] >= 3 and c["signals"] >= c["junctions"]
    for v in real.variants():
        assert v.scenario == {"network": v.name} and len(v.cases) == real.CASES_PER_CORRIDOR


def test_a_real_spec_reads_the_installed_package_in_place():
    spec = real_spec("cologne8")
    assert "sumo_rl/nets/RESCO/cologne8" in spec.net and spec.demand[0].endswith("cologne8.rou.xml")
    assert spec.begin == 25200.0 and spec.end == 28800.0


def test_an_unknown_variant_is_refused():
    from ecodrive_bench.bench.cases.heldout import FamilyError

    with pytest.raises(FamilyError, match="not a real corridor; accepted: ingolstadt7, cologne3, cologne8"):
        real.variants(["paris"])


def test_the_route_through_the_most_signals_is_chosen(tmp_path):
    """A T of two signalised junctions and a side street with none: the route crosses both
    signals and is cut after the edge that follows the last one."""
    (tmp_path / "n.nod.xml").write_text("""<nodes>
  <node id="a" x="0" y="0"/><node id="b" x="200" y="0" type="traffic_light"/>
  <node id="c" x="400" y="0" type="traffic_light"/><node id="d" x="600" y="0"/><node id="e" x="800" y="0"/>
  <node id="n" x="200" y="200"/><node id="s" x="400" y="-200"/>
</nodes>""")
    (tmp_path / "n.edg.xml").write_text("""<edges>
  <edge id="ab" from="a" to="b" numLanes="1" speed="13.89"/><edge id="bc" from="b" to="c" numLanes="1" speed="13.89"/>
  <edge id="cd" from="c" to="d" numLanes="1" speed="13.89"/><edge id="de" from="d" to="e" numLanes="1" speed="13.89"/>
  <edge id="nb" from="n" to="b" numLanes="1" speed="13.89"/><edge id="cs" from="c" to="s" numLanes="1" speed="13.89"/>
</edges>""")
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "n.net.xml",
                    "--tls.default-type", "static", "--no-turnarounds", "true", "--no-warnings", "true"],
                   cwd=tmp_path, check=True, capture_output=True)
    net = _read_net(tmp_path / "n.net.xml")
    route = real_cases.most_signals(net)
    # both signals crossed, cut after the edge past c (de never taken), the shorter of the ties
    assert route in (["ab", "bc", "cd"], ["ab", "bc", "cs"], ["nb", "bc", "cd"], ["nb", "bc", "cs"])
    lengths = {r: sum(net.getEdge(e).getLength() for e in r) for r in
               (("ab", "bc", "cd"), ("ab", "bc", "cs"), ("nb", "bc", "cd"), ("nb", "bc", "cs"))}
    assert lengths[tuple(route)] == min(lengths.values())
    assert real_cases.most_signals(net) == route  # deterministic


def test_the_docs_table_is_the_case_sets():
    """docs/networks.md's table of the real corridors states what real.json holds (signals, length)."""
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[3] / "docs" / "networks.md").read_text()
    for name, c in real_corridors().items():
        row = next(line for line in doc.splitlines() if line.startswith(f"| `{name}` |"))
        cells = [x.strip() for x in row.strip("|").split("|")]
        assert cells[3] == f"{len(c['route'])} edges" and cells[4] == str(c["junctions"])
        assert cells[5] == f"{round(c['length'])} m"
