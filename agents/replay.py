"""Uniform replay buffer in numpy (grids stored as uint8), sampled with a seeded Generator, and
the n-step window that turns consecutive transitions into n-step ones."""
from __future__ import annotations

from pathlib import Path
from typing import BinaryIO

import numpy as np
import torch


class Replay:
    FIELDS = ("grid", "logic", "action", "reward", "next_grid", "next_logic", "done", "next_mask", "steps")

    def __init__(self, capacity: int, grid_shape: tuple[int, int], logic_dim: int, action_dim: int) -> None:
        self.capacity = capacity
        self.grid = np.zeros((capacity, *grid_shape), dtype=np.uint8)
        self.next_grid = np.zeros_like(self.grid)
        self.logic = np.zeros((capacity, logic_dim), dtype=np.float32)
        self.next_logic = np.zeros_like(self.logic)
        self.action = np.zeros((capacity, action_dim), dtype=np.float32)
        self.reward = np.zeros(capacity, dtype=np.float32)
        self.done = np.zeros(capacity, dtype=np.float32)
        self.next_mask = np.ones((capacity, 3), dtype=np.bool_)
        self.steps = np.ones(capacity, dtype=np.float32)  # env steps from state to next state (n-step)
        self.size = 0
        self.pos = 0
        self._batches: dict[int, tuple[dict[str, np.ndarray], dict[str, torch.Tensor]]] = {}

    def add(self, grid, logic, action, reward, next_grid, next_logic, done, next_mask, steps: int = 1) -> None:
        i = self.pos
        self.grid[i], self.logic[i], self.action[i], self.reward[i] = grid, logic, action, reward
        self.next_grid[i], self.next_logic[i], self.done[i], self.next_mask[i] = next_grid, next_logic, done, next_mask
        self.steps[i] = steps
        self.pos = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, rng: np.random.Generator, batch: int) -> dict[str, np.ndarray]:
        idx = rng.integers(0, self.size, size=batch)
        return {f: getattr(self, f)[idx] for f in self.FIELDS}

    def sample_torch(self, rng: np.random.Generator, batch: int) -> dict[str, torch.Tensor]:
        """``sample``'s batch (the same draw from ``rng``) as torch tensors, gathered into buffers
        that the next call overwrites; grids stay uint8."""
        idx = rng.integers(0, self.size, size=batch)
        if batch not in self._batches:
            arrays = {f: np.empty((batch, *getattr(self, f).shape[1:]), getattr(self, f).dtype) for f in self.FIELDS}
            self._batches[batch] = arrays, {f: torch.from_numpy(a) for f, a in arrays.items()}
        arrays, tensors = self._batches[batch]
        for f, a in arrays.items():
            np.take(getattr(self, f), idx, axis=0, out=a)
        return tensors

    def save(self, path: Path | BinaryIO) -> None:
        n = self.size
        np.savez(path, size=n, pos=self.pos, **{f: getattr(self, f)[:n] for f in self.FIELDS})

    def load(self, path: Path) -> None:
        with np.load(path) as d:
            n = int(d["size"])
            for f in self.FIELDS:
                getattr(self, f)[:n] = d[f] if f in d else 1.0  # files from before "steps": 1-step
            self.size, self.pos = n, int(d["pos"])


class NStepWindow:
    """Turns an episode's 1-step transitions into n-step ones (Sutton and Barto 7.1; Rainbow):
    (s_t, a_t, sum_{i<m} gamma^i r_{t+i}, s_{t+m}, done_{t+m}, mask_{t+m}, m) with m = n, or
    fewer at the episode's end, where the window is flushed (a truncated episode bootstraps from
    its last state, a terminated one does not). ``n = 1`` passes transitions through unchanged."""

    def __init__(self, n: int, gamma: float) -> None:
        self.n, self.gamma = n, gamma
        self.window: list[tuple] = []

    def reset(self) -> None:
        self.window = []

    def _emit(self, i: int) -> tuple:
        first, last = self.window[i], self.window[-1]
        ret = sum(self.gamma ** j * t[3] for j, t in enumerate(self.window[i:]))
        return (first[0], first[1], first[2], ret, last[4], last[5], last[6], last[7], len(self.window) - i)

    def push(self, transition: tuple, episode_end: bool) -> list[tuple]:
        """``transition`` = (grid, logic, action, reward, next_grid, next_logic, done, next_mask);
        returns the n-step transitions now complete, as ``Replay.add`` arguments."""
        self.window.append(transition)
        if episode_end:
            out = [self._emit(i) for i in range(len(self.window))]
            self.window = []
            return out
        if len(self.window) < self.n:
            return []
        out = [self._emit(0)]
        self.window.pop(0)
        return out
