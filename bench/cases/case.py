"""Fixed test cases: (SUMO seed, ego insertion time) pairs shared by every method.

The list is generated from a documented master seed and stored in ``bench/cases/cases.json`` (a
versioned file in the repo). ``ecodrive cases --write`` regenerates it; ``--check``
verifies the stored file matches the generator (``bench.shipped.cases_command``).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ecodrive_bench.bench.args import InputError, read_json

MASTER_SEED = 20240501  # documented master seed of the protocol
CASES_PER_SETTING = 100  # section 5.3
SEED_GROUPS = 10  # independent groups for the violin figure
INSERT_RANGE = (150.0, 300.0)  # [s] U(150, 300); a stored case's insert_time must lie in it
SEED_BOUND = 2**31 - 1  # [-] SUMO seeds are drawn from [0, SEED_BOUND)
CASE_KEYS = ("index", "sumo_seed", "insert_time", "group")  # every key of a stored case, no other
VERSION = 1
CASES_FILE = Path(__file__).with_name("cases.json")


class CaseError(InputError):
    """A case list (its file or one of its cases) that is not accepted; one line naming the file,
    the case and the value with the accepted range. ``ecodrive`` commands exit 2 on it."""


@dataclass(frozen=True)
class Case:
    index: int
    sumo_seed: int
    insert_time: float  # [s], rounded to 0.1 s
    group: int  # seed group: the index mod SEED_GROUPS in the fixed list

    def options(self) -> dict[str, float]:
        return {"sumo_seed": self.sumo_seed, "insert_time": self.insert_time}


def generate(master_seed: int = MASTER_SEED, n: int = CASES_PER_SETTING, groups: int = SEED_GROUPS) -> dict:
    rng = np.random.default_rng(master_seed)
    seeds = rng.choice(SEED_BOUND, size=n, replace=False)
    times = np.round(rng.uniform(*INSERT_RANGE, size=n), 1)
    cases = [{"index": i, "sumo_seed": int(seeds[i]), "insert_time": float(times[i]), "group": i % groups}
             for i in range(n)]
    return {"version": VERSION, "master_seed": master_seed, "insert_range_s": list(INSERT_RANGE),
            "groups": groups, "cases": cases}


def load(path: Path = CASES_FILE) -> list[Case]:
    """The fixed cases of a case-list file, each checked (``check_cases``): a file that is not a
    regular JSON file of at most ``MAX_JSON_BYTES``, of another version, or with a bad case is a
    ``CaseError`` of one line naming the file, the case and the value."""
    try:
        data = read_json(path, "case list")
    except InputError as e:
        raise CaseError(str(e)) from None
    if not isinstance(data, dict) or data.get("version") != VERSION:
        got = data.get("version") if isinstance(data, dict) else None
        raise CaseError(f"{path}: cases version {_shown(got)} is not the supported {VERSION}")
    check_header(data, path)
    out = check_cases(data.get("cases"), path, groups=SEED_GROUPS)
    for pos, c in enumerate(out):
        if c.group != c.index % SEED_GROUPS:
            raise CaseError(f"{path}: case #{pos} (index {c.index}): group={c.group}; accepted: the index mod "
                            f"{SEED_GROUPS}, {c.index % SEED_GROUPS} (the violin figure's seed group)")
    return out


def check_header(data: dict, where: str | Path) -> None:
    """The fixed case list's header, or a one-line ``CaseError``: ``groups`` the violin figure's
    ``SEED_GROUPS`` (it groups the cases by index mod 10), ``master_seed`` a non-negative integer
    (it documents how the list was drawn), ``insert_range_s`` the protocol's ``INSERT_RANGE``."""
    groups = data.get("groups")
    if isinstance(groups, bool) or groups != SEED_GROUPS:
        raise CaseError(f"{where}: groups={_shown(groups)}; accepted: {SEED_GROUPS} (the violin figure groups the "
                        f"cases by index mod {SEED_GROUPS})")
    seed = data.get("master_seed")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise CaseError(f"{where}: master_seed={_shown(seed)}; accepted: a non-negative integer")
    span = data.get("insert_range_s")
    if not (isinstance(span, list) and len(span) == 2 and all(type(x) in (int, float) for x in span)
            and tuple(float(x) for x in span) == INSERT_RANGE):
        raise CaseError(f"{where}: insert_range_s={_shown(span)}; accepted: [{INSERT_RANGE[0]}, {INSERT_RANGE[1]}], "
                        f"the protocol's insertion window [s]")


def check_cases(raw: Any, where: str | Path, groups: int) -> list[Case]:
    """``raw`` (a JSON list of case objects) as ``Case``s, every value checked: exactly the keys
    ``CASE_KEYS``; index a non-negative integer, unique; sumo_seed an integer in [0, 2**31-1);
    insert_time a number in ``INSERT_RANGE``; group an integer in [0, groups). Otherwise a
    ``CaseError`` of one line naming ``where``, the case and the bad value with the accepted range."""
    if raw is None:
        raise CaseError(f"{where}: no 'cases' list (missing or null); accepted: a non-empty list of case objects")
    if not isinstance(raw, list) or not raw:
        raise CaseError(f"{where}: 'cases' is {_shown(raw)}; accepted: a non-empty list of case objects")
    out, seen = [], {}
    for pos, c in enumerate(raw):
        at = f"{where}: case #{pos}"
        if not isinstance(c, dict):
            raise CaseError(f"{at} is {_shown(c)}; accepted: an object with keys {', '.join(CASE_KEYS)}")
        if isinstance(c.get("index"), int) and not isinstance(c.get("index"), bool):
            at = f"{where}: case #{pos} (index {_shown(c['index'])})"
        unknown = sorted(str(k) for k in c if k not in CASE_KEYS)
        missing = [k for k in CASE_KEYS if k not in c]
        if unknown or missing:
            raise CaseError(f"{at}: {'unknown key(s) ' + ', '.join(map(repr, unknown)) if unknown else ''}"
                            f"{'; ' if unknown and missing else ''}"
                            f"{'missing key(s) ' + ', '.join(map(repr, missing)) if missing else ''}; "
                            f"accepted: exactly {', '.join(CASE_KEYS)}")
        _integer(at, "index", c["index"], 0, None)
        _integer(at, "sumo_seed", c["sumo_seed"], 0, SEED_BOUND, "2**31-1")
        _integer(at, "group", c["group"], 0, groups)
        t = c["insert_time"]
        lo, hi = INSERT_RANGE
        if isinstance(t, bool) or not isinstance(t, (int, float)) or not lo <= t <= hi:  # NaN fails too
            raise CaseError(f"{at}: insert_time={_shown(t)}; accepted: a number of seconds in [{lo}, {hi}]")
        if c["index"] in seen:
            raise CaseError(f"{at}: index={c['index']} is also case #{seen[c['index']]}'s; accepted: unique "
                            f"non-negative integers (each case writes case-<index>.mcap)")
        seen[c["index"]] = pos
        out.append(Case(int(c["index"]), int(c["sumo_seed"]), float(t), int(c["group"])))
    return out


def _integer(at: str, key: str, value: Any, lo: int, hi: int | None, hi_text: str = "") -> None:
    """An integer in [lo, hi) (hi None: no upper bound), else a ``CaseError``."""
    if isinstance(value, bool) or not isinstance(value, int) or value < lo or (hi is not None and value >= hi):
        span = f"[{lo}, {hi_text or ('inf' if hi is None else hi)})"
        raise CaseError(f"{at}: {key}={_shown(value)}; accepted: an integer in {span}")


def _shown(value: Any) -> str:
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 190:
        return f"<an integer of about {int(value.bit_length() * 0.30103) + 1} digits>"
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."
