"""Build the report of a run folder (``build``): Table 4, statistics, violin and trajectory figures,
and the sections found in it or given beside it (further experiments, held-out and real
corridors). The command (its options, ``--readme``, the exit codes) is ``reports.command``,
which imports this module once its options are read, so that ``--help`` imports nothing heavy."""
from __future__ import annotations

from pathlib import Path

import pandas as pd
from tqdm import tqdm

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.io import atomic_csv, atomic_text
from ecodrive_bench.bench.io.outdir import staged
from ecodrive_bench.bench.logs.mcaplog import LogError, resolve_log
from ecodrive_bench.bench.paper import FLEET_SAVING, HDV_TOL, SPEED_LOSS_TOL

from . import bound_sections, claims, experiments, figures, generalisation, headline, metrics, real, stats, tables
from .headline import LEARNED
from .html import render
from .html_markdown import experiment_caption
from .html_parts import BOUND_LABEL, Figure, Page, trajectory_caption, violin_caption
from .load import (
    RunError,
    case_set_warnings,
    component_sums,
    load_plan,
    load_run,
    load_steps,
    read_manifest,
    stop_lines,
    unfinished_warnings,
)
from .names import seeded
from .top import TOP

METHOD_ORDER = headline.ORDER  # the registry's order of methods (bench.registry)
# the method drawn against SUMO's driver: the first specialist by the registry's order, else a
# rule-based method that is neither SUMO's driver nor steady driving (GLOSA)
_COMPARED = tuple(m.name for m in sorted(registry.methods(installed=False), key=lambda m: (m.kind != "learned", m.order))
                  if (m.kind == "learned" and not m.generalist) or (m.kind == "rule-based" and not m.role))
TRAJECTORY_CASES = 3  # per signal setting, as in the paper's fig:compare1/2
RECORD = ".report-files.json"  # the files the last report wrote into its folder (paths relative to it)


def build(run_dir: Path, out: Path, gen_dir: Path | None = None, progress: bool = True,
          force_into: bool = False, real_dir: Path | None = None) -> tuple[Path, list[str]]:
    """Write the report of ``run_dir`` into ``out``: the path of ``index.md`` (in ``out`` resolved)
    and the warnings. ``out`` must be new, empty or an earlier report's folder unless
    ``force_into`` (``bench.io.outdir``). The parts whose time grows with the run, reading every
    step log for the return split and drawing the figures, show bars with an ETA on stderr where it
    is a terminal (``progress=False``: never; a CI log gets none either way)."""
    if not run_dir.is_dir():
        raise RunError(f"{run_dir}: not a run folder (a directory written by `ecodrive run`)")
    if gen_dir is not None and not gen_dir.is_dir():
        raise RunError(f"--generalisation {gen_dir}: not a run folder (written by `ecodrive run --profile "
                       f"generalisation`)")
    if gen_dir is None and generalisation.present(run_dir):
        gen_dir = run_dir
    notes: list[str] = []  # rows dropped from the family tables: the report's warnings
    if gen_dir is not None:
        notes += generalisation.load(gen_dir)[2]  # a bad table is one line before anything is written
    if real_dir is not None and not real_dir.is_dir():
        raise RunError(f"--real {real_dir}: not a run folder (written by `ecodrive run --profile real`)")
    if real_dir is None and real.present(run_dir):
        real_dir = run_dir
    if real_dir is not None:
        notes += real.load(real_dir)[2]  # a bad table is one line before anything is written
    if (not (run_dir / "results.parquet").is_file() and not experiments.present(run_dir)
            and not generalisation.present(run_dir) and not real.present(run_dir)):
        raise RunError(f"{run_dir}: no results.parquet and no experiment folders (is this a folder written by "
                       f"`ecodrive run`?)")
    with staged(out, RECORD, force_into) as stage:  # an Unwritable (OSError) or InUse: one line, nothing written
        _, warnings = _write(run_dir, stage.scratch, gen_dir, progress, real_dir, notes)
    return stage.out / "index.md", warnings


class _Phases:
    """One line on stdout as each phase of the build ends, with its time (a redirected log shows
    where the time goes; stderr keeps the warnings and the one error line; ``progress=False``:
    none)."""

    def __init__(self, enabled: bool) -> None:
        import time

        self.enabled, self.clock = enabled, time.perf_counter
        self.start = self.last = self.clock()

    def done(self, what: str) -> None:
        now = self.clock()
        if self.enabled:
            print(f"report: {what} in {now - self.last:.1f} s ({now - self.start:.0f} s in all)", flush=True)
        self.last = now


def _write(run_dir: Path, out: Path, gen_dir: Path | None, progress: bool,
           real_dir: Path | None = None, notes: list[str] | None = None) -> tuple[Path, list[str]]:
    """``build``'s writing, after its checks."""
    page = Page(run_name=run_dir.name)
    phases = _Phases(progress)
    if (run_dir / "results.parquet").is_file():
        md, warnings = _single_vehicle(run_dir, out, page, progress)
        phases.done("Table 4, statistics, return split, violins and trajectories")
    else:
        md, warnings = [f"# Report: {run_dir.name}", ""], []
        page.manifest = _manifest(run_dir)
    emd, eimages, ewarnings = experiments.sections(run_dir, out)
    if emd:
        phases.done("the experiments' sections")
    if gen_dir is not None:
        ind = load_run(run_dir)[0] if (run_dir / "results.parquet").is_file() else None
        gmd, gimages = generalisation.section(gen_dir, out, METHOD_ORDER, ind)
        emd, eimages = gmd + emd, gimages + eimages
        phases.done("the held-out corridors' section")
    if real_dir is not None:
        paper = load_run(run_dir)[0] if (run_dir / "results.parquet").is_file() else None
        heldout = generalisation.load(gen_dir)[0] if gen_dir is not None else None  # its notes: in ``notes``
        emd = real.section(real_dir, out, METHOD_ORDER, paper, heldout) + emd
        phases.done("the real corridors' section")
    md, warnings = md + emd, warnings + ewarnings + list(notes or [])
    if warnings:
        md += ["## Warnings", ""] + [f"- {w}" for w in warnings] + [""]
    atomic_text("\n".join(md), out / "index.md")
    page.experiments_md = page.experiments_md + emd
    page.experiment_figures = page.experiment_figures + [Figure(p, experiment_caption(t), t) for t, p in eimages]
    page.mixed_claims = _mixed_claims(run_dir)
    page.warnings = warnings
    atomic_text(render(page), out / "index.html")
    phases.done("index.md and index.html")
    return out / "index.md", warnings


def _manifest(run_dir: Path) -> dict:
    """The manifest of an experiments-only folder, if one is there, for the page's provenance ({} if
    none or unreadable: the page then says so; nothing else reads it)."""
    try:  # read with bounds: a FIFO or /dev/zero is refused, not waited on
        return read_manifest(run_dir / "manifest.json")
    except RunError:
        return {}


def _mixed_claims(run_dir: Path) -> pd.DataFrame | None:
    """The mixed-traffic claims as ``reports.experiments`` computes them for its section, for the headline."""
    path = run_dir / "mixed" / "mixed.parquet"
    if not path.is_file():
        return None
    effect = metrics.mpr_effect(metrics.mixed_cells(metrics.common_runs(pd.read_parquet(path))))
    return claims.mixed_claims(effect, SPEED_LOSS_TOL, HDV_TOL, FLEET_SAVING)


def _single_vehicle(run_dir: Path, out: Path, page: Page, progress: bool = True) -> tuple[list[str], list[str]]:
    """Table 4, statistics, violins and trajectories of a ``bench.harness.run`` folder: the markdown
    lines and warnings; what the HTML page shows goes into ``page``."""
    results, manifest, dropped = load_run(run_dir)
    if "train_seed" not in results.columns:  # a table from before training seeds: one policy each
        results = results.assign(train_seed=[0 if m in LEARNED else -1 for m in results.method])
    methods = [m for m in METHOD_ORDER if m in set(results.method)] + sorted(set(results.method) - set(METHOD_ORDER))
    t4 = metrics.table4(results)
    t4 = t4.set_index("method").loc[[m for m in methods if m in set(t4.method)]].reset_index()
    st = metrics.statistics(results)
    seeds = metrics.across_seeds(results)
    atomic_text(tables.table4_markdown(t4), out / "table4.md")
    atomic_text(tables.table4_latex(t4), out / "table4.tex")
    atomic_text(tables.stats_markdown(st), out / "statistics.md")
    atomic_csv(t4, out / "table4.csv")
    atomic_csv(st, out / "statistics.csv")
    atomic_csv(seeds, out / "seeds.csv")
    groups = metrics.group_means(results)
    overrides = claims.overrides_text(manifest.get("scenario_overrides") or {})  # "": the paper's scenario
    scenario = f"**not the paper's**: `{overrides}` (`--scenario`/`--set`)" if overrides else "the paper's"
    md = [f"# Report: {run_dir.name}", "",
          f"Profile `{manifest.get('profile', '?')}`, git `{manifest.get('git_sha', '?')}`, "
          f"{len(results)} episodes, methods: {', '.join(methods)}. Scenario: {scenario}.", ""]
    if dropped:
        md += ["**results.parquet was cleaned before any table or figure was made**: what was dropped (how many "
               "rows, of which method and setting, and why) or converted is listed under Warnings.", ""]
    if manifest.get("skipped_methods"):
        md += [f"Not in this run (no shipped policy): {', '.join(manifest['skipped_methods'])}.", ""]
    phis = headline.phis(results, manifest)
    costs = metrics.paper_costs(t4, phis)
    md += ["## Table 4", "", tables.table4_markdown(t4)]
    if not costs.empty:
        md += ["Table 4 compares energy and travel time apart; the reward's cost, E + phi T (eq. 11, the criterion "
               "the learning methods' checkpoints are selected by), weighs them together. Ours against the cost "
               "that the paper's Table 4 implies:", ""]
        md += [f"- {r.method}, {r.signals}: {r.cost:.1f} against {r.paper_cost:.1f} (phi = {r.phi:g} Wh/s; "
               f"{100 * r.cost_vs_paper:+.1f}%)" for r in costs.itertuples()] + [""]
    page.claims = claims.paper_claims(results)
    if overrides:
        page.claims = claims.off_scenario(page.claims, f"this run's scenario is not the paper's ({overrides})")
    md += ["## Does the paper hold on this run?", "",
           "Section 5.3's and Table 4's claims on this run's own episodes, with the published numbers and "
           "tolerances of `bench/paper.py`; a claim about a method or setting not in the run is NOT CHECKED.", "",
           tables.frame_markdown(page.claims.set_index(["signals", "claim"]))]
    md += ["## Statistics", "",
           f"Bootstrap (BCa, {stats.BOOTSTRAP_RESAMPLES} resamples) {int(stats.CI_LEVEL * 100)}% CIs; IQM = "
           "25% trimmed mean; P(improve) = chance the method uses less than the baseline on the same case (per case "
           "over its training seeds, averaged over the cases; CI by resampling cases and seeds).",
           "", tables.stats_markdown(st), "## Across training seeds", "",
           "Each method's runs on the same cases, a learning method's shipped training seeds: the mean over seeds "
           f"and cases with a {int(stats.CI_LEVEL * 100)}% stratified bootstrap CI over seeds (seeds resampled per "
           "case, as rliable does), the IQM over all runs, and the range of the per-seed means. One seed (a "
           "rule-based method or an agent of your own runs once) has no CI.",
           "", tables.frame_markdown(seeds.set_index(["method", "signals", "metric"]), digits=2)]
    page.experiments_md = bound_sections.gaps(results, manifest, out) + bound_sections.headroom(results, manifest, out, page, run_dir)
    md += page.experiments_md
    warnings = dropped + case_set_warnings(results) + unfinished_warnings(results)
    if overrides:
        warnings.append(f"this run's scenario is not the paper's ({overrides}): the paper's "
                        f"Table 4 numbers are beside this run's for reference only, and its claims are NOT CHECKED")
    parts, partial, refused = _return_parts(results, run_dir, warnings, progress)
    if partial:
        md += [f"**{partial} step log(s) are partial** (cut short after the results were written); they are left "
               "out of the return split and the trajectories, and listed under Warnings.", ""]
    if refused:
        md += [f"**{refused} step log(s) were refused by the log reader** (missing, unreadable, past a size limit or "
               "holding what no log of the writer holds; each reason under Warnings); they are left out of the "
               "return split and the trajectories.", ""]
    if parts is not None:
        atomic_csv(parts, out / "return_parts.csv")
        md += ["## Return by reward component", "",
               "Mean per episode of each reward component's sum, read from the step logs (form r: speed "
               "and jerk penalties, lane-change penalty, -energy [Wh] and -phi x time [s] paid per step); "
               "terminal is eq. 11's -(E_f + phi T_f) paid once at the end, in logs written with "
               "cost_timing = 'end' (the same sum as energy + time). "
               "The components add up to the return. Components that are zero for every method are left out. "
               "Each method is scored with its own reward (DDPG+LC2013's has no lane-change penalty).",
               "", tables.frame_markdown(parts.set_index(["method", "signals"]), digits=1)]
    md += ["## Distributions over seed groups (fig:rwd_bar)", ""]
    page.manifest, page.results, page.table4, page.statistics, page.seeds = manifest, results, t4, st, seeds
    page.methods = methods
    page.parts, page.partial_logs, page.refused_logs = parts, partial, refused
    page.bootstrap = (f"Per-episode bootstrap (BCa, {stats.BOOTSTRAP_RESAMPLES} resamples) "
                      f"{int(stats.CI_LEVEL * 100)}% confidence intervals of the mean and of the IQM.")
    settings = sorted(set(results.signals))
    compare = next((m for m in _COMPARED if m in methods), None)
    page.compare = compare
    drawn = compare is not None and "baseline" in methods
    shown = _trajectory_cases(results, compare) if drawn else []
    with tqdm(total=len(settings) + len(shown), desc="figures", unit="fig",
              disable=None if progress else True) as bar:  # None: off where stderr is no terminal
        for signals in settings:
            p = figures.violins(groups, methods, signals, out / "figures")
            page.violins.append(Figure(p[0], violin_caption(groups, results, methods, signals), f"violin, {signals}"))
            md += [f"![violin {signals}](figures/{p[0].name})", ""]
            bar.update(1)
        if drawn:
            md += [f"## Trajectories: baseline against {compare} (fig:compare1/2)", ""]
            if compare != "prl":
                md += [f"PRL is not in this run; {compare} is shown instead.", ""]
        for signals, case in shown:
            md += _trajectory(run_dir, out, results[results.signals == signals], compare, signals, case, page, warnings)
            bar.update(1)
    return md, warnings


def _trajectory_cases(results: pd.DataFrame, compare: str) -> list[tuple[str, int]]:
    """(signals, case) of the trajectory figures: the first ``TRAJECTORY_CASES`` cases per setting
    that both the baseline and ``compare`` drove."""
    out = []
    for signals in sorted(set(results.signals)):
        sub = results[results.signals == signals]
        both = sorted(set(sub[sub.method == compare].case) & set(sub[sub.method == "baseline"].case))
        out += [(signals, int(case)) for case in both[:TRAJECTORY_CASES]]
    return out


def _trajectory(run_dir: Path, out: Path, sub: pd.DataFrame, compare: str, signals: str, case: int, page: Page,
                warnings: list[str]) -> list[str]:
    """The baseline-against-``compare`` figure of one case (with ``clairvoyant``'s drive, the top of
    the scale the headroom is measured to, and the oracle's plan, where the run has them) into
    ``page``, and its markdown lines; none when neither drive can be drawn."""
    trajs, bands, longest = {}, None, 0
    top = [TOP] if TOP in set(sub[sub.case == case].method) else []
    for method in ("baseline", compare, *top):
        rows = sub[(sub.method == method) & (sub.case == case)].sort_values("train_seed")
        row = rows.iloc[0]  # a learned method's lowest training seed, named in the legend and caption
        path = resolve_log(run_dir, row.mcap)
        try:
            steps, warn = load_steps(path)
        except LogError as e:
            warnings.append(str(e))
            continue
        if warn:  # a partial log is never drawn as a whole drive
            warnings.append(f"{warn} (not drawn)")
            continue
        seed = int(row.train_seed) if pd.notna(row.train_seed) else None
        trajs[seeded(method, seed)] = metrics.trajectory(steps)
        if len(steps) > longest:  # bands over the longer drive
            longest, bands = len(steps), metrics.signal_bands(steps, *stop_lines(steps))
    plan = _bound_plan(run_dir, sub, case, warnings) if trajs else None
    if plan is not None:
        trajs[BOUND_LABEL] = plan
    if not trajs or bands is None:
        return []
    name = f"compare-{signals}-case{case:03d}"
    p = figures.trajectories(trajs, bands, f"{signals}, case {case}", out / "figures", name)
    page.trajectories.append(Figure(p[0], trajectory_caption(list(trajs), signals, case), f"{signals} case {case}"))
    return [f"![{name}](figures/{p[0].name})", ""]


def _bound_plan(run_dir: Path, sub: pd.DataFrame, case: int, warnings: list[str]) -> pd.DataFrame | None:
    """The cost-optimal plan of ``case``, from the oracle's log when the run has one."""
    rows = sub[(sub.method == "oracle") & (sub.case == case)]
    if rows.empty:
        return None
    try:
        return load_plan(resolve_log(run_dir, rows.mcap.iloc[0]))
    except LogError as e:
        warnings.append(str(e))
        return None


def _return_parts(results: pd.DataFrame, run_dir: Path, warnings: list[str],
                  progress: bool = True) -> tuple[pd.DataFrame | None, int, int]:
    """Per method and setting, the mean episode sum of each reward component (from the logs), the
    number of partial logs left out (cut short: a partial log never counts as an episode) and the
    number refused by the reader (``LogError``: unreadable, past a limit, crafted content), each
    with its reason in ``warnings``. Reading every step log is most of a paper run's report (about
    20 s for its 4000 logs)."""
    rows, partial, refused = [], 0, 0
    for r in tqdm(results.itertuples(index=False), total=len(results), desc="return split", unit="log",
                  disable=None if progress else True):
        try:
            sums, warn = component_sums(resolve_log(run_dir, r.mcap))
        except (LogError, OSError) as e:
            warnings.append(str(e))
            refused += 1
            continue
        if warn:
            warnings.append(f"{warn} (left out of the return split)")
            partial += 1
            continue
        rows.append({"method": r.method, "signals": r.signals, "case": r.case, **sums})
    if not rows:
        return None, partial, refused
    parts = metrics.return_parts(pd.DataFrame(rows))
    order = {m: i for i, m in enumerate([*METHOD_ORDER, *sorted(set(parts.method) - set(METHOD_ORDER))])}
    parts = parts.sort_values(["signals", "method"], key=lambda c: c.map(order) if c.name == "method" else c)
    keep = [c for c in parts.columns if c in ("method", "signals", "episodes") or (parts[c] != 0).any()]
    return parts[keep].reset_index(drop=True), partial, refused

