"""The report page's provenance section: the run's command, code, packages, timings against SUMO's
floor and scenario, from ``manifest.json``."""
from __future__ import annotations

import math

from .html_parts import DASH, duration, esc, missing, pct, td


def _floor_all(man: dict) -> str:
    """The whole job's ratio to its floor, wall time x workers / SUMO's time, over every command
    that wrote the run folder: of the episodes' and bounds' phases, and of the whole commands
    (start-up, checks and writing included) where recorded ("" where the manifest lacks them)."""
    wall, sumo, workers = (man.get(k) for k in ("wall_time_all_commands_s", "sumo_time_all_commands_s", "workers"))
    if not (wall and sumo and workers):
        return ""
    whole = man.get("command_wall_all_commands_s")
    return (f" <span class='ci'>(every command: {esc(duration(sumo))}; wall time \u00d7 workers / SUMO's time = "
            f"{wall * workers / sumo:.2f}"
            + (f", {whole * workers / sumo:.2f} over the whole commands" if whole else "") + ")</span>")

def provenance_section(run_name: str, man: dict) -> str:
    """The provenance part of the page: what ``manifest.json`` records of how the run was made."""
    out = ["<section id='provenance'><h2>Provenance</h2>"]
    if not man:
        out.append("<p>No <code>manifest.json</code> in this run folder: where these numbers came from is not "
                   "recorded.</p></section>")
        return "".join(out)
    sha = str(man.get("git_sha", ""))
    dirty = " <span class='badge fail'>uncommitted changes</span>" if sha.endswith("-dirty") else ""
    overhead = man.get("harness_overhead")
    commands = man.get("commands")
    earlier = [c for c in commands[:-1] if isinstance(c, dict)] if isinstance(commands, list) else []
    rows = [("Run folder", f"<code>{esc(run_name)}</code>"),
            ("Command" + (" (the latest; the rows below are its own)" if earlier else ""),
             f"<code>{esc(man.get('command', DASH))}</code>")]
    if earlier:
        rows.append((f"Earlier commands on this folder ({len(earlier)}, oldest first)", "<br>".join(
            f"<code>{esc(c.get('command') or DASH)}</code> <span class='ci'>(git {esc(str(c.get('git_sha') or DASH)[:12])}, "
            f"{esc(c.get('episodes_run', DASH))} episodes run)</span>" for c in earlier)))
    rows += [("Git SHA", f"<code class='sha'>{esc(sha or DASH)}</code>{dirty}"),
             ("Profile", esc(man.get("profile", DASH))),
             ("Signal settings", esc(", ".join(man.get("signals", [])) or DASH)),
             ("Cases per setting", esc(man.get("cases_per_setting", DASH))),
             ("Methods", esc(", ".join(man.get("methods", [])) or DASH)),
             ("Not in this run (no shipped policy)", esc(", ".join(man.get("skipped_methods", [])) or "no method skipped")),
             ("Executor", esc(f"{man.get('executor', DASH)}, {man.get('workers', DASH)} worker(s)")),
             ("Episodes", esc(f"{man.get('episodes_run', DASH)} run, {man.get('episodes_reused', DASH)} reused from "
                              f"complete logs, {man.get('episodes_kept_from_earlier_commands', DASH)} kept from earlier "
                              "commands")),
             ("Wall time", esc(duration(man.get("wall_time_s")))
              + (f" <span class='ci'>(every command that wrote the folder: "
                 f"{esc(duration(man.get('wall_time_all_commands_s')))})</span>"
                 if man.get("wall_time_all_commands_s") else "")),
             *([("Whole command", esc(duration(man.get("command_wall_s")))
                 + " <span class='ci'>(start-up included)</span>"
                 + (f" <span class='ci'>(every command that wrote the folder: "
                    f"{esc(duration(man.get('command_wall_all_commands_s')))}"
                    + ("" if all(isinstance(c, dict) and c.get("command_wall_s") for c in commands or [])
                       else "; earlier commands that did not record it count their episodes' time")
                    + ")</span>" if man.get("command_wall_all_commands_s") else ""))]
               if man.get("command_wall_s") else []),
             ("Time in SUMO (the floor)", esc(duration(man.get("sumo_time_s"))) + (
                 f" <span class='ci'>(wall time \u00d7 workers / SUMO's time = {man['floor_ratio']:.2f})</span>"
                 if man.get("floor_ratio") else "") + _floor_all(man)),
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
                   "(<code>models/&lt;method&gt;-&lt;signals&gt;/s&lt;seed&gt;/</code>), of a plug-in agent's code, or of a planner's "
                   "versions.</caption><tbody>"
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

