"""Matplotlib figures (PNG and PDF). Everything plotted is computed in ``reports.metrics``."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

from ecodrive_bench.bench.io import atomic_file  # noqa: E402

from .names import name  # noqa: E402

LABELS = {"energy": "energy [Wh]", "travel_time": "travel time [s]"}


def shared_legend(fig, *axes) -> None:
    """One legend for all panels, below them, so that it hides no curve: the entries of ``axes``,
    each label once (in the order met); none where no line has a label."""
    entries: dict[str, object] = {}
    for ax in axes:
        for handle, label in zip(*ax.get_legend_handles_labels()):
            entries.setdefault(label, handle)
    if entries:
        fig.legend(list(entries.values()), list(entries), loc="lower center", ncol=min(len(entries), 8), frameon=False)
    fig.tight_layout(rect=(0, 0.35 / fig.get_figheight() if entries else 0, 1, 1))  # a 0.35 in strip for it


def save(fig, out: Path, name: str) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / f"{name}.png", out / f"{name}.pdf"]
    if fig.get_layout_engine() is None:
        fig.tight_layout()  # stacked panels: a title must not sit on the x label above it
    with atomic_file(paths[0]) as f:  # never through a link planted under the name
        fig.savefig(f, format="png", dpi=120, bbox_inches="tight")
    with atomic_file(paths[1]) as f:
        fig.savefig(f, format="pdf", bbox_inches="tight")
    plt.close(fig)
    return paths


def violins(groups: pd.DataFrame, methods: list[str], signals: str, out: Path) -> list[Path]:
    """fig:rwd_bar: per-method distributions of the seed-group means."""
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, metric in zip(axes, ("energy", "travel_time")):
        data = [groups[(groups.method == m) & (groups.signals == signals)][metric].to_numpy() for m in methods]
        ax.violinplot(data, showmedians=True)
        ax.set_xticks(range(1, len(methods) + 1), [name(m) for m in methods], rotation=30, ha="right")  # 8 names fit a panel
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
        style = {"ls": "--", "color": "black", "lw": 1} if tr.energy.isna().all() else {}  # a plan: no energy
        axes[0].plot(tr.t, tr.distance, label=method, **style)
        axes[1].plot(tr.t, tr.speed, label=method, **style)
        if not style:
            axes[2].plot(tr.t, tr.energy, label=method)
    for ax, ylab in zip(axes, ("distance [m]", "speed [m/s]", "cumulative energy [Wh]")):
        ax.set_xlabel("time since entry [s]")
        ax.set_ylabel(ylab)
        ax.grid(alpha=0.3)
    fig.suptitle(title)
    shared_legend(fig, axes[0])
    return save(fig, out, name)


def reward_study(curves: pd.DataFrame, out: Path) -> list[Path]:
    """fig:rwd_compare: smoothed energy and travel time per training episode, band = seed range."""
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    for ax, metric in zip(axes, ("energy", "travel_time")):
        for config, g in curves.groupby("config"):
            ax.plot(g.episode, g[metric], label=config)
            ax.fill_between(g.episode, g[f"{metric}_lo"], g[f"{metric}_hi"], alpha=0.2)
        ax.set_xlabel("training episode")
        ax.set_ylabel(LABELS[metric])
        ax.grid(alpha=0.3)
    axes[1].legend(fontsize=7, ncol=2)
    fig.suptitle("reward study (smoothed 0.98; band = min-max over seeds)")
    return save(fig, out, "reward-study")


def heatmaps(grids: dict[str, pd.DataFrame], out: Path,
             seeds: dict[str, tuple[pd.DataFrame, pd.DataFrame]] | None = None) -> list[Path]:
    """fig:heatmap: test-case means over the |r_p^s| x |r_p^j| grid, averaged over seeds; with
    ``seeds`` (``metrics.heatmap_seeds`` per metric) each cell also shows its number of seeds and
    their range (max - min)."""
    fig, axes = plt.subplots(1, len(grids), figsize=(6.5 * len(grids), 5))
    for ax, (metric, grid) in zip(np.atleast_1d(axes), grids.items()):
        im = ax.imshow(grid.to_numpy(), origin="lower", cmap="viridis")
        ax.set_xticks(range(grid.shape[1]), [f"{v:g}" for v in grid.columns])
        ax.set_yticks(range(grid.shape[0]), [f"{v:g}" for v in grid.index])
        ax.set_xlabel("|r_p^j| [reward units]")
        ax.set_ylabel("|r_p^s| [reward units]")
        count, spread = seeds[metric] if seeds and metric in seeds else (None, None)
        for (i, j), v in np.ndenumerate(grid.to_numpy()):
            if np.isnan(v):
                continue
            text = f"{v:.1f}"
            if count is not None:
                n, r = count.iat[i, j], spread.iat[i, j]
                text += f"\n{int(n)} seed{'s' if n > 1 else ''}" + ("" if np.isnan(r) else f"\nrange {r:.1f}")
            ax.text(j, i, text, ha="center", va="center", color="k" if im.norm(v) > 0.65 else "w",  # readable on yellow
                    fontsize=6.5 if count is not None else 8)
        fig.colorbar(im, ax=ax, label=LABELS[metric])
    if seeds:
        fig.suptitle("mean over training seeds; below it, the seeds and their range (max - min)")
    return save(fig, out, "heatmap")


def mixed_panels(cells: pd.DataFrame, out: Path) -> list[Path]:
    """fig:dd / fig:avg: fleet energy and speed against demand, one line per MPR. The paper's
    means over the vehicles that finished, then (when the run has them) energy per km and
    space-mean speed over every vehicle inserted."""
    settings = sorted(set(cells.signals))
    panels = [("all_energy", "energy, finished [Wh/veh]"), ("all_speed", "mean speed, finished [m/s]"),
              ("all_energy_per_km", "energy, all inserted [Wh/km]"),
              ("all_space_mean_speed", "space-mean speed, all inserted [m/s]")]
    panels = [p for p in panels if p[0] in cells.columns]
    fig, axes = plt.subplots(len(panels), len(settings), figsize=(6 * len(settings), 4 * len(panels)), squeeze=False)
    colour = {mpr: f"C{i}" for i, mpr in enumerate(sorted(set(cells.mpr)))}  # the same MPR, the same colour
    for col, signals in enumerate(settings):
        sub = cells[cells.signals == signals]
        for row, (metric, label) in enumerate(panels):
            ax = axes[row][col]
            for mpr, g in sub.groupby("mpr"):
                ax.plot(g.demand, g[metric], marker="o", label=f"MPR {mpr:g}", color=colour[mpr])
            ax.set_xlabel("demand [veh/h/lane]")
            ax.set_ylabel(label)
            ax.set_title(signals)
            ax.grid(alpha=0.3)
    shared_legend(fig, *axes[0])  # a setting may lack an MPR level the other has (a sweep cut short)
    return save(fig, out, "mixed-traffic")


def lateral(trajs: dict[str, pd.DataFrame], scenario: str, out: Path) -> list[Path]:
    """fig:scenario_compare: the ego's lane against position (with the scripted vehicles' lanes in
    grey), time-distance and time-speed, one line per method."""
    fig, axes = plt.subplots(1, 3, figsize=(15, 4))
    first = next(iter(trajs.values()))
    for _, g in first[first.vehicle != "ego"].groupby("vehicle"):
        axes[0].plot(g.x, g.lane, color="0.7", lw=6, alpha=0.5, solid_capstyle="butt")
        axes[1].plot(g.time - first.time.min(), g.x - first.x.min(), color="0.7", lw=1)
    for method, df in trajs.items():
        ego = df[df.vehicle == "ego"]
        axes[0].step(ego.x, ego.lane, where="post", label=method)
        axes[1].plot(ego.time - first.time.min(), ego.x - first.x.min(), label=method)
        axes[2].plot(ego.time - first.time.min(), ego.speed, label=method)
    axes[0].yaxis.get_major_locator().set_params(integer=True)
    for ax, (xl, yl) in zip(axes, (("position x [m]", "lane index (0 = rightmost) [-]"),
                                   ("time [s]", "distance [m]"), ("time [s]", "speed [m/s]"))):
        ax.set_xlabel(xl)
        ax.set_ylabel(yl)
        ax.grid(alpha=0.3)
    fig.suptitle(f"scenario {scenario} (grey: scripted HDVs)")
    shared_legend(fig, axes[0])
    return save(fig, out, f"lateral-{scenario}")


def generalisation(per_variant: pd.DataFrame, methods: list[str], signals: str, out: Path) -> list[Path]:
    """Energy and travel-time change against the baseline [%], variant x method, one setting."""
    sub = per_variant[per_variant.signals == signals]
    fig, axes = plt.subplots(1, 2, figsize=(12, 0.5 * sub.variant.nunique() + 2.2))
    for ax, col, title in zip(axes, ("energy_change", "time_change"), ("energy", "travel time")):
        grid = 100 * sub.pivot_table(index="variant", columns="method", values=col).reindex(columns=methods)
        lim = max(float(np.nanmax(np.abs(grid.to_numpy()))), 1.0) if grid.notna().any().any() else 1.0
        im = ax.imshow(grid.to_numpy(), cmap="RdBu_r", vmin=-lim, vmax=lim, aspect="auto")
        ax.set_xticks(range(grid.shape[1]), grid.columns, rotation=45, ha="right")
        ax.set_yticks(range(grid.shape[0]), grid.index)
        for (i, j), v in np.ndenumerate(grid.to_numpy()):
            if not np.isnan(v):
                ax.text(j, i, f"{v:+.0f}", ha="center", va="center", fontsize=8,
                        color="w" if abs(v) > 0.6 * lim else "k")
        ax.set_title(f"{title} vs baseline [%], {signals}")
        fig.colorbar(im, ax=ax)
    return save(fig, out, f"generalisation-{signals}")


def headroom(shares: pd.DataFrame, out: Path) -> list[Path]:
    """The share of the baseline0-to-clairvoyant cost gap each method closes, per setting, with its
    CI over cases and seeds (``reports.metrics.headroom``'s rows). The axis spans [-25, 125] % at
    least and [-100, 200] % at most; a bar or whisker beyond it is cut at the edge and its value
    written there, so one method far outside does not squeeze the others."""
    settings = sorted(set(shares.signals))
    fig, axes = plt.subplots(1, len(settings), figsize=(5 * len(settings), 3.6), squeeze=False)
    for ax, s in zip(axes[0], settings):
        g = shares[shares.signals == s].sort_values("share_closed")
        y = np.arange(len(g))
        vals = 100 * g[["share_closed", "ci_low", "ci_high"]].to_numpy(dtype=float)
        left = float(np.clip(np.nanmin(vals, initial=0.0) - 10, -100, -25))
        right = float(np.clip(np.nanmax(vals, initial=100.0) + 10, 125, 200))
        mid = np.clip(vals[:, 0], left, right)
        err = np.vstack([mid - np.clip(vals[:, 1], left, right), np.clip(vals[:, 2], left, right) - mid])
        ax.barh(y, mid, xerr=np.nan_to_num(err), color="tab:blue", alpha=0.7, capsize=3)
        for yi, v in zip(y, vals[:, 0]):
            if v < left or v > right:
                ax.text(left if v < left else right, yi, f" {v:.0f}% ", va="center",
                        ha="left" if v < left else "right", fontsize=8)
        ax.set_xlim(left, right)
        ax.set_yticks(y, [name(m) for m in g.method])
        ax.axvline(0, color="k", lw=0.8)
        ax.axvline(100, color="k", lw=0.8, ls="--")
        ax.set_xlabel("share of the baseline0-to-clairvoyant cost gap closed [%]")
        ax.set_title(s)
        ax.grid(alpha=0.3, axis="x")
    return save(fig, out, "headroom")
