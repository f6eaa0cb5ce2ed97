"""The drive views of ``ecodrive view``: an ego close-up that follows the ego, and the time-distance
diagram of the episode (the figure of eco-driving papers). Reads a step log's content only.

Entities (timeline ``sim_time``):
  /world/ego_frame                   a Transform3D per step, translation (ego x, 0): the close-up's origin
  /td/ego                            the ego's position x [m] at each step (time-distance view)
  /td/plan                           the plan's position, dashed (logs with a plan: the oracle)
  /td/signals/<tls>/red, .../yellow  the stop line's position while the ego's link shows red or yellow

**The close-up is a view of ``/world`` from ``/world/ego_frame``**, not a second, ego-relative copy of
the drawing. Rerun resolves every entity into the coordinate frame of a view's origin, walking *up*
the entity tree through the inverse of each transform as well as down (the "Spaces and Transforms"
concept page; ``re_view_spatial``'s transform context computes both directions), and a view's
``VisualBounds2D`` are in the origin's frame. So with the origin at ``/world/ego_frame``, translated
by the ego's x at every step, the lanes, stop lines, signal heads, neighbours and the ego are drawn at
``x - ego_x`` and the fixed bounds ``[-BEHIND, AHEAD]`` follow the ego: the ego stays put while the
corridor scrolls under it. Checked in rerun 0.41's web viewer under headless Chromium: recordings
of one baseline episode cut at t = 306 s and t = 406 s put the ego's box at the same pixels of the
close-up (x 250-274 of a 958 px panel: its front at 60/210 of the width), with other neighbours and
stop lines around it. The alternative, logging every entity a second time relative to the ego
(``x - ego_x``), was not needed: it would cost a second copy of the neighbours, stop lines and
signal heads per step and two drawings kept in step by hand; the transform is one row per step.
One flaw seen there: the viewer places a box's *label* at its untransformed x (the "ego" label drifts
right as the ego drives while its box stays), so the close-up hides the ego's and the plan's labels.

**The time-distance diagram is a TimeSeriesView**, not a 2D view: it has the axes with ticks in
seconds and metres that a 2D view lacks, y pointing up, and the viewer's time cursor drawn across it
at the current time. Signal bands are thick lines at each stop line's position while the ego's link
there is red or yellow, broken by ``Clear`` (scalar plots draw a clear as a hole); the plan is dashed
the same way, ``DASH`` s drawn then ``GAP`` s left out (Rerun has no dash style).
Its time axis spans the episode. A signal has bands only if the ego reached its approach (the log
names the ego's link there; a truncated log may stop before the last signals).
"""
from __future__ import annotations

from typing import Any

import numpy as np

BEHIND = 60.0  # [m] close-up: visible behind the ego's front
AHEAD = 150.0  # [m] close-up: visible ahead of the ego's front
SIDE = 6.0  # [m] close-up: visible beyond the outer lane edges
DASH, GAP = 2.0, 1.5  # [s] the plan's dashes and the holes between them
PLAN_STEP = 0.5  # [s] sampling of the dashed plan
BAND_WIDTH = 7.0  # [px] signal band thickness
RED, YELLOW = (220, 40, 40), (230, 190, 30)
EGO, PLAN = (30, 120, 255), (255, 140, 0)
ROAD = (45, 45, 50)  # 2D view background: the white stop lines stay visible under a light theme


def signal_links(steps: list[Any]) -> dict[str, int]:
    """The ego's link index at each signal it approached: the last one logged (the lane it crossed on)."""
    links: dict[str, int] = {}
    for s in steps:
        if s.signal.tls:
            links[s.signal.tls] = s.signal.link
    return links


def phases(steps: list[Any], tls_ids: list[str], links: dict[str, int]) -> dict[str, np.ndarray]:
    """Per signal the ego approached, its state character ('r', 'y' or 'g') at each step."""
    out: dict[str, np.ndarray] = {}
    for j, tls in enumerate(tls_ids):
        if tls not in links:
            continue
        chars = []
        for s in steps:
            st = s.tls_states[j][links[tls]] if j < len(s.tls_states) else "?"
            chars.append("r" if st in "rs" else "y" if st in "yY" else "g" if st in "gG" else "?")
        out[tls] = np.array(chars)
    return out


def dashes(times: np.ndarray, values: np.ndarray) -> list[tuple[float, float | None]]:
    """``(time, value)`` samples of a dashed line every ``PLAN_STEP`` s; ``None`` where a hole starts."""
    t = np.arange(times[0], times[-1] + 1e-9, PLAN_STEP)
    v = np.interp(t, times, values)
    phase = np.mod(t - times[0], DASH + GAP)
    out: list[tuple[float, float | None]] = []
    for ti, vi, ph in zip(t, v, phase):
        if ph < DASH + 1e-9:
            out.append((float(ti), float(vi)))
        elif out and out[-1][1] is not None:
            out.append((float(ti), None))
    return out


def log_time_distance(rec: Any, steps: list[Any], geo: dict, links: dict[str, int],
                      plan: dict | None) -> list[str]:
    """Log the time-distance diagram; returns its entity paths."""
    import rerun as rr

    times = np.array([s.time for s in steps])
    rec.log("/td/ego", rr.SeriesLines(colors=EGO, widths=2.5, names="ego"), static=True)
    rec.send_columns("/td/ego", indexes=[rr.TimeColumn("sim_time", duration=times)],
                     columns=rr.Scalars.columns(scalars=np.array([s.x for s in steps], float)))
    paths = ["/td/ego"]
    stops = geo.get("stop_lines", [])
    tls_ids = geo.get("tls", sorted(links))
    for tls, chars in phases(steps, tls_ids, links).items():
        x = stops[tls_ids.index(tls)] if tls_ids.index(tls) < len(stops) else None
        if x is None:
            continue
        for name, state, colour in (("red", "r", RED), ("yellow", "y", YELLOW)):
            on = chars == state
            if not on.any():
                continue
            path = f"/td/signals/{tls}/{name}"
            rec.log(path, rr.SeriesLines(colors=colour, widths=BAND_WIDTH, names=f"{tls} {name}"), static=True)
            for i, t in enumerate(times):
                if on[i] or (i and on[i - 1]):
                    rec.set_time("sim_time", duration=t)
                    rec.log(path, rr.Scalars(x) if on[i] else rr.Clear(recursive=False))
            paths.append(path)
    if plan:
        rec.log("/td/plan", rr.SeriesLines(colors=PLAN, widths=2.0, names="plan"), static=True)
        for t, v in dashes(np.asarray(plan["time"], float), np.asarray(plan["x"], float)):
            rec.set_time("sim_time", duration=t)
            rec.log("/td/plan", rr.Scalars(v) if v is not None else rr.Clear(recursive=False))
        paths.append("/td/plan")
    return paths


def log_ego_frame(rec: Any, steps: list[Any]) -> None:
    """The close-up's origin: translated by the ego's x at every step (lateral moves stay visible)."""
    import rerun as rr

    times = np.array([s.time for s in steps])
    rec.send_columns("/world/ego_frame", indexes=[rr.TimeColumn("sim_time", duration=times)],
                     columns=rr.Transform3D.columns(translation=[[s.x, 0.0, 0.0] for s in steps]))


def views(steps: list[Any], lane_y: list[float], half: float, x_end: float, td_paths: list[str]) -> tuple[Any, Any]:
    """The close-up and time-distance views for the blueprint."""
    import rerun as rr
    import rerun.blueprint as rrb
    from rerun.encodings import TimeRange

    episode = TimeRange(start=rrb.TimeRangeBoundary.absolute(seconds=steps[0].time),
                        end=rrb.TimeRangeBoundary.absolute(seconds=steps[-1].time))

    no_label = rr.Boxes2D.from_fields(show_labels=False)  # rerun 0.41 leaves labels at the untransformed x
    closeup = rrb.Spatial2DView(
        name=f"ego close-up ({BEHIND:.0f} m behind, {AHEAD:.0f} m ahead)", origin="/world/ego_frame",
        contents=["/world/**", "- /world/trail"], background=ROAD,
        overrides={"/world/ego": no_label, "/world/plan": no_label},
        visual_bounds=rrb.VisualBounds2D(x_range=[-BEHIND, AHEAD],
                                         y_range=[lane_y[0] - half - SIDE, lane_y[-1] + half + SIDE]))
    td = rrb.TimeSeriesView(
        name="time-distance [m over s]: ego blue, plan orange dashes, red/yellow signals", origin="/td", contents=td_paths,
        axis_x=rrb.TimeAxis(view_range=episode), axis_y=rrb.ScalarAxis(range=[0.0, x_end]),
        plot_legend=rrb.PlotLegend(visible=False))
    return closeup, td
