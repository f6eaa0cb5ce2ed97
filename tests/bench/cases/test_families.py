"""The training family (bench.cases.train_family): its file is the generator's, checked like
cases.json, and it shares no corridor with the held-out family or the paper's corridor."""
from __future__ import annotations

import json

import pytest

from ecodrive_bench.bench.cases import heldout, train_family
from ecodrive_bench.bench.shipped import cases_command as case_files


def test_the_training_family_is_its_generators_and_disjoint_from_the_held_out_one(capsys):
    assert case_files.main(["--check", "--family", "train"]) == 0
    assert "shares no corridor" in capsys.readouterr().out
    data = train_family.load()
    assert len(data["splits"]["train"]) == train_family.N_TRAIN and len(data["splits"]["validation"]) == train_family.N_VALIDATION
    assert train_family.overlaps(data) == []
    held = {json.dumps(v["scenario"], sort_keys=True) for v in heldout.generate()["variants"]}
    mine = [json.dumps(c["scenario"], sort_keys=True) for s in data["splits"].values() for c in s]
    assert not held & set(mine) and len(set(mine)) == len(mine)
    junctions = {c["scenario"]["n_intersections"] for c in data["splits"]["train"]}
    assert junctions == {3, 4, 5, 6, 7}


def test_an_overlap_with_a_held_out_corridor_is_named():
    data = train_family.generate()
    data["splits"]["validation"][2]["scenario"] = dict(heldout.generate()["variants"][4]["scenario"])
    lines = train_family.overlaps(data)
    assert lines and all("validation corridor v03" in line and "g5-" in line for line in lines)


def test_an_edited_or_duplicated_family_file_is_refused(tmp_path):
    bad = tmp_path / "train.json"
    bad.write_text(train_family.text().replace('"lanes": 3', '"lanes": 4', 1))
    with pytest.raises(train_family.TrainFamilyError, match="differs from the generator"):
        train_family.load(bad)
    bad.write_text('{"version": 1, "version": 1}')
    with pytest.raises(train_family.TrainFamilyError, match="duplicate key 'version'"):
        train_family.load(bad)


def test_the_validation_set_has_its_cases():
    vs = train_family.validation_set()
    assert len(vs) == train_family.N_VALIDATION and all(len(cases) == train_family.VALIDATION_CASES for _, cases in vs)
