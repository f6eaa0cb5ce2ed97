"""The training family (bench.harness.families): its file is the generator's, checked like
cases.json, and it shares no corridor with the held-out family or the paper's corridor."""
from __future__ import annotations

import json

import pytest

from ecodrive_bench.bench.harness import case_files, families, generalisation


def test_the_training_family_is_its_generators_and_disjoint_from_the_held_out_one(capsys):
    assert case_files.main(["--check", "--family", "train"]) == 0
    assert "shares no corridor" in capsys.readouterr().out
    data = families.load()
    assert len(data["splits"]["train"]) == families.N_TRAIN and len(data["splits"]["validation"]) == families.N_VALIDATION
    assert families.overlaps(data) == []
    held = {json.dumps(v["scenario"], sort_keys=True) for v in generalisation.generate()["variants"]}
    mine = [json.dumps(c["scenario"], sort_keys=True) for s in data["splits"].values() for c in s]
    assert not held & set(mine) and len(set(mine)) == len(mine)
    junctions = {c["scenario"]["n_intersections"] for c in data["splits"]["train"]}
    assert junctions == {3, 4, 5, 6, 7}


def test_an_overlap_with_a_held_out_corridor_is_named():
    data = families.generate()
    data["splits"]["validation"][2]["scenario"] = dict(generalisation.generate()["variants"][4]["scenario"])
    lines = families.overlaps(data)
    assert lines and all("validation corridor v03" in line and "g5-" in line for line in lines)


def test_an_edited_or_duplicated_family_file_is_refused(tmp_path):
    bad = tmp_path / "train.json"
    bad.write_text(families.text().replace('"lanes": 3', '"lanes": 4', 1))
    with pytest.raises(families.TrainFamilyError, match="differs from the generator"):
        families.load(bad)
    bad.write_text('{"version": 1, "version": 1}')
    with pytest.raises(families.TrainFamilyError, match="duplicate key 'version'"):
        families.load(bad)


def test_the_validation_set_has_its_cases():
    vs = families.validation_set()
    assert len(vs) == families.N_VALIDATION and all(len(cases) == families.VALIDATION_CASES for _, cases in vs)
