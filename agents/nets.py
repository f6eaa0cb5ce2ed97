"""The paper's networks (section 4.2) and the observation scaling the agents share.

Conv block: Conv(8, k3) -> MaxPool(2) -> Conv(16, k3, pad 1) -> MaxPool(2, pad 1) -> flatten.
One deviation, stated: the first pool uses ``ceil_mode=True``. On the 60 x 5 grid the first conv
leaves 3 lane columns and a floor-mode 2-wide pool drops the third, so the leftmost lane would
never reach the features; ceil mode keeps it.
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn


class ObsScaler:
    """Scales the raw logic vector to about [-1, 1] by the observation space's bounds."""

    def __init__(self, logic_low: np.ndarray, logic_high: np.ndarray) -> None:
        self.scale = (1.0 / np.maximum(np.abs(logic_low), np.abs(logic_high)).clip(min=1e-6)).astype(np.float32)

    def logic(self, logic: np.ndarray) -> np.ndarray:
        return logic * self.scale


class ConvBlock(nn.Module):
    """One network's conv weights. Networks that see the same grid run their blocks together in
    ``trunks`` (one grouped pass), which is what makes an update affordable on one CPU core."""

    def __init__(self) -> None:
        super().__init__()
        self.conv1 = nn.Conv2d(1, 8, 3)
        self.conv2 = nn.Conv2d(8, 16, 3, padding=1)


def trunks(grid: torch.Tensor, blocks: list[ConvBlock]) -> list[torch.Tensor]:
    """Flattened conv features of ``grid`` (B, 60, 5) for each block, in one grouped pass.

    The grid is laid out lanes-first (B, 1, 5, 60) for speed; with square 3x3 kernels and 2x2
    pools this is the paper's block on the transposed grid (a relabelling of weights).
    """
    n = len(blocks)
    x = grid.transpose(1, 2).unsqueeze(1)
    w1 = torch.cat([b.conv1.weight for b in blocks]) if n > 1 else blocks[0].conv1.weight
    b1 = torch.cat([b.conv1.bias for b in blocks]) if n > 1 else blocks[0].conv1.bias
    cl = torch.channels_last  # CPU max-pooling is ~7x faster in this layout
    x = F.max_pool2d(F.relu(F.conv2d(x, w1, b1)).contiguous(memory_format=cl), 2, ceil_mode=True)
    w2 = torch.cat([b.conv2.weight for b in blocks]) if n > 1 else blocks[0].conv2.weight
    b2 = torch.cat([b.conv2.bias for b in blocks]) if n > 1 else blocks[0].conv2.bias
    if n > 1:  # each block's conv2 sees only its own conv1 channels
        x = F.conv2d(x, w2, b2, padding=1, groups=n)
    else:
        x = F.conv2d(x, w2, b2, padding=1)
    x = F.max_pool2d(F.relu(x).contiguous(memory_format=cl), 2, padding=1)
    return [c.flatten(1) for c in x.chunk(n, dim=1)]


def trunk_dim(grid_shape: tuple[int, int]) -> int:
    with torch.no_grad():
        return trunks(torch.zeros(1, *grid_shape), [ConvBlock()])[0].shape[1]


class Head(nn.Module):
    """A network: conv block, then [features, logic (, extra inputs)] -> hidden -> outputs."""

    def __init__(self, grid_shape: tuple[int, int], logic_dim: int, extra_dim: int, hidden: tuple[int, int],
                 out_dim: int) -> None:
        super().__init__()
        self.conv = ConvBlock()
        h1, h2 = hidden
        self.mlp = nn.Sequential(
            nn.Linear(trunk_dim(grid_shape) + logic_dim + extra_dim, h1), nn.ReLU(),
            nn.Linear(h1, h2), nn.ReLU(), nn.Linear(h2, out_dim),
        )

    def from_features(self, feats: torch.Tensor, extra: torch.Tensor | None = None) -> torch.Tensor:
        return self.mlp(feats if extra is None else torch.cat([feats, extra], dim=1))

    def forward(self, grid: torch.Tensor, logic: torch.Tensor, extra: torch.Tensor | None = None) -> torch.Tensor:
        return self.from_features(torch.cat([trunks(grid, [self.conv])[0], logic], 1), extra)


def features(grid: torch.Tensor, logic: torch.Tensor, nets: list[Head]) -> list[torch.Tensor]:
    """[conv features, logic] of each net, computed in one grouped pass."""
    return [torch.cat([f, logic], 1) for f in trunks(grid, [n.conv for n in nets])]


def soft_update(target: nn.Module, source: nn.Module, tau: float) -> None:
    with torch.no_grad():
        for t, s in zip(target.parameters(), source.parameters()):
            t.lerp_(s, tau)


class OUNoise:
    """Ornstein-Uhlenbeck noise (eq. 13) drawn from a seeded numpy Generator."""

    def __init__(self, dim: int, theta: float, sigma: float, rng: np.random.Generator) -> None:
        self.theta, self.sigma, self.rng = theta, sigma, rng
        self.state = np.zeros(dim)

    def reset(self) -> None:
        self.state[:] = 0.0

    def sample(self) -> np.ndarray:
        self.state += -self.theta * self.state + self.sigma * self.rng.standard_normal(self.state.shape)
        return self.state.copy()


def linear_epsilon(episode: int, eps_init: float, eps_end: float, decay_episodes: int) -> float:
    """Eq. 12: eps = (eps_init - eps_end) * max((N - n) / N, 0) + eps_end."""
    return (eps_init - eps_end) * max((decay_episodes - episode) / decay_episodes, 0.0) + eps_end
