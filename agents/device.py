"""Where a learning agent's networks live: the CPU (the default and the tested path) or a CUDA
device (``ecodrive train --device cuda``).

The replay buffer, the numpy Generators and the environment stay on the host: a sampled batch is
copied to the device once per update, an observation once per action, and actions come back as
numpy arrays. On the CPU every call here returns its input, so CPU runs are unchanged bit for bit.
"""
from __future__ import annotations

from typing import Any

import numpy as np
import torch

CPU = torch.device("cpu")


def parse(spec: str) -> torch.device:
    """The device named by ``spec`` (``cpu``, ``cuda`` or ``cuda:N``); ValueError naming the value
    and what this machine's torch accepts when it cannot be used here."""
    n = torch.cuda.device_count() if torch.cuda.is_available() else 0
    accepted = "cpu" + (", cuda" + (f", cuda:0..cuda:{n - 1}" if n else "") if n else "")
    try:
        dev = torch.device(spec)
    except RuntimeError:
        raise ValueError(f"--device {spec!r} is not a device; accepted here: {accepted}") from None
    if dev.type == "cpu" and dev.index in (None, 0):
        return CPU
    if dev.type != "cuda":
        raise ValueError(f"--device {spec!r}: only cpu and cuda are supported; accepted here: {accepted}")
    if not n:
        raise ValueError(f"--device {spec!r}: torch {torch.__version__} sees no CUDA device; accepted here: {accepted}")
    if dev.index is not None and dev.index >= n:
        raise ValueError(f"--device {spec!r}: this machine has {n} CUDA device(s); accepted here: {accepted}")
    return dev


class OnDevice:
    """Mixin of the learning agents: ``to(device)`` moves the networks (``NETS``, attribute names)
    and the optimizers' state (``OPTS``), then ``_views`` rebuilds what the agent derived from the
    parameters (the update's ``Dense`` views, workspace, constants)."""

    device: torch.device = CPU
    NETS: tuple[str, ...] = ()
    OPTS: tuple[str, ...] = ()

    def _views(self) -> None:
        raise NotImplementedError

    def to(self, device: str | torch.device) -> OnDevice:
        device = torch.device(device)
        if device == self.device:
            return self
        for name in self.NETS:
            net = getattr(self, name, None)
            if net is not None:
                net.to(device)  # parameters and their .grad, in place (the optimizers keep them)
        for name in self.OPTS:
            lazy = getattr(type(self), name, None)
            opt = lazy.built(self) if hasattr(lazy, "built") else getattr(self, name)  # none built: nothing to move
            for state in (opt.state.values() if opt is not None else ()):
                for k, v in state.items():
                    if torch.is_tensor(v):
                        state[k] = v.to(device)
        self.device = device
        self._views()
        return self

    def tensor(self, a: Any, dtype: torch.dtype | None = None) -> torch.Tensor:
        """``torch.as_tensor(a, dtype)`` on the agent's device."""
        t = torch.as_tensor(a, dtype=dtype)
        return t if self.device == CPU else t.to(self.device)

    def batch(self, b: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """A sampled replay batch (host tensors) on the agent's device."""
        return b if self.device == CPU else {k: v.to(self.device, non_blocking=True) for k, v in b.items()}


def host(t: torch.Tensor) -> np.ndarray:
    """A tensor as a numpy array (copied from the device when it is not the CPU)."""
    return t.numpy() if t.device == CPU else t.cpu().numpy()
