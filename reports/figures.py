"""Matplotlib figures (PNG and PDF). Everything plotted is computed in ``reports.metrics``."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402

LABELS = {"energy": "energy [Wh]", "travel_time": "travel time [s]"}


def save(fig, out: Path, name: str) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{name}.png", out / f"{name}.pdf"]
    fig.savefig(paths[0], dpi=120, bbox_inches="tight")
    fig.savefig(paths[1], bbox_inches="tight")
    plt.close(fig)
    return paths


def violins(groups: pd.DataFrame, methods: list[str], signals: str, out: Path) -> list[Path]:
    """fig:rwd_bar: per-method distributions of the seed-group means."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, metric in zip(axes, ("energy", "travel_time")):
        data = [groups[(groups.method == m) & (groups.signals == signals)][metric].to_numpy() for m in methods]
        ax.violinplot(data, showmedians=True)
        ax.set_xticks(range(1, len(methods) + 1), methods)
        ax.set_xlabel("method")
        ax.set_ylabel(LABELS[metric])
        ax.grid(alpha=0.3)
    fig.suptitle(f"{signals}: seed-group means ({groups.group.nunique()} groups)")
    return save(fig, out, f"violin-{signals}")


def trajectories(trajs: dict[str, pd.DataFrame], bands: pd.DataFrame, title: str, out: Path, name: str) -> list[Path]:
    """fig:compare1/2: time-distance with signal bands at each stop line, time-speed, cumulative energy."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    for _, b in bands.iterrows():
        axes[0].plot([b.t_start, b.t_end], [b.x, b.x], color="tab:green" if b.green else "tab:red", lw=3,
                     solid_capstyle="butt")
    for method, tr in trajs.items():
        axes[0].plot(tr.t, tr.distance, label=method)
        axes[1].plot(tr.t, tr.speed, label=method)
        axes[2].plot(tr.t, tr.energy, label=method)
    for ax, ylab in zip(axes, ("distance [m]", "speed [m/s]", "cumulative energy [Wh]")):
        ax.set_xlabel("time since entry [s]")
        ax.set_ylabel(ylab)
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle(title)
    return save(fig, out, name)
