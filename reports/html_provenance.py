"""The report page's provenance: the run's command, code, packages, timings against SUMO's floor and
scenario, from ``manifest.json``: the values here (``provenance``), the markup in the Jinja2
template ``PROVENANCE``. A value is a list of pieces, (kind, text): "" plain text, "code", "sha"
(code that may break anywhere), "ci" (a muted note), "badge" (a warning), "br" (a line break)."""
from __future__ import annotations

import math

from .html_parts import DASH, duration, missing, pct
from .html_style import ENV

Piece = tuple[str, str]
NOTE = (("", " "),)  # the space before a note

PROVENANCE = ENV.from_string("""
{%- macro value(pieces) %}{% for kind, text in pieces %}{% if kind == "code" %}<code>{{ text }}</code>
{%- elif kind == "sha" %}<code class='sha'>{{ text }}</code>{% elif kind == "ci" %}<span class='ci'>{{ text }}</span>
{%- elif kind == "badge" %}<span class='badge fail'>{{ text }}</span>{% elif kind == "br" %}<br>
{%- else %}{{ text }}{% endif %}{% endfor %}{% endmacro -%}
<section id='provenance'><h2>Provenance</h2>
{%- if not rows -%}
<p>No <code>manifest.json</code> in this run folder: where these numbers came from is not recorded.</p>
{%- else -%}
<table class='kv'><caption>From the run's <code>manifest.json</code> (written by <code>ecodrive run</code>).</caption><tbody>
{%- for key, pieces in rows %}<tr><th scope='row'>{{ key }}</th><td>{{ value(pieces) }}</td></tr>{% endfor -%}
</tbody></table><div class='pair'>
{%- if packages -%}
<table class='kv packages'><caption>Package versions (SUMO first).</caption><tbody>
{%- for name, version, sumo in packages %}<tr class='{{ "hl" if sumo }}'><th scope='row'>{{ name }}</th><td><code>{{ version }}</code></td></tr>{% endfor -%}
</tbody></table>
{%- else %}<p>No package versions recorded.</p>{% endif -%}
{%- if shas -%}
<table class='kv'><caption>Policies evaluated: sha256 of each <code>policy.pt</code> (<code>models/&lt;method&gt;-&lt;signals&gt;/s&lt;seed&gt;/</code>), of a plug-in agent's code, or of a planner's versions.</caption><tbody>
{%- for name, sha in shas %}<tr><th scope='row'>{{ name }}</th><td><code class='sha'>{{ sha }}</code></td></tr>{% endfor -%}
</tbody></table></div>
{%- else %}<p>No learned policy in this run (rule-based methods only): no checkpoint hashes.</p></div>{% endif -%}
{%- if scenario -%}
<details><summary>Scenario configuration per setting (<code>envs.config.ScenarioConfig</code>; rows that differ between the settings are marked)</summary><div class='scroll'><table class='kv scenario'><thead><tr><th>Field</th>
{%- for s in settings %}<th>{{ s }}</th>{% endfor %}</tr></thead><tbody>
{%- for key, values, differs in scenario %}<tr class='{{ "differs" if differs }}'><th scope='row'>{{ key }}</th>
{%- for v in values %}<td class='num'>{{ v }}</td>{% endfor %}</tr>{% endfor -%}
</tbody></table></div></details>
{%- endif -%}
{%- endif -%}
</section>""")


def provenance_section(run_name: str, man: dict) -> str:
    """The provenance part of the page: what ``manifest.json`` records of how the run was made."""
    return PROVENANCE.render(**provenance(run_name, man))


def provenance(run_name: str, man: dict) -> dict:
    """The template's values: ``rows`` (label, pieces) of the run, ``packages`` (name, version, a
    SUMO package) SUMO's first, ``shas`` (policy, sha256), the ``scenario``'s (field, values per
    setting, differs) over its ``settings``; nothing where there is no manifest."""
    if not man:
        return {"rows": []}
    pk = man.get("packages") or {}
    sumo = {k: v for k, v in pk.items() if "sumo" in k}
    flat = {s: _flatten(cfg) for s, cfg in (man.get("scenario") or {}).items()}
    keys = list(dict.fromkeys(k for f in flat.values() for k in f))
    return {"rows": _rows(run_name, man),
            "packages": [(k, v, k in sumo) for k, v in {**sumo, **pk}.items()],
            "shas": list((man.get("checkpoint_sha256") or {}).items()),
            "settings": list(flat),
            "scenario": [(k, [_value(f.get(k)) for f in flat.values()], len({str(f.get(k)) for f in flat.values()}) > 1)
                         for k in keys]}


def _rows(run_name: str, man: dict) -> list[tuple[str, list[Piece]]]:
    sha = str(man.get("git_sha", ""))
    commands = man.get("commands")
    earlier = [c for c in commands[:-1] if isinstance(c, dict)] if isinstance(commands, list) else []
    rows: list[tuple[str, list[Piece]]] = [
        ("Run folder", [("code", run_name)]),
        ("Command" + (" (the latest; the rows below are its own)" if earlier else ""),
         [("code", str(man.get("command", DASH)))])]
    if earlier:
        pieces: list[Piece] = []
        for i, c in enumerate(earlier):
            pieces += [("br", "")] if i else []
            pieces += [("code", str(c.get("command") or DASH)), *NOTE,
                       ("ci", f"(git {str(c.get('git_sha') or DASH)[:12]}, {c.get('episodes_run', DASH)} episodes run)")]
        rows.append((f"Earlier commands on this folder ({len(earlier)}, oldest first)", pieces))
    rows += [("Git SHA", [("sha", sha or DASH)] + ([*NOTE, ("badge", "uncommitted changes")] if sha.endswith("-dirty")
                                                  else [])),
             ("Profile", [("", str(man.get("profile", DASH)))]),
             ("Signal settings", [("", ", ".join(man.get("signals", [])) or DASH)]),
             ("Cases per setting", [("", str(man.get("cases_per_setting", DASH)))]),
             ("Methods", [("", ", ".join(man.get("methods", [])) or DASH)]),
             ("Not in this run (no shipped policy)", [("", ", ".join(man.get("skipped_methods", [])) or "no method skipped")]),
             ("Executor", [("", f"{man.get('executor', DASH)}, {man.get('workers', DASH)} worker(s)")]),
             ("Episodes", [("", f"{man.get('episodes_run', DASH)} run, {man.get('episodes_reused', DASH)} reused from "
                                f"complete logs, {man.get('episodes_kept_from_earlier_commands', DASH)} kept from earlier "
                                "commands")]),
             ("Wall time", [("", duration(man.get("wall_time_s")))] + (
                 [*NOTE, ("ci", "(every command that wrote the folder: "
                                f"{duration(man.get('wall_time_all_commands_s'))})")]
                 if man.get("wall_time_all_commands_s") else []))]
    if man.get("command_wall_s"):
        whole = [("", duration(man.get("command_wall_s"))), *NOTE, ("ci", "(start-up included)")]
        if man.get("command_wall_all_commands_s"):
            recorded = all(isinstance(c, dict) and c.get("command_wall_s") for c in commands or [])
            whole += [*NOTE, ("ci", f"(every command that wrote the folder: "
                                    f"{duration(man.get('command_wall_all_commands_s'))}"
                                    + ("" if recorded else "; earlier commands that did not record it count their "
                                                           "episodes' time") + ")")]
        rows.append(("Whole command", whole))
    floor: list[Piece] = [("", duration(man.get("sumo_time_s")))]
    if man.get("floor_ratio"):
        floor += [*NOTE, ("ci", f"(wall time \u00d7 workers / SUMO's time = {man['floor_ratio']:.2f})")]
    if _floor_all(man):
        floor += [*NOTE, ("ci", _floor_all(man))]
    overhead = man.get("harness_overhead")
    return rows + [("Time in SUMO (the floor)", floor),
                   ("Sum of episode times", [("", duration(man.get("episode_time_sum_s")))]),
                   ("Harness overhead", [("", pct(overhead, 1) if not missing(overhead) else DASH), *NOTE,
                                         ("ci", "(wall time \u00d7 workers / sum of episode times \u2212 1)")])]


def _floor_all(man: dict) -> str:
    """The whole job's ratio to its floor, wall time x workers / SUMO's time, over every command
    that wrote the run folder: of the episodes' and bounds' phases, and of the whole commands
    (start-up, checks and writing included) where recorded ("" where the manifest lacks them)."""
    wall, sumo, workers = (man.get(k) for k in ("wall_time_all_commands_s", "sumo_time_all_commands_s", "workers"))
    if not (wall and sumo and workers):
        return ""
    whole = man.get("command_wall_all_commands_s")
    return (f"(every command: {duration(sumo)}; wall time \u00d7 workers / SUMO's time = {wall * workers / sumo:.2f}"
            + (f", {whole * workers / sumo:.2f} over the whole commands" if whole else "") + ")")


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
