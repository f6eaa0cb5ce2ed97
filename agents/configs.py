"""The learning agents' config dataclasses (CleanRL's typed ``Args``: every field with its meaning,
unit and range), apart from the torch modules that use them: ``ecodrive train --help`` lists
them, and a help imports no torch. Each algorithm's file (``pdqn.py``, ``dqn.py``, ``ddpg.py``)
re-exports its own."""
from __future__ import annotations

from dataclasses import dataclass

from ecodrive_bench.envs.validation import param

from .base import check_config

PDQN_NAMES = {False: "prl", True: "mpdqn"}  # the algorithm name of each PDQNConfig.multipass


@dataclass
class PDQNConfig:
    gamma: float = param(0.99, 0.0, 1.0, unit="-",
                          doc="discount factor (Table 2)")
    tau_q: float = param(0.01, 0.0, 1.0, unit="1/update", lo_open=True,
                          doc="soft-update rate of the target Q network, tau_1 (Table 2)")
    tau_param: float = param(0.001, 0.0, 1.0, unit="1/update", lo_open=True,
                              doc="soft-update rate of the target parameter network, tau_2 (Table 2)")
    lr_q: float = param(1e-4, 0.0, 1.0, unit="-", lo_open=True,
                         doc="Adam step size of the Q network, alpha (Table 2)")
    lr_param: float = param(1e-5, 0.0, 1.0, unit="-", lo_open=True,
                             doc="Adam step size of the parameter network, beta (Table 2)")
    batch_size: int = param(128, 1, None, unit="transitions",
                             doc="minibatch size B (Table 2)")
    replay_size: int = param(500_000, 1, None, unit="transitions",
                              doc="replay capacity R (Table 2)")
    eps_init: float = param(1.0, 0.0, 1.0, unit="-",
                             doc="initial exploration factor (Table 2)")
    eps_end: float = param(0.01, 0.0, 1.0, unit="-",
                            doc="final exploration factor (Table 2)")
    eps_decay_episodes: int = param(1000, 1, None, unit="episodes",
                                     doc="episodes of linear decay, N in eq. 12 (Table 2)")
    ou_theta: float = param(0.15, 0.0, 1.0, unit="1/step",
                             doc="OU mean reversion per step (eq. 13; not in the paper: DDPG's usual value)")
    ou_sigma: float = param(0.2, 0.0, None, unit="-",
                             doc="OU noise scale, in units of the half action range (not in the paper)")
    learning_starts: int = param(1000, 0, None, unit="transitions",
                                  doc="transitions stored before the first update (not in the paper)")
    reward_scale: float = param(0.01, 0.0, None, unit="-", lo_open=True,
                                 doc="rewards are multiplied by this for learning (raw rewards are ~1e2)")
    grad_clip: float = param(10.0, 0.0, None, unit="-", lo_open=True,
                              doc="max gradient norm per network (not in the paper)")
    multipass: bool = param(False, doc="MP-DQN's multi-pass Q evaluation (beyond the paper)")
    n_step: int = param(1, 1, 100, unit="steps",
                         doc="n-step Bellman targets, gamma^m max_k Q'(s_{t+m}) after m <= n rewards (1 = the paper; beyond the paper)")
    twin_q: bool = param(False, doc="clipped double Q (TD3, Fujimoto et al. 2018): two Q networks, targets use their minimum (beyond the paper)")
    seed: int = param(0, 0, None, unit="-",
                       doc="seeds network initialisation and the agent's numpy Generator")

    def __post_init__(self) -> None:
        check_config(self)


@dataclass
class DQNConfig:
    gamma: float = param(0.99, 0.0, 1.0, unit="-",
                          doc="discount factor (Table 2)")
    tau: float = param(0.01, 0.0, 1.0, unit="1/update", lo_open=True,
                        doc="soft-update rate of the target network, tau_1 (Table 2)")
    lr: float = param(1e-4, 0.0, 1.0, unit="-", lo_open=True,
                       doc="Adam step size, alpha (Table 2)")
    batch_size: int = param(128, 1, None, unit="transitions",
                             doc="minibatch size (Table 2)")
    replay_size: int = param(500_000, 1, None, unit="transitions",
                              doc="replay capacity (Table 2)")
    eps_init: float = param(1.0, 0.0, 1.0, unit="-",
                             doc="initial exploration factor (Table 2)")
    eps_end: float = param(0.01, 0.0, 1.0, unit="-",
                            doc="final exploration factor (Table 2)")
    eps_decay_episodes: int = param(1000, 1, None, unit="episodes",
                                     doc="episodes of linear decay (eq. 12)")
    learning_starts: int = param(1000, 0, None, unit="transitions",
                                  doc="transitions stored before the first update (not in the paper)")
    reward_scale: float = param(0.01, 0.0, None, unit="-", lo_open=True,
                                 doc="rewards are multiplied by this for learning")
    grad_clip: float = param(10.0, 0.0, None, unit="-", lo_open=True,
                              doc="max gradient norm (not in the paper)")
    seed: int = param(0, 0, None, unit="-",
                       doc="seeds network initialisation and the agent's numpy Generator")

    def __post_init__(self) -> None:
        check_config(self)


@dataclass
class DDPGConfig:
    gamma: float = param(0.99, 0.0, 1.0, unit="-",
                          doc="discount factor (Table 2)")
    tau_critic: float = param(0.01, 0.0, 1.0, unit="1/update", lo_open=True,
                               doc="soft-update rate of the target critic, tau_1 (Table 2)")
    tau_actor: float = param(0.001, 0.0, 1.0, unit="1/update", lo_open=True,
                              doc="soft-update rate of the target actor, tau_2 (Table 2)")
    lr_critic: float = param(1e-4, 0.0, 1.0, unit="-", lo_open=True,
                              doc="Adam step size of the critic, alpha (Table 2)")
    lr_actor: float = param(1e-5, 0.0, 1.0, unit="-", lo_open=True,
                             doc="Adam step size of the actor, beta (Table 2)")
    batch_size: int = param(128, 1, None, unit="transitions",
                             doc="minibatch size (Table 2)")
    replay_size: int = param(500_000, 1, None, unit="transitions",
                              doc="replay capacity (Table 2)")
    ou_theta: float = param(0.15, 0.0, 1.0, unit="1/step",
                             doc="OU mean reversion per step (not in the paper)")
    ou_sigma: float = param(0.2, 0.0, None, unit="-",
                             doc="OU noise scale in units of the half action range (not in the paper)")
    learning_starts: int = param(1000, 0, None, unit="transitions",
                                  doc="transitions stored before the first update (not in the paper)")
    reward_scale: float = param(0.01, 0.0, None, unit="-", lo_open=True,
                                 doc="rewards are multiplied by this for learning")
    grad_clip: float = param(10.0, 0.0, None, unit="-", lo_open=True,
                              doc="max gradient norm per network (not in the paper)")
    bound: str = param("invert", choices=("invert", "tanh"),
                        doc="'invert': inverting gradients at [-1, 1]; 'tanh': squash (saturates, see above)")
    seed: int = param(0, 0, None, unit="-",
                       doc="seeds network initialisation and the agent's numpy Generator")

    def __post_init__(self) -> None:
        check_config(self)
