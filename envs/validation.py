"""Field validation of the config dataclasses (``envs.config``): every numeric field declares its
accepted range in its metadata, and a value outside it, of the wrong type, or not finite is a
``ConfigError`` of one line naming the value and the range."""
from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import fields
from typing import Any


class ConfigError(ValueError):
    """A config key or value that is not accepted; the message names the value and the range."""


def rng(lo: float | None, hi: float | None, *, lo_open: bool = False) -> dict[str, Any]:
    """Field metadata: a number in [lo, hi] ((lo, hi] with lo_open; None: unbounded on that side)."""
    return {"lo": lo, "hi": hi, "lo_open": lo_open}


def each(lo: float, hi: float) -> dict[str, Any]:
    """Range of every entry of an optional tuple field (None: the field is not set)."""
    return {**rng(lo, hi), "each": True, "optional": True}


def validate(obj: Any) -> None:
    """Check every field of a config dataclass against its metadata."""
    for f in fields(obj):
        value = getattr(obj, f.name)
        meta = f.metadata
        name = f.name
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
