"""Crafted step logs for the reader's tests: real MCAP files written with the mcap library, either
through its ``Writer`` as ``EpisodeLog`` writes them (valid files whose content is crafted), or
record by record (a chunk that claims 1 GiB, a chunk of thousands of empty records)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
import zstandard
from mcap.data_stream import RecordBuilder
from mcap.records import Chunk, DataEnd, Footer, Header, Metadata
from mcap.well_known import MessageEncoding
from mcap.writer import MCAP0_MAGIC, CompressionType, Writer

from ecodrive_bench.bench.logs import schema
from ecodrive_bench.bench.logs.mcaplog import _SCHEMAS, CHUNK_SIZE, PLAN

TLS = ["J1", "J2", "J3", "J4", "J5"]
STATES = "GGGggrrrrrrrGGGggrrrrrrr"  # 24 links, as the paper's corridor
GEOMETRY = {"junction_x": [440.0, 880.0, 1320.0, 1760.0, 2200.0], "lane_width": 3.2,
            "lane_y": [185.6, 188.8, 192.0, 195.2, 198.4], "stop_lines": [432.8, 872.8, 1312.8, 1752.8, 2192.8],
            "tls": TLS, "v2i_range": 300.0}
META = {"method": "baseline", "signals": "coordinated", "case_index": "0", "agent_sha256": ""}
EMPTY_RECORD = bytes(9)  # opcode 0 (none of mcap's), length 0


def step(i: int, **fields: Any) -> Any:
    """Step ``i`` of a valid drive (1 s steps, 10 m a step), with ``fields`` set on it."""
    s = schema.Step(time=200.0 + i, travel_time=float(i), x=100.0 + 10 * i, y=192.0, speed=10.0,
                    energy_step=1.0, energy_total=float(i), reward=-1.0, lane=2, grid=bytes(300), grid_rows=60,
                    grid_cols=5, tls_states=[STATES] * len(TLS), neighbour_x=[130.0 + 10 * i, 80.0 + 10 * i],
                    neighbour_y=[192.0, 188.8], neighbour_angle=[90.0, 90.0], neighbour_length=[5.0, 5.0])
    tls = TLS[min(i // 10, len(TLS) - 1)]
    s.signal.tls, s.signal.link, s.signal.distance, s.signal.state = tls, 3, 300.0 - 10 * (i % 10), "G"
    for k, v in fields.items():
        if isinstance(getattr(s, k), (str, bytes, int, float)):
            setattr(s, k, v)
        else:  # a repeated field
            del getattr(s, k)[:]
            getattr(s, k).extend(v)
    return s


def plan(n: int = 30) -> dict[str, Any]:
    return {"time": [200.0 + i for i in range(n)], "x": [100.0 + 10 * i for i in range(n)], "speed": [10.0] * n,
            "travel_time": float(n), "energy": 40.0}


def write_log(path: Path, steps: list[Any] | None = None, geometry: Any = GEOMETRY, plan_json: str | None = None,
              meta: dict[str, str] | None = None) -> Path:
    """A finished step log as ``EpisodeLog`` writes one: ``/meta`` (its ``geometry_json``: the JSON
    of ``geometry``, or the text itself when it is a string), the steps (30 valid ones by default),
    the ``plan`` metadata record (``plan_json``, as is) and the ``/episode`` summary."""
    steps = [step(i) for i in range(30)] if steps is None else steps
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "wb") as f:
        w = Writer(f, chunk_size=CHUNK_SIZE, compression=CompressionType.ZSTD)
        w.start(profile="", library="ecodrive-bench")
        ch = {t: w.register_channel(topic=t, message_encoding=MessageEncoding.Protobuf,
                                    schema_id=w.register_schema(name=name, encoding="protobuf", data=data))
              for t, (name, data) in _SCHEMAS.items()}
        w.add_metadata("ecodrive", {**META, **(meta or {})})
        geo = geometry if isinstance(geometry, str) else json.dumps(geometry)
        w.add_message(channel_id=ch["/meta"], log_time=0, publish_time=0,
                      data=schema.Metadata(method="baseline", signals="coordinated", geometry_json=geo).SerializeToString())
        for s in steps:
            t = int(s.time * 1e9) if 0 <= s.time < 1e9 else 0  # a log time is unsigned; the step's own time as drawn
            w.add_message(channel_id=ch["/step"], log_time=t, publish_time=t, data=s.SerializeToString())
        if plan_json is not None:
            w.add_metadata(PLAN, {"json": plan_json})
        w.add_message(channel_id=ch["/episode"], log_time=0, publish_time=0,
                      data=schema.Episode(method="baseline", energy=30.0, travel_time=float(len(steps)),
                                          steps=len(steps), terminated=True).SerializeToString())
        w.finish()
    return path


def write_chunks(path: Path, chunks: list[tuple[bytes, int]], compression: str = "zstd") -> Path:
    """An MCAP file of a header, the ``ecodrive`` metadata record, the given chunks ((data as
    stored, the uncompressed size it claims)), data end and footer, written record by record."""
    b = RecordBuilder()
    b.write(MCAP0_MAGIC)
    Header(profile="", library="ecodrive-bench").write(b)
    Metadata(name="ecodrive", metadata=META).write(b)
    for data, claimed in chunks:
        Chunk(compression=compression, data=data, message_start_time=0, message_end_time=0, uncompressed_crc=0,
              uncompressed_size=claimed).write(b)
    DataEnd(data_section_crc=0).write(b)
    Footer(summary_start=0, summary_offset_start=0, summary_crc=0).write(b)
    b.write(MCAP0_MAGIC)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b.end())
    return path


def zstd_of_zeros(size: int) -> bytes:
    """A real zstd frame of ``size`` zero bytes (the size in its header), compressed 1 MiB at a time."""
    c = zstandard.ZstdCompressor(level=3).compressobj(size=size)
    block = bytes(min(size, 2**20))
    parts = [c.compress(block[: min(len(block), size - i)]) for i in range(0, size, len(block))]
    return b"".join([*parts, c.flush()])


def empty_records(n: int) -> tuple[bytes, int]:
    """A zstd chunk's data of ``n`` empty 9-byte records, and its size."""
    raw = EMPTY_RECORD * n
    return zstandard.ZstdCompressor().compress(raw), len(raw)


@pytest.fixture
def no_decompression(monkeypatch):
    """Any zstd decompression in this process fails the test (mcap's readers and ours both go
    through these)."""
    def refuse(*args, **kwargs):
        raise AssertionError("a chunk was decompressed")

    for name in ("decompress", "ZstdDecompressor"):
        monkeypatch.setattr(zstandard, name, refuse)


@pytest.fixture(scope="session")
def bomb(tmp_path_factory) -> Path:
    """A 33 KB step log whose one zstd chunk claims (and holds) 1 GiB of zeros."""
    return write_chunks(tmp_path_factory.mktemp("bomb") / "case-000.mcap", [(zstd_of_zeros(2**30), 2**30)])


class Craft:
    """The helpers above, for the tests (a conftest is not imported by name)."""

    TLS, STATES, GEOMETRY, EMPTY_RECORD = TLS, STATES, GEOMETRY, EMPTY_RECORD
    step, plan, write_log, write_chunks = staticmethod(step), staticmethod(plan), staticmethod(write_log), \
        staticmethod(write_chunks)
    zstd_of_zeros, empty_records = staticmethod(zstd_of_zeros), staticmethod(empty_records)


@pytest.fixture(scope="session")
def craft() -> type[Craft]:
    return Craft
