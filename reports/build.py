"""Build the report of a run folder: Table 4, statistics, violin and trajectory figures, and the
sections of the further experiments found in it (reward study, heatmap, mixed traffic).

    ecodrive report logs/<run-id> [--out reports/<run-id>]

Reads only ``results.parquet``, ``manifest.json`` and the step logs; writes ``index.md`` and
``index.html`` (which shows the figures) plus the tables and figures.
"""
from __future__ import annotations

import html
import shutil
import sys
from pathlib import Path

import pandas as pd

from bench.args import Parser, fail
from bench.logs.mcaplog import LogError, resolve_log

from . import experiments, figures, metrics, tables
from .load import RunError, component_sums, load_run, load_steps, stop_lines

METHOD_ORDER = ("baseline", "baseline0", "glosa", "prl", "mpdqn", "ddpg", "dqn")
LEARNED = ("prl", "mpdqn", "ddpg", "dqn")
TRAJECTORY_CASES = 3  # per signal setting, as in the paper's fig:compare1/2


def build(run_dir: Path, out: Path) -> Path:
    if not run_dir.is_dir():
        raise RunError(f"{run_dir}: not a run folder (a directory written by `ecodrive run`)")
    if not (run_dir / "results.parquet").is_file() and not experiments.present(run_dir):
        raise RunError(f"{run_dir}: no results.parquet and no experiment folders (is this a folder written by "
                       f"`ecodrive run`?)")
    out.mkdir(parents=True, exist_ok=True)
    if (run_dir / "results.parquet").is_file():
        md, images, warnings, html_tables = _single_vehicle(run_dir, out)
    else:
        md, images, warnings, html_tables = [f"# Report: {run_dir.name}", ""], [], [], []
    emd, eimages, ewarnings = experiments.sections(run_dir, out)
    md, images, warnings = md + emd, images + eimages, warnings + ewarnings
    if warnings:
        md += ["## Warnings", ""] + [f"- {w}" for w in warnings] + [""]
    (out / "index.md").write_text("\n".join(md))
    body = "".join(f"<h3>{html.escape(t)}</h3><img src='figures/{p.name}' style='max-width:100%'>" for t, p in images)
    tables_html = "".join(f"<h2>{h}</h2>{df.to_html(index=False, float_format=lambda v: f'{v:.3f}')}"
                          for h, df in html_tables)
    (out / "index.html").write_text(f"<html><head><meta charset='utf-8'><title>{html.escape(run_dir.name)}</title>"
                                    f"</head><body><h1>Report: {html.escape(run_dir.name)}</h1>{tables_html}{body}"
                                    "</body></html>")
    return out / "index.md", warnings


def _single_vehicle(run_dir: Path, out: Path) -> tuple[list[str], list, list[str], list]:
    """Table 4, statistics, violins and trajectories of a ``bench.harness.run`` folder."""
    results, manifest = load_run(run_dir)
    if "train_seed" not in results.columns:  # a table from before training seeds: one policy each
        results = results.assign(train_seed=[0 if m in LEARNED else -1 for m in results.method])
    methods = [m for m in METHOD_ORDER if m in set(results.method)]
    t4 = metrics.table4(results)
    t4 = t4.set_index("method").loc[[m for m in methods if m in set(t4.method)]].reset_index()
    st = metrics.statistics(results)
    seeds = metrics.across_seeds(results)
    (out / "table4.md").write_text(tables.table4_markdown(t4))
    (out / "table4.tex").write_text(tables.table4_latex(t4))
    (out / "statistics.md").write_text(tables.stats_markdown(st))
    t4.to_csv(out / "table4.csv", index=False)
    st.to_csv(out / "statistics.csv", index=False)
    seeds.to_csv(out / "seeds.csv", index=False)
    groups = metrics.group_means(results)
    md = [f"# Report: {run_dir.name}", "",
          f"Profile `{manifest.get('profile', '?')}`, git `{manifest.get('git_sha', '?')}`, "
          f"{len(results)} episodes, methods: {', '.join(methods)}.", ""]
    if manifest.get("skipped_methods"):
        md += [f"Not in this run (no shipped policy): {', '.join(manifest['skipped_methods'])}.", ""]
    md += ["## Table 4", "", tables.table4_markdown(t4), "## Statistics", "",
           f"Bootstrap (BCa, {metrics.BOOTSTRAP_RESAMPLES} resamples) {int(metrics.CI_LEVEL * 100)}% CIs; IQM = "
           "25% trimmed mean; P(improve) = chance an episode of the method uses less than one of the baseline.",
           "", tables.stats_markdown(st), "## Across training seeds", "",
           "Each learning method's shipped training seeds, evaluated on the same cases: the mean over seeds and "
           f"cases with a {int(metrics.CI_LEVEL * 100)}% stratified bootstrap CI over seeds (seeds resampled per "
           "case, as rliable does), the IQM over all runs, and the range of the per-seed means. One seed has no CI.",
           "", tables.frame_markdown(seeds.set_index(["method", "signals", "metric"]), digits=2)]
    warnings = []
    parts, partial = _return_parts(results, run_dir, warnings)
    if partial:
        md += [f"**{partial} step log(s) are partial** (cut short after the results were written); they are left "
               "out of the return split and the trajectories, and listed under Warnings.", ""]
    if parts is not None:
        parts.to_csv(out / "return_parts.csv", index=False)
        md += ["## Return by reward component", "",
               "Mean per episode of each reward component's sum, read from the step logs (form r: speed "
               "and jerk penalties, lane-change penalty, -energy [Wh] and -phi x time [s] paid per step); "
               "terminal is eq. 11's -(E_f + phi T_f) paid once at the end, in logs written with "
               "cost_timing = 'end' (the same sum as energy + time). "
               "The components add up to the return. Components that are zero for every method are left out. "
               "Each method is scored with its own reward (DDPG+LC2013's has no lane-change penalty).",
               "", tables.frame_markdown(parts.set_index(["method", "signals"]), digits=1)]
    md += ["## Distributions over seed groups (fig:rwd_bar)", ""]
    images = []
    for signals in sorted(set(results.signals)):
        p = figures.violins(groups, methods, signals, out / "figures")
        images.append((f"violin, {signals}", p[0]))
        md += [f"![violin {signals}](figures/{p[0].name})", ""]
    compare = next((m for m in ("prl", "mpdqn", "ddpg", "glosa") if m in methods), None)
    if compare is not None and "baseline" in methods:
        md += [f"## Trajectories: baseline against {compare} (fig:compare1/2)", ""]
        if compare != "prl":
            md += [f"PRL is not in this run; {compare} is shown instead.", ""]
        for signals in sorted(set(results.signals)):
            sub = results[results.signals == signals]
            for case in sorted(set(sub[sub.method == compare].case) & set(sub[sub.method == "baseline"].case))[
                    :TRAJECTORY_CASES]:
                trajs, bands, longest = {}, None, 0
                for method in ("baseline", compare):
                    path = resolve_log(run_dir, sub[(sub.method == method) & (sub.case == case)].mcap.iloc[0])
                    try:
                        steps, warn = load_steps(path)
                    except LogError as e:
                        warnings.append(str(e))
                        continue
                    if warn:  # a partial log is never drawn as a whole drive
                        warnings.append(f"{warn} (not drawn)")
                        continue
                    trajs[method] = metrics.trajectory(steps)
                    if len(steps) > longest:  # bands over the longer drive
                        longest, bands = len(steps), metrics.signal_bands(steps, *stop_lines(steps))
                if trajs and bands is not None:
                    name = f"compare-{signals}-case{case:03d}"
                    p = figures.trajectories(trajs, bands, f"{signals}, case {case}", out / "figures", name)
                    images.append((f"{signals} case {case}", p[0]))
                    md += [f"![{name}](figures/{p[0].name})", ""]
    return md, images, warnings, [("Table 4", t4), ("Statistics", st)] + ([("Return by reward component", parts)]
                                                                          if parts is not None else [])


def _return_parts(results: pd.DataFrame, run_dir: Path, warnings: list[str]) -> tuple[pd.DataFrame | None, int]:
    """Per method and setting, the mean episode sum of each reward component (from the logs),
    and the number of partial logs left out (a partial log never counts as an episode)."""
    rows, partial = [], 0
    for r in results.itertuples(index=False):
        try:
            sums, warn = component_sums(resolve_log(run_dir, r.mcap))
        except (LogError, OSError) as e:
            warnings.append(str(e))
            partial += 1
            continue
        if warn:
            warnings.append(f"{warn} (left out of the return split)")
            partial += 1
            continue
        rows.append({"method": r.method, "signals": r.signals, "case": r.case, **sums})
    if not rows:
        return None, partial
    parts = metrics.return_parts(pd.DataFrame(rows))
    order = {m: i for i, m in enumerate(METHOD_ORDER)}
    parts = parts.sort_values(["signals", "method"], key=lambda c: c.map(order) if c.name == "method" else c)
    keep = [c for c in parts.columns if c in ("method", "signals", "episodes") or (parts[c] != 0).any()]
    return parts[keep].reset_index(drop=True), partial


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__)
    ap.add_argument("run_dir", type=Path, help="a run folder written by ecodrive run")
    ap.add_argument("--out", type=Path, default=None, help="output folder (default reports/<run-id>)")
    args = ap.parse_args(argv)
    out = args.out or Path("reports") / args.run_dir.name
    created = not out.exists()
    try:
        index, warnings = build(args.run_dir, out)
    except (RunError, LogError, OSError) as e:
        if created and out.exists():  # nothing is left behind
            shutil.rmtree(out)
        return fail(ap.prog, str(e))
    for w in warnings:
        print(f"warning: {w}", file=sys.stderr)
    print(f"report: {index} and {index.with_suffix('.html')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
