"""Reading an MCAP file at a bounded cost: what a crafted step log may take is limited before it is paid.

mcap's own readers decompress a chunk into a buffer of the size the chunk claims (a 33 KB file can
claim 1 GiB), parse however many records a chunk holds (a 2 KB chunk can hold millions of empty
9-byte records) and read a record of whatever length its header states. Here a file is read once,
record by record with mcap's record classes (chunks left compressed, indexes passed over unread,
never past the file's end), and each chunk is checked before it is decompressed. The limits follow
from what the writer (``bench.logs.mcaplog``) writes:

- ``MAX_CHUNK_BYTES`` (1 MiB): the uncompressed size a chunk may claim. The writer's chunk size,
  ``mcaplog.CHUNK_SIZE``, is 64 KiB (as it has been since the first step log); mcap closes a chunk
  once it passes that size, so a chunk is 64 KiB plus at most one record (a step is 0.5-2 KB; the
  first chunk also holds the schemas, a few KB each). The largest of 1,668 logs on hand: 67,098
  bytes. 16 times the chunk size leaves room for any step and bounds one chunk's memory to 1 MiB;
  decompression never writes more than the size claimed (a chunk that decompresses to more or
  less is corrupt).
- ``MAX_CHUNK_RECORDS`` (4,096): records in one chunk. A message record is at least 31 bytes, so a
  chunk of the writer holds at most (64 KiB + one record) / 31, about 2,200 records.
- ``MAX_LOG_RECORDS``: records in a whole file, chunks' records included: twice ``MAX_STEPS``, the
  steps of the longest episode the env allows (``max_episode_time`` at most 7,200 s, ``step_length``
  above 0.05 s: 144,000 steps and the reset's). The other half is room for the chunk, index and
  summary records around them (about 3 per chunk of some 130 steps) and the other channels; the
  longest training's ``/train`` log (100,000 episodes) and a mixed-traffic cell's vehicles fit too.
- ``MAX_LOG_BYTES`` (512 MiB): all chunks' uncompressed bytes together: the longest episode's
  steps at 2 KB each (a step with a full neighbourhood; 0.5 KB is usual) are 288 MB. So a file of
  many small chunks that each decompress to 1 MiB costs at most about a second of decompression.
- ``MAX_RECORD_BYTES`` (64 MiB): one record as stored. The largest the writer makes is the
  ``plan`` metadata of an mpc episode (its first plan and every re-plan's look-ahead), about
  300 bytes a step: 45 MB for the longest episode.

Past a limit the file is refused: ``LogError``, one line naming the file, the record and the
limit. The compressions read are the writer's ``zstd`` and none; another (``lz4``) is refused.
"""
from __future__ import annotations

import io
import math
import os
import struct
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, DataEnd, Footer, Header, McapRecord, Message, Metadata, Schema
from mcap.stream_reader import CRCValidationError, read_magic

from ecodrive_bench.envs.config import ScenarioConfig, accepted_range

CHUNK_BYTES_WRITTEN = 64 * 1024  # [bytes] the writer's chunk size (mcaplog.CHUNK_SIZE; a test keeps them equal)
MAX_CHUNK_BYTES = 16 * CHUNK_BYTES_WRITTEN  # [bytes] uncompressed size a chunk may claim
MIN_MESSAGE_RECORD = 31  # [bytes] opcode, length, channel, sequence, two times: a message with no data
MAX_CHUNK_RECORDS = 4096  # [-] records in one chunk (the writer's hold at most ~2,200)
LONGEST_EPISODE_S = float(accepted_range(ScenarioConfig, "max_episode_time")[1] or 0.0)  # [s] 7,200
SHORTEST_STEP_S = float(accepted_range(ScenarioConfig, "step_length")[0] or 0.0)  # [s] 0.05 (excluded)
MAX_STEPS = math.ceil(LONGEST_EPISODE_S / SHORTEST_STEP_S) + 1  # [-] the longest episode's steps and the reset's
MAX_LOG_RECORDS = 2 * MAX_STEPS  # [-] records in one file
MAX_LOG_BYTES = 512 * 2**20  # [bytes] uncompressed bytes of all chunks of one file
MAX_RECORD_BYTES = 64 * 2**20  # [bytes] one record as stored
COMPRESSIONS = ("zstd", "")
_OPENING = struct.Struct("<BQ")  # a record's opcode and length
_MESSAGE = struct.Struct("<HIQQ")  # a message's channel, sequence, log time and publish time


class LogError(RuntimeError):
    """A step log that cannot be read at all, or that says what no log of the writer says; the
    message (one line) names the file and the cause."""


class _Clamped(io.RawIOBase):
    """A file read no further than its end: a record that claims more than the file holds gets
    what is left (and the next read finds the end of the file), so no read allocates more than
    the file's size."""

    def __init__(self, f: IO[bytes], size: int) -> None:
        super().__init__()
        self._f, self._left = f, size

    def readable(self) -> bool:
        return True

    def read(self, n: int = -1) -> bytes:
        n = self._left if n is None or n < 0 else min(n, self._left)
        data = self._f.read(n)
        self._left -= len(data)
        return data

    def readinto(self, b: Any) -> int:
        data = self.read(len(b))
        b[: len(data)] = data
        return len(data)


class Budget:
    """What one file may still cost: records and uncompressed bytes."""

    def __init__(self, path: Path) -> None:
        self.path, self.records, self.bytes = path, 0, 0

    def record(self) -> None:
        self.records += 1
        if self.records > MAX_LOG_RECORDS:
            raise LogError(f"{self.path}: more than {MAX_LOG_RECORDS} records; a step log holds at most "
                           f"{MAX_LOG_RECORDS} (twice the {MAX_STEPS} steps of the longest episode); refused")


# the records read outside chunks; the others (indexes, statistics, attachments) are passed over unread
_READ = {Opcode.HEADER: Header.read, Opcode.FOOTER: Footer.read, Opcode.DATA_END: DataEnd.read,
         Opcode.CHUNK: Chunk.read, Opcode.CHANNEL: Channel.read, Opcode.SCHEMA: Schema.read,
         Opcode.METADATA: Metadata.read}


def records(path: Path, f: IO[bytes], expand: bool = True, budget: Budget | None = None) -> Iterator[McapRecord]:
    """The records of the MCAP file ``f`` (at ``path``) that a step log's readers use, in order: a
    chunk's records in its place (``expand``) or the chunk itself, never decompressed (not
    ``expand``; ``chunk_records`` with the same ``budget`` expands one). The data section's CRC is
    checked at its end. Raises ``LogError`` past a limit, mcap's errors (``McapError``,
    ``ValueError``, ``struct.error``) where the file is corrupt, ends early or goes on past its
    closing magic."""
    size = os.fstat(f.fileno()).st_size - f.tell()
    budget = budget or Budget(path)
    stream = ReadDataStream(io.BufferedReader(_Clamped(f, size)), calculate_crc=True)
    read_magic(stream)
    while True:
        crc = stream.checksum()
        opcode, length = stream.read1(), stream.read8()
        budget.record()
        if length > MAX_RECORD_BYTES:
            raise LogError(f"{path}: a record (opcode {opcode:#04x}) of {length} bytes; a step log's records are at "
                           f"most {MAX_RECORD_BYTES} bytes; refused")
        start = stream.count
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE.size:
                raise McapError(f"a message record of {length} bytes, short of its fields")
            rec = Message.read(stream, length)
        elif opcode in _READ:
            rec = _READ[opcode](stream)
        else:
            stream.read(length)
            continue
        rest = length - (stream.count - start)
        if rest < 0:
            raise McapError(f"a record (opcode {opcode:#04x}) is longer than the {length} bytes it claims")
        stream.read(rest)
        if isinstance(rec, DataEnd) and rec.data_section_crc and rec.data_section_crc != crc:
            raise CRCValidationError(rec.data_section_crc, crc, rec)
        if isinstance(rec, Chunk) and expand:
            yield from chunk_records(path, rec, budget)
        else:
            yield rec
        if isinstance(rec, Footer):
            read_magic(stream)
            if stream.count != size:  # the writer ends a file with its closing magic
                raise McapError(f"{size - stream.count} bytes after the closing magic")
            return


def chunk_records(path: Path, chunk: Chunk, budget: Budget) -> list[McapRecord]:
    """The schema, channel and message records of ``chunk``, checked before it is decompressed."""
    claimed = chunk.uncompressed_size
    if chunk.compression not in COMPRESSIONS:
        raise LogError(f"{path}: a chunk compressed with {chunk.compression!r}; step logs are written with "
                       f"zstd (accepted: {', '.join(repr(c) for c in COMPRESSIONS)}); refused")
    if claimed > MAX_CHUNK_BYTES:
        raise LogError(f"{path}: a chunk claims {claimed} bytes uncompressed; accepted: at most {MAX_CHUNK_BYTES} "
                       f"(the writer's chunks are {CHUNK_BYTES_WRITTEN} bytes and one record); refused before it is "
                       "decompressed")
    budget.bytes += claimed
    if budget.bytes > MAX_LOG_BYTES:
        raise LogError(f"{path}: its chunks claim more than {MAX_LOG_BYTES} bytes uncompressed in all; accepted: at "
                       f"most {MAX_LOG_BYTES}; refused")
    data = _decompress(chunk) if chunk.compression else chunk.data
    if len(data) != claimed:
        raise McapError(f"a chunk decompresses to {len(data)}{'+' if len(data) > claimed else ''} bytes, not the "
                        f"{claimed} it claims")
    if chunk.uncompressed_crc and zlib.crc32(data) != chunk.uncompressed_crc:
        raise CRCValidationError(chunk.uncompressed_crc, zlib.crc32(data), chunk)
    out: list[McapRecord] = []
    at, n, view = 0, 0, memoryview(data)
    while at < claimed:
        n += 1
        if n > MAX_CHUNK_RECORDS:
            raise LogError(f"{path}: a chunk holds more than {MAX_CHUNK_RECORDS} records; accepted: at most "
                           f"{MAX_CHUNK_RECORDS} (the writer's hold about {CHUNK_BYTES_WRITTEN // MIN_MESSAGE_RECORD}); "
                           "refused")
        budget.record()
        opcode, length = _OPENING.unpack_from(view, at)  # struct.error where the chunk ends inside it
        at += _OPENING.size
        end = at + length
        if end > claimed:
            raise McapError(f"a record in a chunk claims {length} bytes, past the chunk's end")
        if opcode == Opcode.MESSAGE:
            if length < _MESSAGE.size:
                raise McapError(f"a message record of {length} bytes, short of its fields")
            channel, sequence, log_time, publish_time = _MESSAGE.unpack_from(view, at)
            out.append(Message(channel_id=channel, log_time=log_time, data=data[at + _MESSAGE.size:end],
                               publish_time=publish_time, sequence=sequence))
        elif opcode in (Opcode.CHANNEL, Opcode.SCHEMA):
            out.append((Channel if opcode == Opcode.CHANNEL else Schema).read(ReadDataStream(io.BytesIO(data[at:end]))))
        at = end  # past fields a later MCAP version may add
    return out


def _decompress(chunk: Chunk) -> bytes:
    """A zstd chunk's data, at most one byte more than it claims (so that more is seen)."""
    import zstandard

    want = chunk.uncompressed_size + 1
    parts, got = [], 0
    try:
        with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(chunk.data)) as r:
            while got < want:
                part = r.read(want - got)
                if not part:
                    break
                parts.append(part)
                got += len(part)
    except zstandard.ZstdError as e:
        raise McapError(f"a chunk's zstd data is corrupt ({e})") from None
    return b"".join(parts)
