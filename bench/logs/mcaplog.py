"""MCAP step log: protobuf messages, zstd chunks, one file per episode.

Channels: ``/meta`` (one ``Metadata``), ``/step`` (one ``Step`` per simulation step, log time =
simulation time) and ``/episode`` (one ``Episode`` summary, written last); metadata records ``ecodrive`` (the run's
provenance, written first) and, for a method that plans, ``plan`` (its planned trajectory). A file is written as
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
from mcap.records import Channel, Message
from mcap.well_known import MessageEncoding
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from mcap_protobuf.schema import build_file_descriptor_set

from ecodrive_bench.bench.io import exclusive_open
from ecodrive_bench.bench.logs import bounded, content, schema
from ecodrive_bench.bench.logs.bounded import LogError

CHUNK_SIZE = 64 * 1024  # [bytes] small chunks: a killed run loses the one it was filling (and STEP_BATCH)
# steps held before they are encoded: encoded back to back, the protobuf and MCAP code stays in the
# core's caches (about 3x faster a step than encoding each between two SUMO steps); a killed run
# loses these besides the chunk it was filling (a chunk holds about 130 steps)
STEP_BATCH = 64
TOPICS = {"/meta": schema.Metadata, "/step": schema.Step, "/episode": schema.Episode,
          "/train": schema.TrainEpisode, "/fleet/vehicle": schema.FleetVehicle, "/fleet/cell": schema.FleetCell}
PART = ".part"
PLAN = "plan"  # MCAP metadata record of a planned trajectory (JSON under "json")
# serialized FileDescriptorSets, built once per process (they are the same for every file)
_SCHEMAS = {topic: (cls.DESCRIPTOR.full_name, build_file_descriptor_set(cls).SerializeToString())
            for topic, cls in TOPICS.items()}


def _ns(t: float) -> int:
    return int(round(t * 1e9))


class EpisodeLog:
    """Writes one episode. Use as the env's recorder: ``env.unwrapped.recorder = log.record``."""

    def __init__(self, path: str | Path, meta: dict[str, Any]) -> None:
        self.path = Path(path)
        self.part = self.path.with_name(self.path.name + PART)
        self.part.parent.mkdir(parents=True, exist_ok=True)
        self._f = exclusive_open(self.part)
        self._w = McapWriter(self._f, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        self._w.start(profile="", library="ecodrive-bench")
        self._channels = {
            topic: self._w.register_channel(
                topic=topic, message_encoding=MessageEncoding.Protobuf,
                schema_id=self._w.register_schema(name=name, encoding="protobuf", data=data))
            for topic, (name, data) in _SCHEMAS.items()
        }
        self._step_channel = self._channels["/step"]
        self._w.add_metadata("ecodrive", {k: str(v) for k, v in meta.items()})
        m = schema.Metadata(**{k: v for k, v in meta.items() if k in schema.Metadata.DESCRIPTOR.fields_by_name})
        self._write("/meta", m, 0)
        self._last_time = 0.0
        self.raw_action: list[float] = []
        self._held: list[tuple] = []  # recorded steps not encoded yet: ``_encode``'s arguments

    def _write(self, topic: str, msg: Any, t: int) -> None:
        self._w.add_message(channel_id=self._channels[topic], log_time=t, data=msg.SerializeToString(),
                            publish_time=t)

    def record(self, rec: dict[str, Any]) -> None:
        """Log one step (the env's ``_record``; ``raw_action`` is the agent's action before it).
        Steps are encoded in batches of ``STEP_BATCH``; ``finish`` and ``abort`` encode the rest."""
        obs, info = rec["obs"], rec["info"]
        # the agent gets obs and info before they are encoded: take what it could change now, in
        # the form encoded (``rec`` itself is the env's, built for this call)
        grid = obs["grid"]
        self._held.append((rec, self.raw_action, np.asarray(grid, dtype=np.uint8).tobytes(), grid.shape,
                           obs["logic"].tolist(), info["action_mask"].tolist(), info.copy(), dict(rec["components"])))
        if len(self._held) >= STEP_BATCH:
            self._encode_held()

    def _encode_held(self) -> None:
        held, self._held = self._held, []
        for step in held:
            self._encode(*step)

    def _encode(self, rec: dict[str, Any], raw_action: list[float], grid: bytes, shape: tuple[int, int],
                logic: list[float], mask: list[int], info: dict[str, Any], comps: dict[str, float]) -> None:
        m, sig = rec["measure"], rec["signal"]
        s = schema.Step(
            time=rec["time"], travel_time=info["travel_time"], x=rec["x"], y=rec["y"], angle=rec["angle"],
            speed=rec["speed"], accel=rec["accel"], lane=rec["lane"], edge=rec["edge"],
            grid=grid, grid_rows=shape[0], grid_cols=shape[1], logic=logic, action_mask=mask, raw_action=raw_action,
            energy_step=info["energy_step"], energy_total=info["energy"], jerk=info["jerk"], reward=rec["reward"],
            tls_states=rec["tls_states"], collisions=info["collisions"], teleports=info["teleports"],
        )
        if m is not None:
            s.has_request = info["requested"] is not None
            s.requested_lateral = m.requested_lateral
            s.requested_accel = 0.0 if m.requested_accel != m.requested_accel else m.requested_accel  # nan -> 0
            s.applied_lateral, s.applied_accel, s.clipped = m.applied_lateral, m.applied_accel, m.clipped
        if comps:
            c = s.components
            c.speed, c.jerk, c.lane_change = comps["speed"], comps["jerk"], comps["lane_change"]
            c.distance, c.energy, c.terminal = comps["distance"], comps["energy"], comps["terminal"]
            c.time = comps["time"]
        if sig is not None:
            g = s.signal
            g.tls, g.link, g.distance, g.state = sig.tls, sig.link, sig.distance, sig.state
            g.in_range, g.red, g.time_to_green = sig.in_range, sig.red, sig.time_to_green
        others = rec["others"]
        if others:
            xs, ys, angles, lengths = zip(*others)
            s.neighbour_x.extend(xs)
            s.neighbour_y.extend(ys)
            s.neighbour_angle.extend(angles)
            s.neighbour_length.extend(lengths)
        self._last_time = rec["time"]
        t = _ns(rec["time"])
        self._w.add_message(channel_id=self._step_channel, log_time=t, data=s.SerializeToString(), publish_time=t)

    def add_plan(self, plan: dict[str, Any]) -> None:
        """Attach a planned trajectory (``time``, ``x``, ``speed`` lists and scalars; the ``oracle``
        method's) as the MCAP metadata record ``plan``, read back as ``LogData.plan``."""
        self._w.add_metadata(PLAN, {"json": json.dumps(plan)})

    def finish(self, summary: dict[str, Any]) -> Path:
        """Write the episode summary, close, and publish the file under its final name."""
        self._encode_held()
        t = _ns(self._last_time)
        self._write("/episode", schema.Episode(**summary), t)
        self._w.finish()
        self._f.close()
        os.replace(self.part, self.path)  # atomic against a killed process (no fsync: not power loss)
        return self.path

    def abort(self) -> None:
        """Close without publishing (the ``.part`` stays for inspection, with every recorded step
        that its last complete chunk holds)."""
        if not self._f.closed:
            try:
                self._encode_held()
                self._w.finish()
            except Exception:  # noqa: BLE001  (best effort on a failing run: its own error is the one raised)
                pass
            finally:
                try:
                    self._f.close()
                except OSError:  # the same: a full disk must not hide why the run failed
                    pass


@dataclass
class LogData:
    path: Path
    meta: dict[str, str] = field(default_factory=dict)
    metadata: Any = None  # the /meta message
    steps: list[Any] = field(default_factory=list)
    episode: Any = None  # the /episode message, None if the run did not finish
    train: list[Any] = field(default_factory=list)  # /train messages (training logs)
    fleet_vehicles: list[Any] = field(default_factory=list)  # /fleet/vehicle (mixed traffic)
    fleet_cell: Any = None  # /fleet/cell summary (mixed traffic)
    plan: dict[str, Any] | None = None  # the plan record (the oracle's and mpc's trajectory), if the log has one
    geometry: dict[str, Any] = field(default_factory=dict)  # /meta's corridor drawing, checked ({}: none)
    complete: bool = False  # footer read and episode summary present
    warning: str = ""

    def grid(self, i: int) -> np.ndarray:
        s = self.steps[i]
        return np.frombuffer(s.grid, dtype=np.uint8).reshape(s.grid_rows, s.grid_cols)


def read_log(path: str | Path) -> LogData:
    """Read a step log, complete or truncated, once and at a bounded cost (``bench.logs.bounded``),
    and check what it says (``bench.logs.content``). Raises ``LogError`` (one line naming the file)
    if nothing can be read, past a limit, or for content that no log of the writer holds."""
    path = Path(path)
    if not path.exists():
        raise LogError(f"{path}: no such log file")
    if path.is_dir():
        raise LogError(f"{path}: a folder; expected a step log file (.mcap)")
    if path.stat().st_size == 0:
        raise LogError(f"{path}: an empty file; expected a step log (.mcap)")
    data = LogData(path)
    channels: dict[int, str] = {}
    footer = False
    plan = geometry = None
    try:
        with open(path, "rb") as f:
            for rec in bounded.records(path, f):
                kind = type(rec).__name__
                if kind == "Channel":
                    channels[rec.id] = rec.topic
                elif kind == "Metadata" and rec.name == "ecodrive":
                    data.meta = dict(rec.metadata)
                elif kind == "Metadata" and rec.name == PLAN:
                    if "json" not in rec.metadata:
                        raise LogError(f"{path}: plan: a metadata record without its 'json'; {content.WRITER}")
                    plan = rec.metadata["json"]
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
                    elif topic == "/train":
                        data.train.append(msg)
                    elif topic == "/fleet/vehicle":
                        data.fleet_vehicles.append(msg)
                    elif topic == "/fleet/cell":
                        data.fleet_cell = msg
                    elif data.metadata is None:
                        data.metadata, geometry = msg, msg.geometry_json
    except LogError:
        raise
    except (McapError, struct.error, ValueError, EOFError, OSError) as e:  # truncated or corrupt tail
        if data.metadata is None and not data.steps:
            raise LogError(f"{path}: not a readable MCAP step log ({type(e).__name__}: "
                           f"{str(e).strip() or 'the file ends before its first record is complete'})") from None
        data.warning = f"{path}: log is truncated or corrupt after {len(data.steps)} steps ({type(e).__name__})"
    except Exception as e:  # decoder errors from a damaged message
        if data.metadata is None and not data.steps:
            raise LogError(f"{path}: not a readable MCAP step log ({type(e).__name__}: {e})") from None
        data.warning = f"{path}: log is corrupt after {len(data.steps)} steps ({type(e).__name__}: {e})"
    data.geometry = content.geometry(path, geometry or "")
    data.plan = content.plan(path, plan) if plan is not None else None
    content.steps(path, data.steps, content.timing(data.meta), data.geometry.get("tls"))
    data.complete = footer and data.episode is not None and not data.warning
    if not data.complete and not data.warning:
        data.warning = f"{path}: log is incomplete ({len(data.steps)} steps, no episode summary)"
    return data


def write_records(path: Path, messages: list[tuple[str, Any, int]], meta: dict[str, Any]) -> None:
    """A whole small log at once (training metrics, mixed-traffic cells): (topic, message, log
    time ns) records, written as ``.part`` and renamed."""
    tmp = path.with_name(path.name + PART)
    path.parent.mkdir(parents=True, exist_ok=True)
    with exclusive_open(tmp) as f:
        w = McapWriter(f, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        w.start(profile="", library="ecodrive-bench")
        channels: dict[str, int] = {}
        w.add_metadata("ecodrive", {k: str(v) for k, v in meta.items()})
        for topic, msg, t in messages:
            if topic not in channels:
                name, data = _SCHEMAS[topic]
                channels[topic] = w.register_channel(
                    topic=topic, message_encoding=MessageEncoding.Protobuf,
                    schema_id=w.register_schema(name=name, encoding="protobuf", data=data))
            w.add_message(channel_id=channels[topic], log_time=t, data=msg.SerializeToString(), publish_time=t)
        w.finish()
    os.replace(tmp, path)


def write_train_log(path: Path, rows: list[dict[str, Any]], meta: dict[str, Any]) -> None:
    """All training episodes so far as a ``/train`` channel (rewritten whole, atomically)."""
    fields = schema.TrainEpisode.DESCRIPTOR.fields_by_name
    write_records(path, [("/train", schema.TrainEpisode(**{k: v for k, v in r.items() if k in fields}),
                          int(r["episode"])) for r in rows], meta)


def is_complete(path: str | Path) -> bool:
    """True for a finished, fully readable log."""
    try:
        return read_log(path).complete
    except LogError:
        return False


def read_plan(path: str | Path) -> dict[str, Any] | None:
    """The ``plan`` metadata record of a log, checked (``bench.logs.content.plan``), or None when the
    log has none. Chunks are passed over, never decompressed. Raises ``LogError`` (one line) for a
    log that cannot be read or whose plan no log of the writer holds."""
    path = Path(path)
    try:
        with open(path, "rb") as f:
            for rec in bounded.records(path, f, expand=False):
                if type(rec).__name__ == "Metadata" and rec.name == PLAN:
                    if "json" not in rec.metadata:
                        raise LogError(f"{path}: plan: a metadata record without its 'json'; {content.WRITER}")
                    return content.plan(path, rec.metadata["json"])
    except LogError:
        raise
    except Exception as e:  # a missing or damaged log
        raise LogError(f"{path}: not a readable MCAP step log ({type(e).__name__}: {str(e).strip()[:200]})") from None
    return None


def episode_summary(path: str | Path, agent_sha256: str | None = None, eval_scenario: str | None = None,
                    legacy_scenario: str = "") -> dict[str, Any] | None:
    """The /episode record of a finished log, or None when the file is missing, unfinished,
    damaged or past a limit of ``bench.logs.bounded``, or (given ``agent_sha256``,
    ``eval_scenario``) was written by another policy or on another scenario: the harness then
    reruns the case. A log without an ``eval_scenario_hash`` counts as written on
    ``legacy_scenario``. Fast: the file is read once and only its last chunk is decompressed (the
    writer's summary is the last message; a file that has it elsewhere is run again)."""
    path = Path(path)
    meta: dict[str, str] = {}
    channels: dict[int, str] = {}
    last, footer = None, False
    budget = bounded.Budget(path)
    try:
        with open(path, "rb") as f:
            for rec in bounded.records(path, f, expand=False, budget=budget):
                kind = type(rec).__name__
                if kind == "Metadata" and rec.name == "ecodrive":
                    meta = dict(rec.metadata)
                    if not _same_provenance(meta, agent_sha256, eval_scenario, legacy_scenario):
                        return None  # written first: nothing else is read
                elif kind == "Chunk":
                    last = rec
                elif kind == "Channel":  # the summary's copies
                    channels[rec.id] = rec.topic
                elif kind == "Footer":
                    footer = True
            if last is None or not footer or not _same_provenance(meta, agent_sha256, eval_scenario, legacy_scenario):
                return None
        inside = bounded.chunk_records(path, last, budget)
        channels.update({r.id: r.topic for r in inside if isinstance(r, Channel)})
        episode = next((schema.Episode.FromString(r.data) for r in reversed(inside)
                        if isinstance(r, Message) and channels.get(r.channel_id) == "/episode"), None)
    except Exception:  # any damage means: run the case again
        return None
    if episode is None:
        return None
    return {fd.name: getattr(episode, fd.name) for fd in episode.DESCRIPTOR.fields}


def _same_provenance(meta: dict[str, str], agent_sha256: str | None, eval_scenario: str | None,
                     legacy_scenario: str) -> bool:
    return ((agent_sha256 is None or meta.get("agent_sha256", "") == agent_sha256)
            and (eval_scenario is None or meta.get("eval_scenario_hash", legacy_scenario) == eval_scenario))


def meta_json(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, default=str)


def resolve_log(run_dir: Path, mcap: str) -> Path:
    """A step log named in ``results.parquet``: relative to the run folder, so that a report is the
    same from any working directory (tables that stored working-directory paths still read)."""
    p = Path(mcap)
    if p.is_absolute():
        return p
    inside = run_dir / p
    return inside if inside.exists() or not p.exists() else p
