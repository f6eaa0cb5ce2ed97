"""The report as one self-contained HTML page: inline CSS, no JavaScript, nothing fetched.

Sections: the paper's claims on this run (PASS / FAIL / NOT CHECKED), Table 4 laid out as the
paper prints it with the published values beside ours, the statistics with their confidence
intervals, every figure in a ``<figure>`` with a caption, the further experiments, and the run's
provenance from ``manifest.json``. Only formatting lives here; the numbers come from
``reports.metrics`` and ``reports.tables``. A value that does not exist is an en dash, never NaN.
The values and small pieces are ``reports.html_parts``, the experiments' markdown as HTML
``reports.html_markdown``, the stylesheet and skeleton ``reports.html_style``.
"""
from __future__ import annotations

from .claims import STATUSES, overrides_text
from .html_markdown import experiments_html
from .html_parts import (
    DASH,
    METRIC_UNITS,
    STATUS_CLASS,
    Page,
    badge,
    ci,
    duration,
    esc,
    figure,
    method_cell,
    missing,
    num,
    ordered,
    pct,
    settings_of,
    signed_class,
    td,
)
from .html_provenance import provenance_section
from .html_style import CSS, TEMPLATE
from .names import label


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
    other = overrides_text(man.get("scenario_overrides") or {})
    if other:
        facts.append(("Scenario", f"not the paper's: <code>{esc(other)}</code>"))
    wall = man.get("wall_time_all_commands_s") or man.get("wall_time_s")  # a rerun that reused every log took ~0 s
    facts += [("Git", f"<code>{esc(sha[:12] if sha else DASH)}</code>"), ("Wall time", esc(duration(wall)))]
    cells = "".join(f"<div class='fact'><span>{k}</span><b>{v}</b></div>" for k, v in facts)
    return f"<header><h1>Eco-driving benchmark: <code>{esc(page.run_name)}</code></h1><div class='facts'>{cells}</div></header>"


def nav(items: list[tuple[str, str]]) -> str:
    return "<nav><ol>" + "".join(f"<li><a href='#{a}'>{esc(t)}</a></li>" for a, t in items) + "</ol></nav>"


def claims_section(page: Page) -> str:
    out = ["<section id='claims'><h2>Does the paper hold on this run?</h2>"]
    if page.claims is not None and len(page.claims):
        c = page.claims
        counts = c.status.value_counts()
        summary = " \u00a0".join(f"{badge(s)}\u00a0{int(counts.get(s, 0))}" for s in STATUSES)
        res = page.results
        cases = int(res.groupby(["method", "signals"]).case.nunique().max()) if res is not None and "case" in res else 0
        seeds = (int(res[res.train_seed >= 0].groupby(["method", "signals"]).train_seed.nunique().max())
                 if res is not None and "train_seed" in res and (res.train_seed >= 0).any() else 1)
        per = f"{cases} test case{'s' if cases != 1 else ''} per method and setting" + (
            f", up to {seeds} training seeds each" if seeds > 1 else "")
        other = overrides_text(page.manifest.get("scenario_overrides") or {}) if page.manifest else ""
        if other:
            out.append(f"<p class='lead'><b>This run's scenario is not the paper's</b> (<code>{esc(other)}</code>): "
                       "every claim is NOT CHECKED, and the paper's numbers stand beside this run's for reference "
                       "only.</p>")
        out.append(f"<p class='lead'><b>{len(c)} claims</b> from the paper: {summary}.</p>"
                   "<p>Section 5.3's and Table 4's claims, "
                   f"checked on this run's own episodes ({per}; the paper used 100 cases) with the published "
                   "numbers and tolerances of "
                   "<code>bench/paper.py</code>. A claim about a method or setting this run did not evaluate is "
                   "NOT CHECKED, never a pass. <code>ecodrive regress</code> checks the same claims on 20 "
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
                   "claims are NOT CHECKED.</p>")
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
        head = ("<thead><tr><th rowspan='2' scope='col'>Method</th><th rowspan='2' scope='col'>Episodes</th>"
                "<th colspan='5' class='group first'>Energy consumption [Wh]</th>"
                "<th colspan='5' class='group first'>Travel time [s]</th></tr><tr>"
                + "<th class='first'>This run</th><th>Paper</th><th>vs paper</th><th>Imp.</th><th>Paper Imp.</th>" * 2 + "</tr></thead>")
        parts.append(f"<div class='scroll'><table class='table4' id='table4-{esc(signals)}'><caption><b>Table 4, "
                     f"{esc(signals)} signals.</b> Mean over {ncases} episodes per method: the fixed test cases times the "
                     "method's training seeds (the paper: 100 cases, one policy). "
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
                          td(DASH if missing(r.p_improve_vs_baseline) else
                             f"{num(r.p_improve_vs_baseline, 2)} <span class='ci'>"
                             f"{ci(r.get('p_improve_ci_low'), r.get('p_improve_ci_high'), 2)}</span>", "num", raw=True)]
            rows.append("<tr>" + "".join(cells) + "</tr>")
        head = ("<thead><tr><th rowspan='2'>Method</th><th rowspan='2'>Episodes</th>"
                + "".join(f"<th colspan='3' class='group first'>{t} [{u}]</th>" for t, u in METRIC_UNITS.values())
                + "</tr><tr>" + "<th class='first'>Mean [95% CI]</th><th>IQM [95% CI]</th><th>P(improve)</th>" * 2
                + "</tr></thead>")
        out.append(f"<div class='scroll'><table class='stats' id='stats-{esc(signals)}'><caption><b>{esc(signals)} "
                   "signals</b>, per episode. IQM = interquartile (25%-trimmed) mean. P(improve) [95% CI] = chance that "
                   "the method uses less energy (or takes less time) than the baseline <i>on the same case</i>: per "
                   "case over the method's training seeds, averaged over the cases (rliable's paired form; CI by "
                   f"resampling cases and seeds); 0.5 = no difference, {DASH} for the baseline itself.</caption>{head}<tbody>{''.join(rows)}</tbody>"
                   "</table></div>")
    out.append(seeds_table(page))
    out.append("</section>")
    return "".join(out)


def seeds_table(page: Page) -> str:
    sd = page.seeds
    if sd is None or sd.empty:
        return ""
    out = ["<h3 id='seeds'>Across training seeds</h3>",
           "<p>Each method's runs on the same cases, a learning method's shipped training seeds: the mean over "
           "seeds and cases with a 95% stratified bootstrap CI over seeds (seeds resampled per case, as rliable "
           "does), the IQM over all seed \u00d7 case runs, and the range of the per-seed means. With one seed (and "
           "for the rule-based methods and an agent of your own, which run once) there is no spread to resample: "
           "<i>one seed</i>.</p>"]
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
    partial += (f"<p class='warn'>{page.refused_logs} step log(s) were refused by the log reader (missing, "
                "unreadable, past a size limit or holding what no log of the writer holds); they are left out here "
                "and from the trajectories, each reason under Warnings.</p>" if page.refused_logs else "")
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
    return TEMPLATE.render(title=esc(f"Report: {page.run_name}"), css=CSS, header=header(page), nav=nav(toc),
                               body="\n".join(body))
