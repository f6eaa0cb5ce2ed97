"""The report as one self-contained HTML page: inline CSS, no JavaScript, nothing fetched.

Sections: the paper's claims on this run (PASS / FAIL / NOT IN THIS RUN), Table 4 laid out as the
paper prints it with the published values beside ours, the statistics with their confidence
intervals, every figure in a ``<figure>`` with a caption, the further experiments, and the run's
provenance from ``manifest.json``. Only formatting lives here; the numbers come from
``reports.metrics`` and ``reports.tables``. A value that does not exist is an en dash, never NaN.
"""
from __future__ import annotations

import html
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from string import Template

import pandas as pd

DASH = "\u2013"
MINUS = "\u2212"
STATUS_CLASS = {"PASS": "pass", "FAIL": "fail", "NOT IN THIS RUN": "absent", "NOT CHECKED": "absent",
                "KNOWN FAIL": "fail", "OUTSIDE BAND": "fail"}
METHOD_LABELS = {"baseline": "Baseline (SUMO Krauss + LC2013)", "baseline0": "Baseline, driver imperfection off",
                 "glosa": "GLOSA (SUMO device)", "prl": "PRL", "mpdqn": "MP-DQN", "ddpg": "DDPG+LC2013",
                 "dqn": "DQN", "oracle": "Oracle (energy-optimal plan replayed in traffic)"}
METRIC_UNITS = {"energy": ("Energy", "Wh"), "travel_time": ("Travel time", "s")}


@dataclass
class Figure:
    """One image of the page: its PNG (under the report's folder) and a caption."""
    path: Path
    caption: str
    title: str = ""


@dataclass
class Page:
    """Everything the page shows; a single-vehicle part is absent (None) for an experiments-only run."""
    run_name: str
    manifest: dict = field(default_factory=dict)
    results: pd.DataFrame | None = None
    claims: pd.DataFrame | None = None
    mixed_claims: pd.DataFrame | None = None
    table4: pd.DataFrame | None = None
    statistics: pd.DataFrame | None = None
    seeds: pd.DataFrame | None = None
    parts: pd.DataFrame | None = None
    partial_logs: int = 0
    violins: list[Figure] = field(default_factory=list)
    trajectories: list[Figure] = field(default_factory=list)
    compare: str | None = None
    experiments_md: list[str] = field(default_factory=list)
    experiment_figures: list[Figure] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    bootstrap: str = ""
    methods: list[str] = field(default_factory=list)  # the order of the tables' rows


def ordered(page: Page, present) -> list[str]:
    """The methods in ``present`` in the page's order, any others after them."""
    present = list(dict.fromkeys(present))
    return [m for m in page.methods if m in present] + [m for m in present if m not in page.methods]


# ---------------------------------------------------------------- values
def missing(v) -> bool:
    if v is None:
        return True
    if isinstance(v, str):
        return v.strip().lower() in ("", "nan", "none", "<na>", "nat")
    try:
        return bool(pd.isna(v))
    except (TypeError, ValueError):
        return False


def num(v, digits: int = 2) -> str:
    """A number with ``digits`` decimals and a true minus sign; an en dash where there is none."""
    if missing(v):
        return DASH
    x = float(v)
    if abs(x) < 0.5 * 10 ** -digits:  # no "-0.00"
        x = 0.0
    return f"{x:.{digits}f}".replace("-", MINUS)


def pct(v, digits: int = 2) -> str:
    """A fraction as a signed percent (0.237 -> '+23.70%'); an en dash where there is none."""
    if missing(v):
        return DASH
    x = 100 * float(v)
    if abs(x) < 0.5 * 10 ** -digits:
        return f"{0:.{digits}f}%"
    return f"{x:+.{digits}f}%".replace("-", MINUS)


def ci(lo, hi, digits: int = 2) -> str:
    return DASH if missing(lo) or missing(hi) else f"[{num(lo, digits)}, {num(hi, digits)}]"


def label(method: str) -> str:
    return METHOD_LABELS.get(method, method)


def esc(v) -> str:
    return html.escape(str(v), quote=True)


def duration(seconds) -> str:
    if missing(seconds):
        return DASH
    s = float(seconds)
    if s < 60:
        return f"{s:.1f} s"
    h, rest = divmod(int(round(s)), 3600)
    m, sec = divmod(rest, 60)
    return (f"{h} h {m:02d} min" if h else f"{m} min {sec:02d} s") + f" ({s:,.0f} s)"


def signed_class(v) -> str:
    """'good' for an improvement (> 0), 'bad' for a loss, '' otherwise."""
    if missing(v) or abs(float(v)) < 5e-5:
        return ""
    return "good" if float(v) > 0 else "bad"


# ---------------------------------------------------------------- pieces
def td(text: str, cls: str = "", raw: bool = False) -> str:
    c = f" class='{cls.strip()}'" if cls.strip() else ""
    return f"<td{c}>{text if raw else esc(text)}</td>"


def badge(status: str) -> str:
    return f"<span class='badge {STATUS_CLASS.get(status, 'absent')}'>{esc(status)}</span>"


def method_cell(method: str) -> str:
    lab = label(method)
    extra = f" <code>{esc(method)}</code>" if lab != method else ""
    return f"<th scope='row'>{esc(lab)}{extra}</th>"


def figure(fig: Figure, fig_id: str) -> str:
    # single quotes around src: other tests look for "<img src='figures/..."
    return (f"<figure id='{esc(fig_id)}'><img src='figures/{esc(fig.path.name)}' alt='{esc(fig.title or fig.caption)}' "
            f"loading='lazy'><figcaption>{fig.caption}</figcaption></figure>")


def settings_of(df: pd.DataFrame) -> list[str]:
    return sorted(set(df.signals))


# ---------------------------------------------------------------- sections
def header(page: Page) -> str:
    man, res = page.manifest, page.results
    facts = [("Profile", esc(man.get("profile", DASH)))]
    if res is not None:
        per = res.groupby(["method", "signals"]).size()
        facts += [("Episodes", f"{len(res)}"),
                  ("Cases per setting", esc(man.get("cases_per_setting", f"{per.min()}\u2013{per.max()}"
                                                    if per.min() != per.max() else per.min()))),
                  ("Settings", esc(", ".join(settings_of(res)))),
                  ("Methods", esc(", ".join(dict.fromkeys(res.method))))]
    sha = man.get("git_sha")
    facts += [("Git", f"<code>{esc(sha[:12] if sha else DASH)}</code>"), ("Wall time", esc(duration(man.get("wall_time_s"))))]
    cells = "".join(f"<div class='fact'><span>{k}</span><b>{v}</b></div>" for k, v in facts)
    return f"<header><h1>Eco-driving benchmark: <code>{esc(page.run_name)}</code></h1><div class='facts'>{cells}</div></header>"


def nav(items: list[tuple[str, str]]) -> str:
    return "<nav><ol>" + "".join(f"<li><a href='#{a}'>{esc(t)}</a></li>" for a, t in items) + "</ol></nav>"


def claims_section(page: Page) -> str:
    out = ["<section id='claims'><h2>Does the paper hold on this run?</h2>"]
    if page.claims is not None and len(page.claims):
        c = page.claims
        counts = c.status.value_counts()
        summary = " \u00a0".join(f"{badge(s)}\u00a0{int(counts.get(s, 0))}" for s in ("PASS", "FAIL", "NOT IN THIS RUN"))
        res = page.results
        cases = int(res.groupby(["method", "signals"]).case.nunique().max()) if res is not None and "case" in res else 0
        seeds = (int(res[res.train_seed >= 0].groupby(["method", "signals"]).train_seed.nunique().max())
                 if res is not None and "train_seed" in res and (res.train_seed >= 0).any() else 1)
        per = f"{cases} test case{'s' if cases != 1 else ''} per method and setting" + (
            f", up to {seeds} training seeds each" if seeds > 1 else "")
        out.append(f"<p class='lead'><b>{len(c)} claims</b> from the paper: {summary}.</p>"
                   "<p>Section 5.3's and Table 4's claims, "
                   f"checked on this run's own episodes ({per}; the paper used 100 cases) with the published "
                   "numbers and tolerances of "
                   "<code>bench/paper.py</code>. A claim about a method or setting this run did not evaluate is "
                   "NOT IN THIS RUN, never a pass. <code>ecodrive regress</code> checks the same claims on 20 "
                   "cases against a recorded reference.</p>")
        rows = []
        for r in c.itertuples(index=False):
            setting = "both settings" if r.signals == "both" else r.signals
            rows.append(f"<tr class='{STATUS_CLASS.get(r.status, 'absent')}'>{td(setting)}{td(r.claim)}"
                        f"{td(r.paper or DASH)}{td(r.ours or DASH, 'num')}{td(badge(r.status), raw=True)}"
                        f"{td(r.detail, 'detail')}</tr>")
        out.append("<div class='scroll'><table class='claims'><caption>The paper's single-vehicle claims. "
                   "<i>Paper</i>: what the paper reports (improvements recomputed from Table 4's means); "
                   "<i>This run</i>: the same quantity from this run's mean over its test cases. Energy savings "
                   "and travel-time changes are against the SUMO baseline of the same setting.</caption>"
                   "<thead><tr><th>Setting</th><th>Claim</th><th>Paper</th><th>This run</th><th>Status</th>"
                   "<th>Detail</th></tr></thead><tbody>" + "".join(rows) + "</tbody></table></div>")
    elif page.results is None:
        out.append("<p>This run folder has no single-vehicle results (<code>results.parquet</code>): Table 4's "
                   "claims are NOT IN THIS RUN.</p>")
    if page.mixed_claims is not None and len(page.mixed_claims):
        rows = "".join(f"<tr class='{STATUS_CLASS.get(r.status, 'absent')}'>{td(r.signals)}{td(r.claim)}"
                       f"{td(r.detail, 'detail')}{td(badge(r.status), raw=True)}</tr>"
                       for r in page.mixed_claims.itertuples(index=False))
        out.append("<div class='scroll'><table class='claims mixed'><caption>Mixed traffic (section 5.5): the "
                   "paper's claims on the fleet at CV market-penetration rates (MPR) 0 to 1, over the demand "
                   "\u00d7 repetition pairs every MPR level has; tolerances of <code>bench/paper.py</code>."
                   "</caption><thead><tr><th>Setting</th><th>Claim</th><th>This run</th><th>Status</th></tr>"
                   "</thead><tbody>" + rows + "</tbody></table></div>")
    out.append("</section>")
    return "".join(out)


def table4_section(page: Page) -> str:
    t4 = page.table4
    res = page.results
    n = res.groupby(["method", "signals"]).size()
    parts = ["<section id='table4'><h2>Table 4: average performance</h2>"]
    for signals in settings_of(t4):
        sub = t4[t4.signals == signals]
        rows = []
        for r in sub.itertuples(index=False):
            g = r._asdict()
            cells = [method_cell(r.method), td(str(int(n.get((r.method, signals), 0))), "num")]
            for col, imp, paper, vs, paper_imp in (("energy", "energy_imp", "paper_energy", "energy_vs_paper",
                                                    "paper_energy_imp"),
                                                   ("travel_time", "time_imp", "paper_time", "time_vs_paper",
                                                    "paper_time_imp")):
                cells += [td(num(g.get(col)), "num ours first"), td(num(g.get(paper)), "num paper"),
                          td(pct(g.get(vs), 1), "num dev"),
                          td(pct(g.get(imp)) if r.method != "baseline" else DASH,
                             f"num ours {signed_class(g.get(imp)) if r.method != 'baseline' else ''}"),
                          td(pct(g.get(paper_imp)) if r.method != "baseline" else DASH, "num paper")]
            rows.append(f"<tr class='{'published' if not missing(g.get('paper_energy')) else ''}'>"
                        + "".join(cells) + "</tr>")
        cases = sorted(set(n[[i for i in n.index if i[1] == signals]]))
        ncases = f"{cases[0]}" if len(cases) == 1 else f"{cases[0]}\u2013{cases[-1]}"
        head = ("<thead><tr><th rowspan='2' scope='col'>Method</th><th rowspan='2' scope='col'>Cases</th>"
                "<th colspan='5' class='group first'>Energy consumption [Wh]</th>"
                "<th colspan='5' class='group first'>Travel time [s]</th></tr><tr>"
                + "<th class='first'>This run</th><th>Paper</th><th>vs paper</th><th>Imp.</th><th>Paper Imp.</th>" * 2 + "</tr></thead>")
        parts.append(f"<div class='scroll'><table class='table4' id='table4-{esc(signals)}'><caption><b>Table 4, "
                     f"{esc(signals)} signals.</b> Mean over {ncases} test cases per method (the paper: 100). "
                     "<b>Imp.</b> = (baseline \u2212 method) / baseline, as in the paper: <b>+</b> means the method "
                     "uses less energy or takes less time than the baseline (better), <b>\u2212</b> means more "
                     "(worse). <b>vs paper</b> = this run / published \u2212 1. Paper columns: the published "
                     "Table 4 (baseline and PRL only; the paper's Imp. recomputed from its means); "
                     f"{DASH} where a value does not exist.</caption>{head}<tbody>{''.join(rows)}</tbody></table></div>")
    parts.append("</section>")
    return "".join(parts)


def statistics_section(page: Page) -> str:
    st = page.statistics
    out = ["<section id='statistics'><h2>Statistics with confidence intervals</h2>",
           f"<p>{page.bootstrap}</p>"]
    for signals in settings_of(st):
        sub = st[st.signals == signals]
        rows = []
        for method in ordered(page, sub.method):
            g = sub[sub.method == method].set_index("metric")
            cells = [method_cell(method), td(str(int(g.n.iloc[0])), "num")]
            for metric in METRIC_UNITS:
                if metric not in g.index:
                    cells += [td(DASH, "num first"), td(DASH, "num"), td(DASH, "num")]
                    continue
                r = g.loc[metric]
                cells += [td(f"{num(r['mean'])} <span class='ci'>{ci(r.ci_low, r.ci_high)}</span>", "num first", raw=True),
                          td(f"{num(r.iqm)} <span class='ci'>{ci(r.iqm_ci_low, r.iqm_ci_high)}</span>", "num", raw=True),
                          td(num(r.p_improve_vs_baseline, 2), "num")]
            rows.append("<tr>" + "".join(cells) + "</tr>")
        head = ("<thead><tr><th rowspan='2'>Method</th><th rowspan='2'>Episodes</th>"
                + "".join(f"<th colspan='3' class='group first'>{t} [{u}]</th>" for t, u in METRIC_UNITS.values())
                + "</tr><tr>" + "<th class='first'>Mean [95% CI]</th><th>IQM [95% CI]</th><th>P(improve)</th>" * 2
                + "</tr></thead>")
        out.append(f"<div class='scroll'><table class='stats' id='stats-{esc(signals)}'><caption><b>{esc(signals)} "
                   "signals</b>, per episode. IQM = interquartile (25%-trimmed) mean. P(improve) = chance that an "
                   "episode of the method uses less energy (or takes less time) than one of the baseline; 0.5 = no "
                   f"difference, {DASH} for the baseline itself.</caption>{head}<tbody>{''.join(rows)}</tbody>"
                   "</table></div>")
    out.append(seeds_table(page))
    out.append("</section>")
    return "".join(out)


def seeds_table(page: Page) -> str:
    sd = page.seeds
    if sd is None or sd.empty:
        return ""
    out = ["<h3 id='seeds'>Across training seeds</h3>",
           "<p>Each learning method's shipped training seeds, evaluated on the same cases: the mean over seeds and "
           "cases with a 95% stratified bootstrap CI over seeds (seeds resampled per case, as rliable does), the "
           "IQM over all seed \u00d7 case runs, and the range of the per-seed means. With one seed (and for the "
           "rule-based methods, which have none) there is no spread to resample: <i>one seed</i>.</p>"]
    for signals in settings_of(sd):
        sub = sd[sd.signals == signals]
        rows = []
        for method in ordered(page, sub.method):
            g = sub[sub.method == method].set_index("metric")
            first = g.iloc[0]
            one = int(first.seeds) < 2
            cells = [method_cell(method), td(str(int(first.seeds)), "num"), td(str(int(first.cases)), "num")]
            for metric in METRIC_UNITS:
                if metric not in g.index:
                    cells += [td(DASH, "num first"), td(DASH, "num"), td(DASH, "num")]
                    continue
                r = g.loc[metric]
                mean_ci = "<span class='ci'>one seed</span>" if one else f"<span class='ci'>{ci(r.ci_low, r.ci_high)}</span>"
                iqm_ci = "<span class='ci'>one seed</span>" if one else \
                    f"<span class='ci'>{ci(r.get('iqm_ci_low'), r.get('iqm_ci_high'))}</span>"
                rng = DASH if one else f"{num(r.seed_min)}\u2009\u2013\u2009{num(r.seed_max)}"
                cells += [td(f"{num(r['mean'])} {mean_ci}", "num first", raw=True), td(f"{num(r.iqm)} {iqm_ci}", "num", raw=True),
                          td(rng, "num")]
            rows.append("<tr>" + "".join(cells) + "</tr>")
        head = ("<thead><tr><th rowspan='2'>Method</th><th rowspan='2'>Seeds</th><th rowspan='2'>Cases</th>"
                + "".join(f"<th colspan='3' class='group first'>{t} [{u}]</th>" for t, u in METRIC_UNITS.values())
                + "</tr><tr>" + "<th class='first'>Mean [95% CI]</th><th>IQM [95% CI]</th><th>Per-seed range</th>" * 2
                + "</tr></thead>")
        out.append(f"<div class='scroll'><table class='seeds' id='seeds-{esc(signals)}'><caption><b>{esc(signals)} "
                   "signals</b>, across training seeds; only the cases every seed of a method ran.</caption>"
                   f"{head}<tbody>{''.join(rows)}</tbody></table></div>")
    return "".join(out)


def parts_section(page: Page) -> str:
    parts = page.parts
    if parts is None or parts.empty:
        return ""
    comps = [c for c in parts.columns if c not in ("method", "signals", "episodes", "reward")]
    rows = "".join("<tr>" + method_cell(r["method"]) + td(r["signals"]) + td(str(int(r["episodes"])), "num")
                   + "".join(td(num(r[c], 1), "num") for c in comps) + td(num(r.get("reward"), 1), "num first")
                   + "</tr>" for _, r in parts.iterrows())
    head = ("<thead><tr><th>Method</th><th>Setting</th><th>Episodes</th>"
            + "".join(f"<th>{esc(c.replace('_', ' '))}</th>" for c in comps) + "<th class='first'>Return</th></tr></thead>")
    partial = (f"<p class='warn'>{page.partial_logs} step log(s) are partial (cut short after the results were "
               "written); they are left out here and from the trajectories, and listed under Warnings.</p>"
               if page.partial_logs else "")
    return ("<section id='return'><h2>Return by reward component</h2>" + partial
            + "<div class='scroll'><table class='parts'><caption>Mean per episode of each reward component's sum, "
              "read from the step logs, in reward units (form r: speed and jerk penalties, lane-change penalty, "
              "\u2212energy [Wh] and \u2212\u03c6\u00b7time [s] paid per step; terminal = eq. 11's "
              "\u2212(E<sub>f</sub> + \u03c6T<sub>f</sub>) paid once, in logs written with cost_timing = 'end'). The "
              "components add up to the return; those zero for every method are left out. Each method is scored "
              "with its own reward (DDPG+LC2013's has no lane-change penalty).</caption>"
            + head + "<tbody>" + rows + "</tbody></table></div></section>")


def figures_section(page: Page) -> str:
    if not page.violins and not page.trajectories:
        return ""
    out = ["<section id='figures'><h2>Figures</h2>"]
    if page.violins:
        out.append("<h3>Distributions over seed groups (fig:rwd_bar)</h3>")
        out += [figure(f, f"fig-{f.path.stem}") for f in page.violins]
    if page.trajectories:
        out.append(f"<h3>Trajectories: baseline against {esc(label(page.compare or ''))} (fig:compare1/2)</h3>")
        if page.compare != "prl":
            out.append(f"<p>PRL is not in this run; {esc(label(page.compare or ''))} is shown instead.</p>")
        out += [figure(f, f"fig-{f.path.stem}") for f in page.trajectories]
    out.append("</section>")
    return "".join(out)


def warnings_section(page: Page) -> str:
    if not page.warnings:
        return ""
    return ("<section id='warnings'><h2>Warnings</h2><ul class='warn'>"
            + "".join(f"<li>{esc(w)}</li>" for w in page.warnings) + "</ul></section>")


def provenance_section(page: Page) -> str:
    man = page.manifest
    out = ["<section id='provenance'><h2>Provenance</h2>"]
    if not man:
        out.append("<p>No <code>manifest.json</code> in this run folder: where these numbers came from is not "
                   "recorded.</p></section>")
        return "".join(out)
    sha = str(man.get("git_sha", ""))
    dirty = " <span class='badge fail'>uncommitted changes</span>" if sha.endswith("-dirty") else ""
    overhead = man.get("harness_overhead")
    rows = [("Run folder", f"<code>{esc(page.run_name)}</code>"),
            ("Command", f"<code>{esc(man.get('command', DASH))}</code>"),
            ("Git SHA", f"<code class='sha'>{esc(sha or DASH)}</code>{dirty}"),
            ("Profile", esc(man.get("profile", DASH))),
            ("Signal settings", esc(", ".join(man.get("signals", [])) or DASH)),
            ("Cases per setting", esc(man.get("cases_per_setting", DASH))),
            ("Methods", esc(", ".join(man.get("methods", [])) or DASH)),
            ("Not in this run (no shipped policy)", esc(", ".join(man.get("skipped_methods", [])) or "no method skipped")),
            ("Executor", esc(f"{man.get('executor', DASH)}, {man.get('workers', DASH)} worker(s)")),
            ("Episodes", esc(f"{man.get('episodes_run', DASH)} run, {man.get('episodes_reused', DASH)} reused from "
                             f"complete logs, {man.get('episodes_kept_from_earlier_commands', DASH)} kept from earlier "
                             "commands")),
            ("Wall time", esc(duration(man.get("wall_time_s")))),
            ("Sum of episode times", esc(duration(man.get("episode_time_sum_s")))),
            ("Harness overhead", esc(pct(overhead, 1) if not missing(overhead) else DASH)
             + " <span class='ci'>(wall time \u00d7 workers / sum of episode times \u2212 1)</span>")]
    out.append("<table class='kv'><caption>From the run's <code>manifest.json</code> (written by "
               "<code>ecodrive run</code>).</caption><tbody>"
               + "".join(f"<tr><th scope='row'>{k}</th><td>{v}</td></tr>" for k, v in rows) + "</tbody></table>")
    pk = man.get("packages") or {}
    if pk:
        sumo = {k: v for k, v in pk.items() if "sumo" in k}
        rest = {k: v for k, v in pk.items() if "sumo" not in k}
        cells = "".join(f"<tr class='{'hl' if k in sumo else ''}'><th scope='row'>{esc(k)}</th><td><code>{esc(v)}</code>"
                        "</td></tr>" for k, v in {**sumo, **rest}.items())
        out.append("<div class='pair'><table class='kv packages'><caption>Package versions (SUMO first)."
                   f"</caption><tbody>{cells}</tbody></table>")
    else:
        out.append("<div class='pair'><p>No package versions recorded.</p>")
    shas = man.get("checkpoint_sha256") or {}
    if shas:
        cells = "".join(f"<tr><th scope='row'>{esc(k)}</th><td><code class='sha'>{esc(v)}</code></td></tr>"
                        for k, v in shas.items())
        out.append("<table class='kv'><caption>Policies evaluated: sha256 of each <code>policy.pt</code> "
                   "(<code>models/&lt;method&gt;-&lt;signals&gt;/s&lt;seed&gt;/</code>).</caption><tbody>"
                   f"{cells}</tbody></table></div>")
    else:
        out.append("<p>No learned policy in this run (rule-based methods only): no checkpoint hashes.</p></div>")
    scen = man.get("scenario") or {}
    if scen:
        flat = {s: _flatten(cfg) for s, cfg in scen.items()}
        keys = list(dict.fromkeys(k for f in flat.values() for k in f))
        names = list(flat)
        body = "".join(
            f"<tr class='{'differs' if len({str(flat[s].get(k)) for s in names}) > 1 else ''}'><th scope='row'>{esc(k)}</th>"
            + "".join(td(_value(flat[s].get(k)), "num") for s in names) + "</tr>" for k in keys)
        out.append("<details><summary>Scenario configuration per setting (<code>envs.config.ScenarioConfig</code>; "
                   "rows that differ between the settings are marked)</summary><div class='scroll'><table "
                   "class='kv scenario'><thead><tr><th>Field</th>" + "".join(f"<th>{esc(s)}</th>" for s in names)
                   + f"</tr></thead><tbody>{body}</tbody></table></div></details>")
    out.append("</section>")
    return "".join(out)


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def _value(v) -> str:
    if isinstance(v, float) and not math.isnan(v):
        return f"{v:.6g}"
    return DASH if missing(v) else str(v)


# ---------------------------------------------------------------- the experiments' markdown
EXPERIMENT_CAPTIONS = {
    "reward study": "<b>fig:rwd_compare.</b> Energy [Wh] (left) and travel time [s] (right) of each training "
                    "episode, smoothed as in the paper (D<sub>k</sub> = 0.98 D<sub>k\u22121</sub> + 0.02 d<sub>k</sub>), "
                    "one line per reward configuration (mean over training seeds; band: min\u2013max over seeds).",
    "sensitivity heatmap": "<b>fig:heatmap.</b> Mean test-case energy [Wh] and travel time [s] of the policy "
                           "trained with each pair of penalties |r<sub>p</sub><sup>s</sup>| (rows) \u00d7 "
                           "|r<sub>p</sub><sup>j</sup>| (columns), in reward units, averaged over training seeds; "
                           "|r<sub>p</sub><sup>c</sup>| = 50.",
    "mixed traffic": "<b>fig:dd / fig:avg.</b> Fleet metrics against arterial demand [veh/h/lane], one line per CV "
                     "market-penetration rate (MPR), one column per signal setting: energy per finished vehicle "
                     "[Wh/veh] and mean speed of the finished vehicles [m/s] (the paper's), then, when recorded, "
                     "energy per km [Wh/km] and space-mean speed [m/s] over every vehicle inserted.",
}
LATERAL = {"A": "HDV1 ahead brakes at \u22122 m/s\u00b2 for three steps, HDV2 in the left lane",
           "B": "a platoon of five queues at a red light, two vehicles queue in the left lane"}


def experiment_caption(title: str) -> str:
    if title in EXPERIMENT_CAPTIONS:
        return EXPERIMENT_CAPTIONS[title]
    m = re.fullmatch(r"generalisation, (\w+)", title)
    if m:
        return (f"<b>Generalisation, {esc(m.group(1))} signals.</b> Each method's mean energy (left) and travel time "
                "(right) on each held-out corridor, as the change against SUMO's driver on the same corridor and "
                "cases [%]: blue is less than the baseline, red more.")
    m = re.fullmatch(r"lateral scenario (\w+)", title)
    if m:
        what = LATERAL.get(m.group(1), "")
        return (f"<b>fig:scenario_compare, scenario {esc(m.group(1))}</b>{': ' + what if what else ''}. Left: the "
                "ego's lane index (0 = rightmost) against position x [m], scripted HDVs' lanes in grey; middle: "
                "distance [m] against time [s]; right: speed [m/s] against time [s]; one line per method.")
    return esc(title)


_ROW = re.compile(r"^\|\s.*\|\s*$|^\|(-+\|)+\s*$")
_IMG = re.compile(r"^!\[([^\]]*)\]\(([^)]+)\)\s*$")
_NUM = re.compile(r"^[+\-\u2212]?\d[\d,]*(\.\d+)?(e[+\-]?\d+)?%?$")


def inline(text: str) -> str:
    """Escaped text with the markdown the report writes: `code` and **bold**."""
    s = esc(text)
    s = re.sub(r"`([^`]+)`", r"<code>\1</code>", s)
    return re.sub(r"\*\*([^*]+)\*\*", r"<b>\1</b>", s)


def md_cell(text: str, column: str) -> tuple[str, str]:
    """(html, class) of one markdown table cell; a column of changes (``*_change*``, fractions) as
    signed percents."""
    t = text.strip()
    if missing(t):
        return DASH, "num"
    if t in STATUS_CLASS:
        return badge(t), ""
    if _NUM.match(t):
        if "_change" in column and not t.endswith("%"):
            try:
                return pct(float(t), 0), "num"
            except ValueError:
                pass
        return esc(t.replace("-", MINUS)), "num"
    return inline(t), ""


def md_table(lines: list[str]) -> str:
    split = [[c.strip() for c in ln.strip().strip("|").split("|")] for ln in lines]
    head, body = split[0], [r for r in split[1:] if not all(set(c) <= set("-: ") for c in r)]
    cols = "".join(f"<th>{esc(c.replace('_', ' '))}</th>" for c in head)
    rows = []
    for r in body:
        cells = []
        for i, c in enumerate(r):
            h, cls = md_cell(c, head[i] if i < len(head) else "")
            cells.append(f"<td class='{cls}'>{h}</td>" if cls else f"<td>{h}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    return f"<div class='scroll'><table class='md'><thead><tr>{cols}</tr></thead><tbody>{''.join(rows)}</tbody></table></div>"


def experiments_html(lines: list[str], figs: list[Figure]) -> tuple[str, list[tuple[str, str]]]:
    """The experiments' markdown (headings, paragraphs, tables, images, lists) as HTML, each image
    a captioned figure; and the (anchor, title) of each section for the navigation."""
    by_name = {f.path.name: f for f in figs}
    out, toc, para, table, items = [], [], [], [], []
    open_section = False

    def flush() -> None:
        if para:
            out.append(f"<p>{inline(' '.join(para))}</p>")
            para.clear()
        if table:
            out.append(md_table(table))
            table.clear()
        if items:
            out.append("<ul>" + "".join(f"<li>{inline(i)}</li>" for i in items) + "</ul>")
            items.clear()

    for ln in "\n".join(lines).split("\n"):  # an element may hold a whole table
        if _ROW.match(ln):
            if para or items:
                flush()
            table.append(ln)
            continue
        if table:
            flush()
        if ln.startswith("## "):
            flush()
            title = ln[3:].strip()
            short = re.sub(r"\s*\(.*\)$", "", title)  # "Mixed traffic (fig:dd, fig:avg)" -> "Mixed traffic"
            anchor = "x-" + re.sub(r"[^a-z0-9]+", "-", short.lower()).strip("-")
            out.append(("</section>" if open_section else "") + f"<section id='{anchor}'><h2>{inline(title)}</h2>")
            open_section = True
            toc.append((anchor, short))
        elif ln.startswith("# "):
            flush()
        elif (m := _IMG.match(ln.strip())):
            flush()
            name = Path(m.group(2)).name
            f = by_name.get(name, Figure(Path(name), esc(m.group(1)), m.group(1)))
            out.append(figure(f, f"fig-{Path(name).stem}"))
        elif ln.startswith("- "):
            if para:
                flush()
            items.append(ln[2:])
        elif not ln.strip():
            flush()
        else:
            para.append(ln.strip())
    flush()
    if open_section:
        out.append("</section>")
    return "".join(out), toc


# ---------------------------------------------------------------- the page
CSS = """
:root { --fg:#1d2327; --muted:#5f6b73; --line:#d9dee2; --bg:#ffffff; --band:#f5f7f9; --accent:#1f5f99;
        --pass:#1a7f37; --pass-bg:#e6f4ea; --fail:#b42318; --fail-bg:#fdecea; --absent:#6b7280; --absent-bg:#eef0f2; }
* { box-sizing: border-box; }
body { margin:0; font:15px/1.5 -apple-system, "Segoe UI", Roboto, "Helvetica Neue", Arial, sans-serif;
       color:var(--fg); background:var(--bg); }
main { max-width:1240px; margin:0 auto; padding:24px 32px 64px; }
header h1 { font-size:26px; margin:8px 0 12px; }
h2 { font-size:21px; margin:40px 0 10px; padding-bottom:4px; border-bottom:2px solid var(--line); }
h3 { font-size:17px; margin:26px 0 8px; }
code { font:13px/1.4 ui-monospace, SFMono-Regular, Menlo, Consolas, monospace; background:var(--band);
       padding:1px 4px; border-radius:3px; }
code.sha { word-break:break-all; }
a { color:var(--accent); }
.facts { display:flex; flex-wrap:wrap; gap:8px; }
.fact { background:var(--band); border:1px solid var(--line); border-radius:6px; padding:6px 12px; }
.fact span { display:block; font-size:11px; text-transform:uppercase; letter-spacing:.04em; color:var(--muted); }
.fact b { font-weight:600; }
nav { margin:18px 0 0; padding:10px 14px; border:1px solid var(--line); border-radius:6px; background:var(--band); }
nav ol { margin:0; padding-left:20px; columns:3; }
nav li { margin:1px 0; }
.lead { font-size:15px; }
.scroll { overflow-x:auto; margin:10px 0 18px; }
table { border-collapse:collapse; font-size:13.5px; width:100%; }
caption { caption-side:top; text-align:left; color:var(--muted); font-size:13px; padding:0 0 6px; line-height:1.45; }
caption b { color:var(--fg); }
th, td { padding:5px 9px; border-bottom:1px solid var(--line); vertical-align:top; }
thead th { background:var(--band); font-weight:600; text-align:center; border-bottom:1px solid #b9c1c7; }
thead tr + tr th { white-space:nowrap; font-weight:500; }
thead th[rowspan] { vertical-align:bottom; }
tbody th { text-align:left; font-weight:600; white-space:nowrap; }
tbody th code { font-weight:400; font-size:11.5px; color:var(--muted); background:none; padding:0; }
tbody tr:nth-child(even) { background:#fafbfc; }
td.num { text-align:right; font-variant-numeric:tabular-nums; white-space:nowrap; }
th.first, td.first { border-left:1px solid var(--line); }
th.group { border-bottom:1px solid var(--line); }
td.paper { color:#475467; background:rgba(31,95,153,.05); }
td.dev { color:var(--muted); }
td.good { color:var(--pass); }
td.bad { color:var(--fail); }
tr.published th { border-left:3px solid var(--accent); }
.ci { color:var(--muted); font-size:12px; }
.badge { display:inline-block; padding:1px 7px; border-radius:10px; font-size:11.5px; font-weight:700;
         letter-spacing:.02em; white-space:nowrap; }
.badge.pass { color:var(--pass); background:var(--pass-bg); }
.badge.fail { color:var(--fail); background:var(--fail-bg); }
.badge.absent { color:var(--absent); background:var(--absent-bg); }
table.claims td.detail { color:var(--muted); font-size:12.5px; }
table.claims tr.absent td { color:var(--absent); }
table.kv { width:auto; margin:10px 0 18px; }
table.kv th { min-width:180px; }
.pair { display:flex; flex-wrap:wrap; gap:0 40px; align-items:flex-start; }
.pair table.kv th { min-width:0; }
table.kv tr.hl th, table.kv tr.hl td { background:#fff8e1; }
table.scenario tr.differs th, table.scenario tr.differs td { background:#fff8e1; }
table.md { width:auto; min-width:40%; }
table.md td, table.md th { font-size:13px; }
figure { margin:14px 0 26px; padding:10px; border:1px solid var(--line); border-radius:6px; background:#fff; }
figure img { display:block; max-width:100%; max-height:1000px; width:auto; height:auto; margin:0 auto; }
figcaption { color:var(--muted); font-size:13px; margin-top:8px; line-height:1.45; }
figcaption b { color:var(--fg); }
details { margin:10px 0; }
summary { cursor:pointer; color:var(--accent); }
.warn { color:#8a4b00; }
ul.warn li { margin:3px 0; word-break:break-word; }
footer { margin-top:48px; color:var(--muted); font-size:12px; border-top:1px solid var(--line); padding-top:10px; }
@media print { nav { display:none; } figure { break-inside:avoid; } main { max-width:none; padding:0; } }
"""

TEMPLATE = Template("""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>$title</title>
<style>$css</style>
</head>
<body>
<main>
$header
$nav
$body
<footer>Written by <code>ecodrive report</code> from the run folder's <code>results.parquet</code>,
<code>manifest.json</code> and step logs; the same content as <code>index.md</code>, with the tables and figures
beside it (<code>table4.csv</code>, <code>statistics.csv</code>, <code>seeds.csv</code>, <code>figures/*.pdf</code>).
Self-contained: no script, nothing fetched.</footer>
</main>
</body>
</html>
""")


def render(page: Page) -> str:
    """The whole page as a string."""
    body, toc = [claims_section(page)], [("claims", "Claims")]
    if page.table4 is not None and len(page.table4):
        body.append(table4_section(page))
        toc.append(("table4", "Table 4"))
    if page.statistics is not None and len(page.statistics):
        body.append(statistics_section(page))
        toc.append(("statistics", "Statistics"))
    if page.parts is not None and not page.parts.empty:
        body.append(parts_section(page))
        toc.append(("return", "Return by component"))
    if page.violins or page.trajectories:
        body.append(figures_section(page))
        toc.append(("figures", "Figures"))
    if page.experiments_md:
        exp, etoc = experiments_html(page.experiments_md, page.experiment_figures)
        body.append(exp)
        toc += etoc
    if page.warnings:
        body.append(warnings_section(page))
        toc.append(("warnings", f"Warnings ({len(page.warnings)})"))
    body.append(provenance_section(page))
    toc.append(("provenance", "Provenance"))
    return TEMPLATE.substitute(title=esc(f"Report: {page.run_name}"), css=CSS, header=header(page), nav=nav(toc),
                               body="\n".join(body))
