"""The report page's inline stylesheet and its Jinja2 skeleton (no script, nothing fetched)."""
from __future__ import annotations

import jinja2

CSS = """
:root { --fg:#1d2327; --muted:#5f6b73; --line:#d9dee2; --bg:#ffffff; --band:#f5f7f9; --accent:#1f5f99;
        --pass:#1a7f37; --pass-bg:#e6f4ea; --fail:#b42318; --fail-bg:#fdecea; --absent:#6b7280; --absent-bg:#eef0f2;
        --known:#8a5a00; --known-bg:#fdf3dc; }
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
.scroll { overflow-x:auto; margin:10px 0 18px; container-type:inline-size; }
.scroll > table > caption { position:sticky; left:0; max-width:100cqw; }  /* readable while the table scrolls */
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
.badge.known { color:var(--known); background:var(--known-bg); }
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

ENV = jinja2.Environment(autoescape=True, keep_trailing_newline=True)  # the page's templates: data escaped
# the page skeleton: the sections' HTML (``body``) and the stylesheet as they are
TEMPLATE = ENV.from_string("""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{{ title }}</title>
<style>{{ css | safe }}</style>
</head>
<body>
<main>
<header><h1>Eco-driving benchmark: <code>{{ run_name }}</code></h1><div class='facts'>
{%- for label, text, code in facts -%}
<div class='fact'><span>{{ label }}</span><b>{{ text }}{% if code %}<code>{{ code }}</code>{% endif %}</b></div>
{%- endfor -%}
</div></header>
<nav><ol>{% for anchor, text in toc %}<li><a href='#{{ anchor }}'>{{ text }}</a></li>{% endfor %}</ol></nav>
{{ body | safe }}
<footer>Written by <code>ecodrive report</code> from the run folder's <code>results.parquet</code>,
<code>manifest.json</code> and step logs; <code>index.md</code> has the same sections as text, without the
provenance table (<code>manifest.json</code> holds it), with the tables and figures beside it (<code>table4.csv</code>, <code>statistics.csv</code>, <code>seeds.csv</code>, <code>figures/*.pdf</code>).
Self-contained: no script, nothing fetched.</footer>
</main>
</body>
</html>
""")
