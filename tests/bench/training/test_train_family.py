"""``ecodrive train --family train``: a generalist trains on a corridor per episode, drawn after
the episode's seed, resumes exactly, is selected on the validation corridors and ships as
``<method>-family`` with the family in its manifest."""
from __future__ import annotations

import json

import pandas as pd
import pytest
import torch

from ecodrive_bench.bench.cases import train_family
from ecodrive_bench.bench.methods.policies import CheckpointError
from ecodrive_bench.bench.training import family as generalist
from ecodrive_bench.bench.training.train import train
from ecodrive_bench.bench.training.train_command import main

FAST_AGENT = {"learning_starts": 16, "batch_size": 8}
FAST_SCENARIO = {"max_episode_time": 40.0}
KW = dict(checkpoint_every=1, agent_config=FAST_AGENT, scenario=FAST_SCENARIO, progress=False, family="train",
          validation_cases=1)


@pytest.mark.slow
def test_a_family_run_resumes_exactly_and_ships_under_its_own_name(tmp_path):
    full = train("prl", "uncoordinated", 3, seed=1, out=tmp_path / "full", models=tmp_path / "models", **KW)
    part = train("prl", "uncoordinated", 3, seed=1, out=tmp_path / "cut", stop_after=2, models=None, **KW)
    assert len(part) == 2
    resumed = train("prl", "uncoordinated", 3, seed=1, out=tmp_path / "cut", models=None, **KW)
    pd.testing.assert_frame_equal(full, resumed)
    a = torch.load(tmp_path / "full" / "checkpoint.pt", weights_only=True)
    b = torch.load(tmp_path / "cut" / "checkpoint.pt", weights_only=True)
    for k in a["agent"]["q"]:
        assert torch.equal(a["agent"]["q"][k], b["agent"]["q"][k])
    assert a["identity"]["family"] == generalist.identity("train")
    m = json.loads((tmp_path / "models" / "prl-family-uncoordinated" / "s1" / "manifest.json").read_text())
    assert m["method"] == "prl-family" and m["base_method"] == "prl" and m["family"]["split"] == "train"
    assert m["validation"]["corridors"] == 1 and m["validation"]["master_seed"] == train_family.MASTER_SEED
    with pytest.raises(CheckpointError, match="differs in family"):  # a specialist run cannot take it over
        train("prl", "uncoordinated", 4, seed=1, out=tmp_path / "full", models=None,
              **{**KW, "family": None, "validation_cases": 0})


def test_validation_cases_go_round_robin_over_the_validation_corridors():
    every = generalist.cases()
    assert len(every) == train_family.N_VALIDATION and sum(len(c) for _, c in every) == 24
    first8 = generalist.cases(8)
    assert len(first8) == 8 and all(len(c) == 1 and c[0].index == 0 for _, c in first8)
    assert [len(c) for _, c in generalist.cases(10)][:3] == [2, 2, 1]


def test_a_bad_family_is_one_line(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--method", "prl", "--signals", "uncoordinated", "--family", "test"])
    assert e.value.code == 2 and "invalid choice: 'test'" in capsys.readouterr().err
