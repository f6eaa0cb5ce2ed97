"""Config fields declared once, validated once: the scenario's (``envs.config``) and the learning
agents' (``agents.pdqn``, ``agents.dqn``, ``agents.ddpg``) configs alike.

A field is declared with ``param(default, lo, hi, unit=..., doc=...)`` (or ``choices=``): its
meaning, unit and accepted range live in the field's metadata, where ``validate`` checks them
(a value outside, of the wrong type, or not finite is a ``ConfigError`` of one line naming the
value and the range) and ``describe`` turns them into ``--help`` text, as CleanRL's attribute
docstrings become its ``--help``. Pure Python: no SUMO, no torch."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import MISSING, field, fields
from typing import Any


class ConfigError(ValueError):
    """A config key or value that is not accepted; the message names the value and the range."""


def rng(lo: float | None, hi: float | None, *, lo_open: bool = False) -> dict[str, Any]:
    """Field metadata: a number in [lo, hi] ((lo, hi] with lo_open; None: unbounded on that side)."""
    return {"lo": lo, "hi": hi, "lo_open": lo_open}


def each(lo: float, hi: float) -> dict[str, Any]:
    """Range of every entry of an optional tuple field (None: the field is not set)."""
    return {**rng(lo, hi), "each": True, "optional": True}


def param(default: Any, lo: float | None = None, hi: float | None = None, *, doc: str, unit: str = "",
          lo_open: bool = False, choices: tuple[str, ...] | None = None, each: bool = False,
          optional: bool = False, text: int | None = None) -> Any:
    """A config field: ``default``, its meaning ``doc``, its ``unit`` ("-" or "" for none) and its
    accepted values: a number in [lo, hi] ((lo, hi] with ``lo_open``), one of ``choices``, a
    tuple of such numbers (``each``, None allowed), a number or None (``optional``), or a text of
    at most ``text`` characters or None."""
    meta: dict[str, Any] = {"doc": doc, "unit": unit}
    if text is not None:
        meta["text"] = text
    elif choices is not None:
        meta["choices"] = tuple(choices)
    elif each:
        meta.update(globals()["each"](lo, hi))  # the module's each(): the name is shadowed here
    elif lo is not None or hi is not None:
        meta.update(rng(lo, hi, lo_open=lo_open), **({"optional": True} if optional else {}))
    return field(default=default, metadata=meta)


def accepted_text(meta: Mapping[str, Any], type_name: str = "") -> str:
    """The accepted values of a field, as its error messages and ``--help`` say them."""
    if "choices" in meta:
        return "one of " + ", ".join(map(str, meta["choices"]))
    if "text" in meta:
        return f"a text of 1 to {meta['text']} characters, or null"
    if "lo" in meta:
        return ("an integer in " if type_name.startswith("int") else "") + range_text(meta)
    return "true or false" if type_name == "bool" else "any"


def describe(cls: type, skip: tuple[str, ...] = ()) -> list[str]:
    """One line per field of a config dataclass: name, default, unit, meaning, accepted values."""
    out = []
    for f in fields(cls):
        if f.name in skip:
            continue
        meta = f.metadata
        unit = meta.get("unit", "")
        default = f.default if f.default is not MISSING else "(required)"
        out.append(f"{f.name} = {default}{f' [{unit}]' if unit and unit != '-' else ''}: {meta.get('doc', '')}"
                   f" (accepted: {accepted_text(meta, str(f.type))})")
    return out


def validate(obj: Any) -> None:
    """Check every field of a config dataclass against its metadata."""
    for f in fields(obj):
        value = getattr(obj, f.name)
        meta = f.metadata
        name = f.name
        if "text" in meta:
            if value is not None and (not isinstance(value, str) or not 0 < len(value) <= meta["text"]):
                raise ConfigError(f"{name}={short(value)} is not accepted; accepted: {accepted_text(meta)}")
            continue
        if "choices" in meta:
            if value not in meta["choices"]:
                raise ConfigError(f"{name}={short(value)} is not accepted; choose one of {', '.join(meta['choices'])}")
            continue
        if "lo" not in meta:
            if f.type in ("bool",) and not isinstance(value, bool):
                raise ConfigError(f"{name}={short(value)} must be true or false")
            continue
        if value is None and meta.get("optional"):
            continue
        if meta.get("each"):
            if not isinstance(value, tuple):
                raise ConfigError(f"{name}={short(value)} must be a list of numbers (or null)")
            for i, v in enumerate(value):
                check_number(f"{name}[{i}]", v, meta, want_int=False)
            continue
        check_number(name, value, meta, want_int=f.type.startswith("int"))


def range_text(meta: Mapping[str, Any]) -> str:
    lo, hi = meta["lo"], meta["hi"]
    return (f"{'(' if meta['lo_open'] or lo is None else '['}{'-inf' if lo is None else lo}, "
            f"{'inf)' if hi is None else f'{hi}]'}")


def check_number(name: str, value: Any, meta: Mapping[str, Any], want_int: bool) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (want_int and not isinstance(value, int)):
        raise ConfigError(f"{name}={short(value)} must be {'an integer' if want_int else 'a number'} "
                          f"in {range_text(meta)}")
    lo, hi = meta["lo"], meta["hi"]
    # an int is compared exactly (math.isfinite would overflow on one beyond a float's range)
    bad = isinstance(value, float) and not math.isfinite(value)
    bad = bad or (lo is not None and (value <= lo if meta["lo_open"] else value < lo))
    bad = bad or (hi is not None and value > hi)
    if bad:
        raise ConfigError(f"{name}={short(value)} is out of range; accepted: {range_text(meta)}")


def short(value: Any, limit: int = 60) -> str:
    """``repr`` of a value, cut to ``limit`` characters: an error stays one readable line."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 128:
        return f"<an integer of about {int(value.bit_length() * math.log10(2)) + 1} digits>"
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def accepted_range(cls: type, name: str) -> tuple[float | None, float | None, bool]:
    """(lo, hi, lo_open) of a numeric config field, for command-line parsers to check against."""
    meta = {f.name: f.metadata for f in fields(cls)}[name]
    return meta["lo"], meta["hi"], meta["lo_open"]
