"""Atomic writes and checksums: a killed process leaves the old file or the new one, never half
of either (``os.replace`` after writing a hidden temporary beside the target; no fsync, so not
proof against power loss)."""
from __future__ import annotations

import hashlib
import io
import json
import os
from pathlib import Path
from typing import Any


class Unwritable(OSError):
    """A folder that cannot be created or written; its message is one line naming it."""


def writable_dir(path: Path) -> Path:
    """Create ``path`` (with its parents) and prove it writable with a probe file, so that a run
    fails before any work, with one line, rather than in the middle of it."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".write-test-{os.getpid()}"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        raise Unwritable(f"folder {path} is not writable ({e.strerror or e})") from None
    return path


def sha256(path: Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _tmp(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp")


def atomic_bytes(data: bytes, path: Path) -> None:
    tmp = _tmp(path)
    tmp.write_bytes(data)
    os.replace(tmp, path)


def atomic_text(text: str, path: Path) -> None:
    atomic_bytes(text.encode(), path)


def atomic_json(obj: Any, path: Path, **kw: Any) -> None:
    atomic_text(json.dumps(obj, indent=1, **kw) + "\n", path)


def atomic_parquet(df: Any, path: Path) -> None:
    tmp = _tmp(path)
    df.to_parquet(tmp, index=False)
    os.replace(tmp, path)


def atomic_csv(df: Any, path: Path, **kw: Any) -> None:
    tmp = _tmp(path)
    df.to_csv(tmp, index=False, **kw)
    os.replace(tmp, path)


def atomic_torch_save(obj: Any, path: Path) -> None:
    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    atomic_bytes(buf.getvalue(), path)
