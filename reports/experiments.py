"""Report sections of section 5.2 and 5.5: reward study, sensitivity heatmap, lateral scenarios,
mixed traffic (``compute``, ``write``, ``markdown``; ``reports.section_experiments`` lists them).

Each reads what ``bench.experiments.sweep`` and ``bench.experiments.mixed`` left in the run folder (parquet tables and
the copied ``/train`` logs); a missing experiment is simply not reported.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from ecodrive_bench.bench.paper import FLEET_SAVING as PAPER_FLEET_SAVING
from ecodrive_bench.bench.paper import HDV_TOL, HEATMAP_CHOICE, SPEED_LOSS_TOL
from ecodrive_bench.bench.paper import TRAINING_EPISODES as PAPER_TRAINING_EPISODES

from . import claims, figures, metrics, tables
from .load import RunError, load_run

MPR_BREAKDOWN_DEMANDS = (200.0, 700.0)  # veh/h/lane, the paper's CV vs HDV breakdown


def present(run_dir: Path) -> bool:
    return any((run_dir / p).is_file() for p in ("reward/sweep.parquet", "heatmap/sweep.parquet",
                                                 "mixed/mixed.parquet", "lateral/lateral.parquet"))


@dataclass(frozen=True)
class Found:
    """What the report shows of the experiments in a run folder; an experiment's part is None where
    its table is absent, an empty table where its sweep started and no job finished."""
    reward: pd.DataFrame | None = None  # reward/sweep.parquet
    train: pd.DataFrame | None = None  # the reward study's training curves (``_train_logs``)
    reward_baseline: float | None = None  # SUMO's driver's energy on the study's cases
    heatmap: pd.DataFrame | None = None  # heatmap/sweep.parquet
    lateral: pd.DataFrame | None = None  # lateral/lateral.parquet
    drives: tuple[tuple[str, dict[str, pd.DataFrame]], ...] = ()  # (scenario, drives by label) drawn
    mixed: pd.DataFrame | None = None  # mixed/mixed.parquet
    warnings: tuple[str, ...] = ()


def compute(run_dir: Path) -> Found:
    """Read every experiment found in ``run_dir`` (no file written)."""
    warnings: list[str] = []
    parts: dict = {}
    reward = run_dir / "reward" / "sweep.parquet"
    if reward.is_file():
        sweep = pd.read_parquet(reward)
        parts["reward"] = sweep
        if not sweep.empty:
            parts["train"] = _train_logs(sweep, warnings)
            parts["reward_baseline"] = _baseline_energy(run_dir, sweep)
    heat = run_dir / "heatmap" / "sweep.parquet"
    if heat.is_file():
        parts["heatmap"] = pd.read_parquet(heat)
    lateral = run_dir / "lateral" / "lateral.parquet"
    if lateral.is_file():
        summary = pd.read_parquet(lateral)
        if "train_seed" not in summary:
            summary["train_seed"] = pd.array([None] * len(summary), dtype="Int64")
        parts["lateral"], parts["drives"] = summary, _lateral_drives(run_dir, summary, warnings)
    mixed = run_dir / "mixed" / "mixed.parquet"
    if mixed.is_file():
        rows = pd.read_parquet(mixed)
        cover = metrics.mixed_coverage(rows)
        if cover.missing.any():
            warnings.append(f"{mixed}: the mixed-traffic sweep is unfinished ({int(cover.cells.sum())} cells, "
                            f"{int(cover.missing.sum())} missing from the grid they span); its figure and "
                            f"tables show the finished cells only")
        if "duration" in rows and rows.duration.nunique() > 1:
            warnings.append(f"{mixed}: cells of different durations ({sorted(rows.duration.unique())} s) are mixed")
        parts["mixed"] = rows
    return Found(**parts, warnings=tuple(warnings))


def _lateral_drives(run_dir: Path, summary: pd.DataFrame,
                    warnings: list[str]) -> tuple[tuple[str, dict[str, pd.DataFrame]], ...]:
    """Each scenario's drives by legend label, a method's lowest seed; a missing one is a warning."""
    out = []
    for name, g in summary.groupby("scenario"):
        trajs = {}
        for m, seed in g.groupby("method", sort=False).train_seed.first().items():
            label, stem = (m, m) if pd.isna(seed) else (f"{m} s{seed}", f"{m}-s{seed}")
            path = run_dir / "lateral" / name / f"{stem}.parquet"
            if path.is_file():
                trajs[label] = pd.read_parquet(path)
            else:
                warnings.append(f"{path}: missing; scenario {name} drawn without {label}")
        if trajs:
            out.append((name, trajs))
    return tuple(out)


def write(d: Found, out: Path) -> None:
    """Draw the experiments' figures under ``out/figures``."""
    figs = out / "figures"
    if d.train is not None and not d.train.empty:
        figures.reward_study(metrics.reward_curves(d.train), figs)
    if d.heatmap is not None and not d.heatmap.empty:
        grids, seeds = _heat(d.heatmap)
        figures.heatmaps(grids, figs, seeds)
    for name, trajs in d.drives:
        figures.lateral(trajs, name, figs)
    if d.mixed is not None:
        figures.mixed_panels(metrics.mixed_cells(d.mixed), figs)


def images(d: Found) -> list[tuple[str, Path]]:
    """(title, PNG) of each figure ``write`` draws, in the page's order."""
    out = [("reward study", Path("reward-study.png"))] if d.train is not None and not d.train.empty else []
    out += [("sensitivity heatmap", Path("heatmap.png"))] if d.heatmap is not None and not d.heatmap.empty else []
    out += [(f"lateral scenario {name}", Path(f"lateral-{name}.png")) for name, _ in d.drives]
    return out + ([("mixed traffic", Path("mixed-traffic.png"))] if d.mixed is not None else [])


def _heat(sweep: pd.DataFrame) -> tuple[dict, dict]:
    grids = {m: metrics.heatmap_grid(sweep, m) for m in ("energy", "travel_time")}
    return grids, {m: metrics.heatmap_seeds(sweep, m) for m in grids}


def markdown(d: Found) -> list[str]:
    """The experiments' sections, in the order reward study, heatmap, lateral, mixed traffic."""
    md: list[str] = []
    if d.reward is not None and d.reward.empty:  # a sweep started, no job finished yet
        md += ["## Reward study (fig:rwd_compare)", "", "No job of the reward study has finished yet.", ""]
    if d.reward is not None and not d.reward.empty:
        sweep = d.reward
        md += ["## Reward study (fig:rwd_compare)", "",
               f"{_jobs_text(sweep)}, "
               f"{_budget(sweep)} each; each validation-selected policy is "
               f"evaluated greedily on the first {int(sweep.cases.max())} test cases.", ""]
        if d.train is not None and not d.train.empty:
            md += ["![reward study](figures/reward-study.png)", ""]
        cols = ["energy", "travel_time", "lane_changes", "collisions", "selected_episode"]
        cols += ["finished"] if "finished" in sweep else []  # share of test trips that reached the end
        md += [_table(sweep.groupby("config")[cols].mean()), ""]
        md += ["The paper's claims on these jobs (`reports/claims.py`):", "",
               _table(claims.reward_claims(sweep, d.reward_baseline).set_index("claim")), ""]
    if d.heatmap is not None and d.heatmap.empty:
        md += ["## Sensitivity heatmap (fig:heatmap)", "", "No cell of the heatmap has finished yet.", ""]
    if d.heatmap is not None and not d.heatmap.empty:
        md += _heatmap_lines(d.heatmap)
    if d.lateral is not None:
        md += _lateral_lines(d.lateral, d.drives)
    if d.mixed is not None:
        md += _mixed_lines(d.mixed)
    return md


def _heatmap_lines(sweep: pd.DataFrame) -> list[str]:
    grids, seeds = _heat(sweep)
    best = sweep.loc[sweep.energy.idxmin()]
    return ["## Sensitivity heatmap (fig:heatmap)", "",
            f"|r_p^c| = 50; {_budget(sweep)}; {int(sweep.cases.max())} test cases per "
            f"cell. Lowest energy at |r_p^s| = {best.reward_speed_penalty:g}, |r_p^j| = {best.reward_jerk_penalty:g} "
            f"(the paper chose {HEATMAP_CHOICE[0]:g} and {HEATMAP_CHOICE[1]:g}).", "", "![heatmap](figures/heatmap.png)", "",
            "Each cell is the mean over its training seeds.", "",
            "Energy [Wh]:", "", _table(grids["energy"]), "", "Travel time [s]:", "", _table(grids["travel_time"]), "",
            "Training seeds per cell:", "", _table(seeds["energy"][0]), "",
            "Range over the seeds (max - min; empty with one seed), energy [Wh]:", "", _table(seeds["energy"][1]), "",
            "and travel time [s]:", "", _table(seeds["travel_time"][1]), "",
            "The paper's claims on these cells (`reports/claims.py`):", "",
            _table(claims.heatmap_claims(sweep).set_index("claim")), ""]


def _lateral_lines(summary: pd.DataFrame, drives: tuple[tuple[str, dict], ...]) -> list[str]:
    md = ["## Lateral scenarios (fig:scenario, fig:scenario_compare)", "",
          "A: HDV1 ahead brakes at -2 m/s^2 for three steps, HDV2 in the left lane. B: a platoon of five "
          "queues at a red light, two vehicles queue in the left lane. Policies are the shipped "
          "uncoordinated ones, every training seed; the figures draw each method's lowest seed.", "",
          _table(summary.set_index(["scenario", "method", "train_seed"])), ""]
    what = {"A": "leave HDV1's lane", "B": "end in the lane with the shortest queue"}
    md += [f"- {r.method}, scenario {r.scenario}: {r.papers_behaviour} of {r.runs} runs show the paper's "
           f"behaviour ({what.get(r.scenario, '?')}); {r.change_lanes} change lanes at all"
           for r in metrics.lateral_behaviour(summary).itertuples()] + [""]
    return md + [line for name, _ in drives for line in (f"![scenario {name}](figures/lateral-{name}.png)", "")]


def _mixed_lines(rows: pd.DataFrame) -> list[str]:
    cover, cells = metrics.mixed_coverage(rows), metrics.mixed_cells(rows)
    effect = metrics.mpr_effect(metrics.mixed_cells(metrics.common_runs(rows)))
    spread = metrics.mpr_effect_spread(rows)
    br = cells[cells.demand.isin(MPR_BREAKDOWN_DEMANDS) & (cells.signals == "uncoordinated")]
    cols = ["mpr", "demand"] + [c for c in (f"{k}_{m}" for k in ("cv", "hdv") for m in (
        "energy", "travel_time", "speed", "energy_per_km", "space_mean_speed", "unfinished"))
        if c in cells.columns] + [c for c in ("cv_stall_steps", "cv_longest_stall_s") if c in cells.columns]
    md = ["## Mixed traffic (fig:dd, fig:avg)", "", "![mixed traffic](figures/mixed-traffic.png)", "",
          "Cells finished per setting and MPR (`missing`: demand x repetition pairs of the "
          "setting's grid not run yet):", "", _table(cover.set_index(["signals", "mpr"])), "",
          "Fleet metrics by MPR (mean over the demand x repetition pairs that every MPR level "
          "has), change against MPR = 0. `energy` and `speed` "
          "are the paper's means over the vehicles that finished in the run; `energy_per_km` and "
          "`space_mean_speed` count every vehicle inserted, finished or not, so a policy that "
          "congests the arterial cannot look better by keeping its slow vehicles inside:", "",
          _table(effect.set_index(["signals", "mpr"])), ""]
    md += ["The paper's claims on these cells (the regression check's tolerances, "
           "`docs/regression.md`):", "",
           _table(claims.mixed_claims(effect, SPEED_LOSS_TOL, HDV_TOL, PAPER_FLEET_SAVING).set_index(["signals", "claim"])), ""]
    if not spread.empty:
        md += ["The same changes within each finished repetition (every repetition drives the same "
               "traffic draw at every MPR): mean, min and max over the repetitions:", "",
               _table(spread.set_index(["signals", "mpr"])), ""]
    md += ["CVs against HDVs, uncoordinated, 200 and 700 veh/h/lane:", "",
           _table(br[cols].set_index(["mpr", "demand"])) if not br.empty else "(not in this run)", ""]
    return md


def _budget(sweep: pd.DataFrame) -> str:
    """The training length of a sweep's jobs, flagged when shorter than the paper's."""
    episodes = int(sweep.episodes.max())
    recipe = ""
    for c in (c for c in sweep.columns if c.startswith("agent_")):  # agent config fields departing from Table 2
        values = "/".join(f"{v:g}" if isinstance(v, float) else str(v) for v in sorted(set(sweep[c].dropna())))
        n = int(sweep[c].notna().sum())
        recipe += (f" by PRL's recipe ({c.removeprefix('agent_')} {values} beside Table 2)" if n == len(sweep) else
                   f" ({n} of {len(sweep)} jobs by PRL's recipe, {c.removeprefix('agent_')} {values}; the others by Table 2)")
    if episodes >= PAPER_TRAINING_EPISODES:
        return f"{episodes} training episodes{recipe}"
    return (f"{episodes} training episodes{recipe} (shorter than the paper's {PAPER_TRAINING_EPISODES}, epsilon "
            f"decaying over {episodes}: a short-budget variant)")


def _baseline_energy(run_dir: Path, sweep: pd.DataFrame) -> float | None:
    """SUMO's driver's mean energy [Wh] over the test cases the sweep's jobs ran (the first
    ``cases``), from the run folder's ``results.parquet`` as checked and cleaned by ``load_run``;
    None where it lacks them."""
    if not (run_dir / "results.parquet").is_file():
        return None
    try:
        r = load_run(run_dir)[0]
    except (RunError, OSError):
        return None
    signals, cases = sweep.signals.iloc[0], int(sweep.cases.max())
    b = r[(r.method == "baseline") & (r.signals == signals) & (r.case < cases)]
    return float(b.energy.mean()) if b.case.nunique() == cases and sweep.signals.nunique() == 1 else None


def _train_logs(sweep: pd.DataFrame, warnings: list[str]) -> pd.DataFrame:
    """Per-episode training energy and travel time of every job, from the ``metrics.parquet`` in its
    log folder (a job restored from the sweep store has no ``train.mcap``)."""
    frames = []
    for r in sweep.itertuples():
        path = Path(r.log_dir) / "metrics.parquet"
        try:
            m = pd.read_parquet(path, columns=["episode", "energy", "travel_time"])
        except (OSError, ValueError, KeyError) as e:
            warnings.append(f"{path}: no training metrics ({e})")
            continue
        frames.append(m.assign(config=r.config, seed=r.seed))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def _jobs_text(sweep: pd.DataFrame) -> str:
    """'18 jobs: 9 configurations, 1-3 training seeds each' (or 'x 3 seeds' when every one has them all)."""
    per = sweep.groupby("config").seed.nunique()
    lo, hi = int(per.min()), int(per.max())
    if lo == hi == sweep.seed.nunique():
        return f"{len(per)} configurations x {hi} seed{'s' if hi > 1 else ''}"
    return f"{len(sweep)} jobs: {len(per)} configurations, {lo if lo == hi else f'{lo}-{hi}'} training seeds each"


def _table(df: pd.DataFrame) -> str:
    return tables.frame_markdown(df)
