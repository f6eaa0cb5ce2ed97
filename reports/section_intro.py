"""The report's opening: the run's profile, code, size and scenario, and what was cleaned out of
its results. Its warnings open the report's Warnings."""
from __future__ import annotations

from dataclasses import dataclass

from .inputs import Run
from .load import case_set_warnings, unfinished_warnings

ANCHOR = None  # no heading of its own: the page's header shows the same facts
PHASE = None  # the phase of the section after it


@dataclass(frozen=True)
class Intro:
    name: str
    profile: str = ""
    git: str = ""
    episodes: int = 0
    methods: tuple[str, ...] = ()
    overrides: str = ""  # "": the paper's scenario
    cleaned: bool = False
    skipped: tuple[str, ...] = ()
    warnings: tuple[str, ...] = ()
    single_vehicle: bool = False


def compute(run: Run, warnings: list[str]) -> Intro:
    if run.results is None:
        return Intro(run.name)
    res, man = run.results, run.manifest
    notes = [*run.dropped, *case_set_warnings(res), *unfinished_warnings(res)]
    if run.overrides:
        notes.append(f"this run's scenario is not the paper's ({run.overrides}): the paper's "
                     f"Table 4 numbers are beside this run's for reference only, and its claims are NOT CHECKED")
    return Intro(run.name, str(man.get("profile", "?")), str(man.get("git_sha", "?")), len(res), run.methods,
                 run.overrides, bool(run.dropped), tuple(man.get("skipped_methods") or ()), tuple(notes), True)


def markdown(d: Intro) -> str:
    lines = [f"# Report: {d.name}", ""]
    if not d.single_vehicle:
        return "\n".join(lines)
    scenario = f"**not the paper's**: `{d.overrides}` (`--scenario`/`--set`)" if d.overrides else "the paper's"
    lines += [f"Profile `{d.profile}`, git `{d.git}`, {d.episodes} episodes, methods: {', '.join(d.methods)}. "
              f"Scenario: {scenario}.", ""]
    if d.cleaned:
        lines += ["**results.parquet was cleaned before any table or figure was made**: what was dropped (how many "
                  "rows, of which method and setting, and why) or converted is listed under Warnings.", ""]
    if d.skipped:
        lines += [f"Not in this run (no shipped policy): {', '.join(d.skipped)}.", ""]
    return "\n".join(lines)
