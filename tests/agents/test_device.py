"""``--device``: the learners' networks on another device than the CPU.

No CUDA device is needed for the first tests: on torch's ``meta`` device every op runs on shapes
only and an op that mixes in a host tensor fails, as it would on CUDA, so a whole update step on
``meta`` shows that nothing in it still lives on the CPU. The CUDA comparison runs where torch sees
a CUDA device and is skipped elsewhere.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch
from test_update_equivalence import _agent

from ecodrive_bench.agents import device
from ecodrive_bench.agents.registry import LEARNING


def _tensors(agent) -> list[tuple[str, torch.Tensor]]:
    """Every parameter, gradient and optimizer-state tensor of the agent."""
    out = []
    for name in agent.NETS:
        net = getattr(agent, name, None)
        if net is None:
            continue
        for pname, p in net.named_parameters():
            out.append((f"{name}.{pname}", p))
            if p.grad is not None:
                out.append((f"{name}.{pname}.grad", p.grad))
    for name in agent.OPTS:
        for i, state in enumerate(getattr(agent, name).state.values()):
            out += [(f"{name}[{i}].{k}", v) for k, v in state.items() if torch.is_tensor(v)]
    return out


@pytest.mark.parametrize("method", LEARNING)
def test_an_update_step_runs_wholly_on_the_agents_device(method):
    agent = _agent(method, n=200)
    agent.update()  # the optimizers' state exists, as in training
    n_state = len(_tensors(agent))
    assert agent.to("meta") is agent and agent.device == torch.device("meta")
    losses = agent.step()  # raises if any op mixes in a tensor left on the CPU
    assert {v.device.type for v in losses.values()} == {"meta"}
    moved = _tensors(agent)
    assert len(moved) == n_state and not [n for n, t in moved if t.device.type != "meta"]
    assert agent.updates == 2


@pytest.mark.parametrize("method", LEARNING)
def test_cpu_is_the_default_and_moving_to_it_changes_nothing(method):
    a, b = _agent(method, n=200), _agent(method, n=200)
    assert a.device == device.CPU and b.to("cpu") is b
    batch = a.replay.sample_torch(np.random.default_rng(0), 8)  # on the CPU the host tensors are used as they are
    assert a.batch(batch) is batch and a.tensor(batch["logic"]) is batch["logic"]
    assert np.shares_memory(device.host(batch["logic"]), batch["logic"].numpy())
    for _ in range(3):
        assert a.update() == b.update()
    for (na, ta), (nb, tb) in zip(_tensors(a), _tensors(b)):
        assert na == nb and torch.equal(ta, tb)


def test_device_names_are_checked_against_what_torch_sees(monkeypatch):
    assert device.parse("cpu") == device.CPU
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    with pytest.raises(ValueError, match="'cuda': torch .* sees no CUDA device; accepted here: cpu$"):
        device.parse("cuda")
    with pytest.raises(ValueError, match="'tpu' is not a device"):
        device.parse("tpu")
    with pytest.raises(ValueError, match="'meta': only cpu and cuda"):
        device.parse("meta")
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    assert device.parse("cuda:1") == torch.device("cuda:1")
    with pytest.raises(ValueError, match="has 2 CUDA device.*cuda:0..cuda:1"):
        device.parse("cuda:2")


def test_train_with_an_unusable_device_is_one_line_and_writes_nothing(tmp_path, capsys, monkeypatch):
    from ecodrive_bench.bench.training import train_command as train

    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    out = tmp_path / "run"
    with pytest.raises(SystemExit) as e:
        train.main(["--method", "prl", "--signals", "coordinated", "--device", "cuda", "--out", str(out)])
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count("\n") == 1 and "sees no CUDA device" in err and not out.exists()


@pytest.mark.skipif(not torch.cuda.is_available(), reason="torch sees no CUDA device")
@pytest.mark.parametrize("method", LEARNING)
def test_updates_on_cuda_match_the_cpu(method):
    a, b = _agent(method), _agent(method)
    b.to("cuda")
    for _ in range(5):
        la, lb = a.update(), b.update()
        assert la.keys() == lb.keys() and all(np.isclose(la[k], lb[k], rtol=1e-3, atol=1e-5) for k in la)
    for (na, ta), (_, tb) in zip(_tensors(a), _tensors(b)):
        torch.testing.assert_close(tb.cpu(), ta, rtol=1e-3, atol=1e-5, msg=na)
    obs = {"grid": a.replay.grid[0].astype(np.float32), "logic": np.zeros(9, np.float32)}
    info = {"action_mask": np.ones(3, bool)}
    assert type(a.act(obs, info)) is type(b.act(obs, info))
