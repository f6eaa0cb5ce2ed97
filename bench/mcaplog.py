"""MCAP step log: protobuf messages, zstd chunks, one file per episode.

Channels: ``/meta`` (one ``Metadata``), ``/step`` (one ``Step`` per simulation step, log time =
simulation time) and ``/episode`` (one ``Episode`` summary, written last). A file is written as
``<name>.part`` and renamed when finished, so a finished ``.mcap`` is complete by construction;
a killed run leaves a ``.part`` that ``read_log`` reads up to its last complete chunk.
"""
from __future__ import annotations

import json
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from mcap.exceptions import McapError
from mcap.records import Message
from mcap.stream_reader import StreamReader
from mcap_protobuf.writer import Writer

from . import schema

CHUNK_SIZE = 64 * 1024  # [bytes] small chunks: a killed run loses at most this much
TOPICS = {"/meta": schema.Metadata, "/step": schema.Step, "/episode": schema.Episode}
PART = ".part"


class LogError(RuntimeError):
    """A step log that cannot be read at all; the message names the file and the cause."""


def _ns(t: float) -> int:
    return int(round(t * 1e9))


class EpisodeLog:
    """Writes one episode. Use as the env's recorder: ``env.unwrapped.recorder = log.record``."""

    def __init__(self, path: str | Path, meta: dict[str, Any]) -> None:
        self.path = Path(path)
        self.part = self.path.with_name(self.path.name + PART)
        self.part.parent.mkdir(parents=True, exist_ok=True)
        self._f = open(self.part, "wb")
        self._w = Writer(self._f, chunk_size=CHUNK_SIZE)
        self._w.add_metadata("ecodrive", {k: str(v) for k, v in meta.items()})
        m = schema.Metadata(**{k: v for k, v in meta.items() if k in schema.Metadata.DESCRIPTOR.fields_by_name})
        self._w.write_message("/meta", m, log_time=0, publish_time=0)
        self._last_time = 0.0
        self.raw_action: list[float] = []

    def record(self, rec: dict[str, Any]) -> None:
        info, m, obs, sig = rec["info"], rec["measure"], rec["obs"], rec["signal"]
        grid = obs["grid"]
        s = schema.Step(
            time=rec["time"], travel_time=info["travel_time"], x=rec["x"], y=rec["y"], angle=rec["angle"],
            speed=rec["speed"], accel=rec["accel"], lane=rec["lane"], edge=rec["edge"],
            grid=np.asarray(grid, dtype=np.uint8).tobytes(), grid_rows=grid.shape[0], grid_cols=grid.shape[1],
            logic=obs["logic"].tolist(), action_mask=info["action_mask"].tolist(), raw_action=self.raw_action,
            energy_step=info["energy_step"], energy_total=info["energy"], jerk=info["jerk"], reward=rec["reward"],
            tls_states=rec["tls_states"], collisions=info["collisions"], teleports=info["teleports"],
        )
        if m is not None:
            s.has_request = info["requested"] is not None
            s.requested_lateral = m.requested_lateral
            s.requested_accel = 0.0 if np.isnan(m.requested_accel) else m.requested_accel
            s.applied_lateral, s.applied_accel, s.clipped = m.applied_lateral, m.applied_accel, m.clipped
        if rec["components"]:
            s.components.CopyFrom(schema.RewardComponents(**rec["components"]))
        if sig is not None:
            s.signal.CopyFrom(schema.Signal(tls=sig.tls, link=sig.link, distance=sig.distance, state=sig.state,
                                            in_range=sig.in_range, red=sig.red, time_to_green=sig.time_to_green))
        for x, y, a, length in rec["others"].tolist():
            s.neighbours.add(x=x, y=y, angle=a, length=length)
        self._last_time = rec["time"]
        t = _ns(rec["time"])
        self._w.write_message("/step", s, log_time=t, publish_time=t)

    def finish(self, summary: dict[str, Any]) -> Path:
        """Write the episode summary, close, and publish the file under its final name."""
        t = _ns(self._last_time)
        self._w.write_message("/episode", schema.Episode(**summary), log_time=t, publish_time=t)
        self._w.finish()
        self._f.flush()
        os.fsync(self._f.fileno())
        self._f.close()
        os.replace(self.part, self.path)
        return self.path

    def abort(self) -> None:
        """Close without publishing (the ``.part`` stays for inspection)."""
        if not self._f.closed:
            self._f.close()


@dataclass
class LogData:
    path: Path
    meta: dict[str, str] = field(default_factory=dict)
    metadata: Any = None  # the /meta message
    steps: list[Any] = field(default_factory=list)
    episode: Any = None  # the /episode message, None if the run did not finish
    complete: bool = False  # footer read and episode summary present
    warning: str = ""

    def grid(self, i: int) -> np.ndarray:
        s = self.steps[i]
        return np.frombuffer(s.grid, dtype=np.uint8).reshape(s.grid_rows, s.grid_cols)


def read_log(path: str | Path) -> LogData:
    """Read a step log, complete or truncated. Raises ``LogError`` if nothing can be read."""
    path = Path(path)
    if not path.exists():
        raise LogError(f"{path}: no such log file")
    data = LogData(path)
    channels: dict[int, str] = {}
    footer = False
    try:
        with open(path, "rb") as f:
            for rec in StreamReader(f, validate_crcs=True).records:
                kind = type(rec).__name__
                if kind == "Channel":
                    channels[rec.id] = rec.topic
                elif kind == "Metadata" and rec.name == "ecodrive":
                    data.meta = dict(rec.metadata)
                elif kind == "Footer":
                    footer = True
                elif isinstance(rec, Message):
                    topic = channels.get(rec.channel_id)
                    cls = TOPICS.get(topic or "")
                    if cls is None:
                        continue
                    msg = cls.FromString(rec.data)
                    if topic == "/step":
                        data.steps.append(msg)
                    elif topic == "/episode":
                        data.episode = msg
                    else:
                        data.metadata = msg
    except (McapError, struct.error, ValueError, EOFError, OSError) as e:  # truncated or corrupt tail
        if data.metadata is None and not data.steps:
            raise LogError(f"{path}: not a readable MCAP step log ({type(e).__name__}: {e})") from None
        data.warning = f"{path}: log is truncated or corrupt after {len(data.steps)} steps ({type(e).__name__})"
    except Exception as e:  # decoder errors from a damaged message
        if data.metadata is None and not data.steps:
            raise LogError(f"{path}: not a readable MCAP step log ({type(e).__name__}: {e})") from None
        data.warning = f"{path}: log is corrupt after {len(data.steps)} steps ({type(e).__name__}: {e})"
    data.complete = footer and data.episode is not None and not data.warning
    if not data.complete and not data.warning:
        data.warning = f"{path}: log is incomplete ({len(data.steps)} steps, no episode summary)"
    return data


def is_complete(path: str | Path) -> bool:
    """True for a finished, fully readable log (used to skip cases on resume)."""
    try:
        return read_log(path).complete
    except LogError:
        return False


def meta_json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, default=str)
