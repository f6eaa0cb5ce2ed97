"""Uniform replay buffer in numpy (grids stored as uint8), sampled with a seeded Generator."""
from __future__ import annotations

from pathlib import Path

import numpy as np


class Replay:
    FIELDS = ("grid", "logic", "action", "reward", "next_grid", "next_logic", "done", "next_mask")

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
        self.size = 0
        self.pos = 0

    def add(self, grid, logic, action, reward, next_grid, next_logic, done, next_mask) -> None:
        i = self.pos
        self.grid[i], self.logic[i], self.action[i], self.reward[i] = grid, logic, action, reward
        self.next_grid[i], self.next_logic[i], self.done[i], self.next_mask[i] = next_grid, next_logic, done, next_mask
        self.pos = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, rng: np.random.Generator, batch: int) -> dict[str, np.ndarray]:
        idx = rng.integers(0, self.size, size=batch)
        return {f: getattr(self, f)[idx] for f in self.FIELDS}

    def save(self, path: Path) -> None:
        n = self.size
        np.savez(path, size=n, pos=self.pos, **{f: getattr(self, f)[:n] for f in self.FIELDS})

    def load(self, path: Path) -> None:
        with np.load(path) as d:
            n = int(d["size"])
            for f in self.FIELDS:
                getattr(self, f)[:n] = d[f]
            self.size, self.pos = n, int(d["pos"])
