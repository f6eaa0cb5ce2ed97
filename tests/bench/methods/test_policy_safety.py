"""A policy, checkpoint or training state is data: a pickle payload planted in one is refused on
every load path (shipped policy, training resume, Q check of a run folder) and never runs."""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import pytest
import torch

from ecodrive_bench.bench.io import sha256
from ecodrive_bench.bench.methods.policies import MODELS, CheckpointError, load_policy, policy_dir
from ecodrive_bench.bench.training.qcheck import main as qcheck_main
from ecodrive_bench.bench.training.train import train
from ecodrive_bench.bench.training.train_command import main as train_main


class Payload:
    """Runs ``touch marker`` when unpickled, as a hostile file would."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (os.system, (f"touch {self.marker}",))


def plant(path: Path, marker: Path) -> None:
    state = torch.load(path, weights_only=True)
    state["extra"] = Payload(marker)
    torch.save(state, path)


def test_a_shipped_policy_with_a_payload_and_a_matching_manifest_is_refused(tmp_path):
    folder = tmp_path / "prl-uncoordinated"
    shutil.copytree(policy_dir("prl", "uncoordinated"), folder)
    marker = tmp_path / "ran"
    plant(folder / "policy.pt", marker)
    man = json.loads((folder / "manifest.json").read_text())
    man["sha256"] = sha256(folder / "policy.pt")  # whoever replaces the file can edit the manifest
    (folder / "manifest.json").write_text(json.dumps(man))
    with pytest.raises(CheckpointError, match=r"refused.*GLOBAL posix.system") as e:
        load_policy(folder, "prl")
    assert "\n" not in str(e.value)
    assert not marker.exists()


def test_the_shipped_policies_load_as_data():
    folders = sorted(MODELS.glob("*-*/s*"))
    assert len(folders) >= 8
    for folder in folders:
        method = folder.parent.name.rsplit("-", 1)[0]  # <method>-<signals>: prl-family-coordinated
        state, _ = load_policy(folder, method)
        assert state


@pytest.fixture(scope="module")
def run_folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("train") / "run"
    train("prl", "coordinated", 1, seed=0, out=out, models=None, progress=False, validation_cases=0,
          agent_config={"learning_starts": 64, "batch_size": 16}, scenario={"max_episode_time": 30.0})
    return out


def test_a_training_checkpoint_is_plain_data(run_folder):
    torch.load(run_folder / "checkpoint.pt", weights_only=True)  # raises if it needs more


@pytest.mark.parametrize("entry", ["train", "qcheck"])
def test_a_payload_in_a_training_checkpoint_is_refused(entry, run_folder, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(run_folder, run)
    marker = tmp_path / "ran"
    plant(run / "checkpoint.pt", marker)
    before = (run / "checkpoint.pt").read_bytes()
    if entry == "train":
        rc = train_main(["--method", "prl", "--signals", "coordinated", "--episodes", "2", "--out", str(run),
                         "--no-export", "--validation-cases", "0"])
    else:
        rc = qcheck_main(["--method", "prl", "--signals", "coordinated", "--cases", "1", "--run", str(run)])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and "refused" in err and "checkpoint.pt" in err
    assert not marker.exists()
    assert (run / "checkpoint.pt").read_bytes() == before


@pytest.mark.parametrize("text, words", [("[1, 2, 3]", "a JSON list, expected an object"), ("{oops", "not valid JSON")])
def test_a_manifest_that_is_not_a_json_object_is_one_clear_error(text, words, tmp_path):
    folder = tmp_path / "prl-uncoordinated"
    shutil.copytree(policy_dir("prl", "uncoordinated"), folder)
    (folder / "manifest.json").write_text(text)
    with pytest.raises(CheckpointError, match=words) as e:
        load_policy(folder, "prl")
    assert "\n" not in str(e.value)
