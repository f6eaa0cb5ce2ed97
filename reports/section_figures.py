"""The figures of the paper on this run: the distributions over seed groups per setting
(fig:rwd_bar), and the drives of SUMO's driver against a learned method on the first cases of each
setting (fig:compare1/2), with clairvoyant's drive and the oracle's cost-optimal plan where the run
has them. The step logs are read here; the drawing is ``write``'s."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import pandas as pd
from tqdm import tqdm

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.logs.mcaplog import LogError, resolve_log

from . import figures, metrics
from .html_parts import BOUND_LABEL, Figure, trajectory_caption, violin_caption
from .inputs import Run
from .load import load_plan, load_steps, stop_lines
from .names import seeded
from .top import TOP

ANCHOR = "figures"
PHASE = "Table 4, statistics, return split, violins and trajectories"
# the method drawn against SUMO's driver: the first specialist by the registry's order, else a
# rule-based method that is neither SUMO's driver nor steady driving (GLOSA)
COMPARED = tuple(m.name for m in sorted(registry.methods(installed=False), key=lambda m: (m.kind != "learned", m.order))
                 if (m.kind == "learned" and not m.generalist) or (m.kind == "rule-based" and not m.role))
TRAJECTORY_CASES = 3  # per signal setting, as in the paper's fig:compare1/2


@dataclass(frozen=True)
class Drive:
    """One trajectory figure: the drives by legend label, the signal bands, its file name and caption."""
    name: str
    title: str
    trajs: dict[str, pd.DataFrame]
    bands: pd.DataFrame
    caption: str


@dataclass(frozen=True)
class Figures:
    groups: pd.DataFrame  # metrics.group_means
    methods: tuple[str, ...]
    violins: tuple[tuple[str, str], ...]  # (signals, caption)
    compare: str | None  # the method drawn against the baseline; None: no trajectories
    shown: int  # (setting, case) pairs tried for a trajectory
    drives: tuple[Drive, ...]  # those that could be drawn
    warnings: tuple[str, ...]
    progress: bool = True  # a bar while drawing, on a terminal


def compute(run: Run, warnings: list[str]) -> Figures | None:
    res = run.results
    if res is None:
        return None
    groups, methods = metrics.group_means(res), list(run.methods)
    violins = tuple((s, violin_caption(groups, res, methods, s)) for s in sorted(set(res.signals)))
    compare = next((m for m in COMPARED if m in methods), None)
    drawn = compare is not None and "baseline" in methods
    shown = trajectory_cases(res, compare) if drawn else []
    notes: list[str] = []
    drives = [_drive(run.dir, res[res.signals == s], compare, s, case, notes) for s, case in shown]
    return Figures(groups, tuple(methods), violins, compare if drawn else None, len(shown),
                   tuple(d for d in drives if d is not None), tuple(notes), run.progress)


def trajectory_cases(results: pd.DataFrame, compare: str) -> list[tuple[str, int]]:
    """(signals, case) of the trajectory figures: the first ``TRAJECTORY_CASES`` cases per setting
    that both the baseline and ``compare`` drove."""
    out = []
    for signals in sorted(set(results.signals)):
        sub = results[results.signals == signals]
        both = sorted(set(sub[sub.method == compare].case) & set(sub[sub.method == "baseline"].case))
        out += [(signals, int(case)) for case in both[:TRAJECTORY_CASES]]
    return out


def _drive(run_dir: Path, sub: pd.DataFrame, compare: str, signals: str, case: int, notes: list[str]) -> Drive | None:
    """The baseline-against-``compare`` figure of one case (with clairvoyant's drive, the top of the
    scale the headroom is measured to, and the oracle's plan, where the run has them); None when
    neither drive can be drawn. A log that cannot be read is a note, and not drawn."""
    trajs, bands, longest = {}, None, 0
    top = [TOP] if TOP in set(sub[sub.case == case].method) else []
    for method in ("baseline", compare, *top):
        rows = sub[(sub.method == method) & (sub.case == case)].sort_values("train_seed")
        row = rows.iloc[0]  # a learned method's lowest training seed, named in the legend and caption
        try:
            steps, warn = load_steps(resolve_log(run_dir, row.mcap))
        except LogError as e:
            notes.append(str(e))
            continue
        if warn:  # a partial log is never drawn as a whole drive
            notes.append(f"{warn} (not drawn)")
            continue
        seed = int(row.train_seed) if pd.notna(row.train_seed) else None
        trajs[seeded(method, seed)] = metrics.trajectory(steps)
        if len(steps) > longest:  # bands over the longer drive
            longest, bands = len(steps), metrics.signal_bands(steps, *stop_lines(steps))
    plan = _bound_plan(run_dir, sub, case, notes) if trajs else None
    if plan is not None:
        trajs[BOUND_LABEL] = plan
    if not trajs or bands is None:
        return None
    return Drive(f"compare-{signals}-case{case:03d}", f"{signals}, case {case}", trajs, bands,
                 trajectory_caption(list(trajs), signals, case))


def _bound_plan(run_dir: Path, sub: pd.DataFrame, case: int, notes: list[str]) -> pd.DataFrame | None:
    """The cost-optimal plan of ``case``, from the oracle's log when the run has one."""
    rows = sub[(sub.method == "oracle") & (sub.case == case)]
    if rows.empty:
        return None
    try:
        return load_plan(resolve_log(run_dir, rows.mcap.iloc[0]))
    except LogError as e:
        notes.append(str(e))
        return None


def write(d: Figures, out: Path) -> None:
    """Draw the figures (PNG and PDF under ``out/figures``), with a bar on a terminal."""
    with tqdm(total=len(d.violins) + d.shown, desc="figures", unit="fig",
              disable=None if d.progress else True) as bar:  # None: off where stderr is no terminal
        for signals, _ in d.violins:
            figures.violins(d.groups, list(d.methods), signals, out / "figures")
            bar.update(1)
        for drive in d.drives:
            figures.trajectories(drive.trajs, drive.bands, drive.title, out / "figures", drive.name)
            bar.update(1)
        bar.update(d.shown - len(d.drives))


def figures_of(d: Figures) -> list[Figure]:
    return ([Figure(Path(f"violin-{s}.png"), caption, f"violin, {s}") for s, caption in d.violins]
            + [Figure(Path(f"{v.name}.png"), v.caption, v.title.replace(",", "")) for v in d.drives])


def markdown(d: Figures) -> str:
    lines = ["## Distributions over seed groups (fig:rwd_bar)", ""]
    lines += [line for s, _ in d.violins for line in (f"![violin {s}](figures/violin-{s}.png)", "")]
    if d.compare is not None:
        lines += [f"## Trajectories: baseline against {d.compare} (fig:compare1/2)", ""]
        if d.compare != "prl":
            lines += [f"PRL is not in this run; {d.compare} is shown instead.", ""]
    lines += [line for v in d.drives for line in (f"![{v.name}](figures/{v.name}.png)", "")]
    return "\n".join(lines)
