"""Step logs the harness can trust: published only once they check out, reused only while they do.

A log is *whole* (``check``) when every record of the file reads back in order with its CRC (the
whole data section, chunk by chunk, not just the index at its end), it holds one ``/episode``
summary, and one ``/step`` per step of that summary plus the reset's. ``VerifiedLog`` writes an
episode as ``bench.logs.mcaplog.EpisodeLog`` does (``<name>.part``) and renames it to its final
name only once whole: a log written over by another process (an agent that forked inside ``act``)
or cut short stays a ``.part`` and the episode fails with ``LogDamaged``. ``finished`` is the
summary of a published log that is whole and of the expected agent and scenario, the test for
reusing it instead of running its case again.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ecodrive_bench.bench.logs.mcaplog import EpisodeLog, episode_summary


class LogDamaged(RuntimeError):
    """A step log that did not check out before it was published; one line."""


def check(path: str | Path, steps: int | None = None) -> str:
    """"" when the log at ``path`` is whole (``steps``: the episode's, when known; else its
    summary's), else why not, in a few words."""
    from mcap.records import Channel, DataEnd, Footer, Message

    from ecodrive_bench.bench.logs import bounded, schema

    path = Path(path)
    topics: dict[int, str] = {}
    counts = {"/step": 0, "/episode": 0}
    episode, ended, footer = None, False, False
    try:
        with open(path, "rb") as f:
            for rec in bounded.records(path, f):  # every chunk checked before it is decompressed
                if isinstance(rec, Channel):
                    topics[rec.id] = rec.topic
                elif isinstance(rec, Message):
                    topic = topics.get(rec.channel_id, "")
                    if topic in counts:
                        counts[topic] += 1
                    if topic == "/episode":
                        episode = schema.Episode.FromString(rec.data)
                elif isinstance(rec, DataEnd):
                    ended = True
                elif isinstance(rec, Footer):
                    footer = True
            if not footer:
                return "it ends before its footer"
    except bounded.LogError as e:
        return f"past a reading limit ({e})"
    except Exception as e:  # noqa: BLE001  (the reader's and decoder's errors have no common base)
        return f"unreadable after {counts['/step']} steps ({type(e).__name__})"
    if not ended or counts["/episode"] != 1 or episode is None:
        return f"{counts['/episode']} episode summaries"
    want = episode.steps if steps is None else steps
    if steps is not None and episode.steps != steps:
        return f"its summary says {episode.steps} steps, the episode had {steps}"
    if counts["/step"] != want + 1:  # a record per step, and the reset's
        return f"{counts['/step']} step records for {want} steps"
    return ""


def finished(path: str | Path, agent_sha256: str | None = None, eval_scenario: str | None = None,
             legacy_scenario: str = "") -> dict[str, Any] | None:
    """The ``/episode`` record of a published log that is whole and was written by
    ``agent_sha256`` on ``eval_scenario`` (``bench.logs.mcaplog.episode_summary``), else None:
    the harness then runs the case again."""
    summary = episode_summary(path, agent_sha256=agent_sha256, eval_scenario=eval_scenario,
                              legacy_scenario=legacy_scenario)
    if summary is None or check(path, int(summary["steps"])):
        return None
    return summary


def written_by(path: str | Path) -> str | None:
    """The ``agent_sha256`` a published log records, None for a log that cannot be read."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            meta = next((m.metadata for m in make_reader(f).iter_metadata() if m.name == "ecodrive"), None)
    except Exception:  # noqa: BLE001  (a missing or damaged log records nothing)
        return None
    return None if meta is None else meta.get("agent_sha256", "")


class VerifiedLog(EpisodeLog):
    """An ``EpisodeLog`` published under its final name only once ``check`` passes."""

    def finish(self, summary: dict[str, Any]) -> Path:
        final, self.path = self.path, self.part  # EpisodeLog.finish renames .part to .path: here to itself
        try:
            super().finish(summary)
        finally:
            self.path = final
        why = check(self.part, int(summary["steps"]))
        if why:
            raise LogDamaged(f"its step log did not check out ({why}; was it written by another process too?); "
                             f"it stays {self.part.name}, not published")
        os.replace(self.part, final)
        return final
