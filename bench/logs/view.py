"""Open a step log in Rerun with a blueprint, or save it as an .rrd recording.

    ecodrive view logs/<run>/<signals>/<method>/case-000.mcap [--save out.rrd]

The blueprint puts the drive first: an ego close-up (``/world`` seen from ``/world/ego_frame``, which
follows the ego), the occupancy grid it observes and the time-distance diagram (``/td``), then the
whole corridor, then the time series. The two drive views, and why the close-up is a moving frame
rather than an ego-relative copy of the drawing, are in ``bench/logs/drive.py``.

Entities (timeline ``sim_time``, simulation seconds):
  /world/lanes, /world/stop_lines    static corridor drawing (top-down, metres)
  /world/ego_frame                   a frame at the ego's x, the close-up's origin
  /td/ego, /td/plan, /td/signals/*   the time-distance diagram: position over time, the plan dashed,
                                     red and yellow bands at each stop line the ego reached
  /world/signals                     signal heads coloured by the ego's phase
  /world/ego, /world/neighbours      vehicles as boxes; /world/trail the ego's last 60 s
  /world/plan                        where the plan puts the ego (logs with a plan: oracle, mpc until it re-plans)
  /world/plan_ahead                  mpc: the plan in force over its look-ahead, from each re-plan
  /series/<name>                     speed (and planned speed), requested vs applied acceleration,
                                     energy, reward parts
  /grid                              the occupancy grid as an image
  /events                            lane-change requests and executed changes
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from ecodrive_bench.bench.args import Parser, fail
from ecodrive_bench.bench.io import Unwritable, writable_dir
from ecodrive_bench.bench.logs.drive import ROAD, log_ego_frame, log_time_distance, signal_links, views
from ecodrive_bench.bench.logs.mcaplog import LogData, LogError, read_log

GREEN, RED, YELLOW = (40, 180, 60), (220, 40, 40), (230, 190, 30)
TRAIL_S = 60  # [s] of ego trail
COMPONENTS = ("speed", "jerk", "lane_change", "distance", "energy", "time", "terminal")


def _colour(state: str) -> tuple[int, int, int]:
    return GREEN if state in "gG" else (YELLOW if state in "yY" else RED)


def build_recording(data: LogData, rec) -> tuple[int, str]:
    """Log a step log's content (``read_log``'s, checked there) into ``rec``; returns (steps, warning)."""
    import rerun as rr
    import rerun.blueprint as rrb

    if not data.steps:
        raise LogError(f"{data.path}: the log has no steps to show")
    geo = data.geometry
    steps = data.steps
    lane_y = geo.get("lane_y") or sorted({s.y for s in steps})
    half = geo.get("lane_width", 3.2) / 2
    x_end = max(geo.get("stop_lines") or [max(s.x for s in steps)]) + 200
    rec.log("/world/lanes", rr.LineStrips2D([[[0, y - half], [x_end, y - half]] for y in lane_y] +
                                            [[[0, lane_y[-1] + half], [x_end, lane_y[-1] + half]]],
                                            colors=(150, 150, 150)), static=True)
    stops = geo.get("stop_lines", [])
    rec.log("/world/stop_lines", rr.LineStrips2D([[[x, lane_y[0] - half], [x, lane_y[-1] + half]] for x in stops],
                                                 colors=(255, 255, 255)), static=True)
    links = signal_links(steps)  # the ego's link index at each signal, recovered from the log
    tls_ids = geo.get("tls", sorted(links))
    times = np.array([s.time for s in steps])
    plan = data.plan if data.plan and "time" in data.plan else None  # a trajectory (the clairvoyant's has none)
    plan_x = dict(zip(np.round(plan["time"], 6), plan["x"])) if plan else {}
    replans = {round(r["time"], 6): r for r in (plan or {}).get("replans", [])}  # mpc: the plan in force
    first_replan = min(replans, default=float("inf"))
    trail: list[tuple[float, float]] = []
    for s in steps:
        rec.set_time("sim_time", duration=s.time)
        trail.append((s.x, s.y))
        trail[:] = trail[-TRAIL_S:]
        rec.log("/world/ego", rr.Boxes2D(centers=[[s.x - 2.5, s.y]], sizes=[[5.0, 1.8]], colors=(30, 120, 255),
                                         labels=["ego"]))
        rec.log("/world/trail", rr.LineStrips2D([trail], colors=(30, 120, 255)))
        now = round(s.time, 6)
        if replans.get(now, {}).get("x"):  # the re-planned look-ahead, in force from this step
            ahead = replans[now]["x"]
            rec.log("/world/plan_ahead", rr.Points2D([[x - 2.5, s.y] for x in ahead], colors=(255, 160, 0),
                                                     radii=0.6, labels=[f"re-plan ({replans[now]['event']})"] + [""] * (len(ahead) - 1)))
        if now in plan_x and now < first_replan:
            rec.log("/world/plan", rr.Boxes2D(centers=[[plan_x[round(s.time, 6)] - 2.5, s.y]], sizes=[[5.0, 1.8]],
                                              colors=(255, 160, 0, 120), labels=["plan"]))
        n = len(s.neighbour_x)
        if n:
            lengths = np.array(s.neighbour_length)
            rec.log("/world/neighbours", rr.Boxes2D(
                centers=np.c_[np.array(s.neighbour_x) - lengths / 2, s.neighbour_y],
                sizes=np.c_[lengths, np.full(n, 1.8)], colors=(180, 180, 180)))
        else:
            rec.log("/world/neighbours", rr.Clear(recursive=False))
        if stops and s.tls_states:
            cols = [_colour(st[links[t]]) if t in links else (128, 128, 128) for t, st in zip(tls_ids, s.tls_states)]
            rec.log("/world/signals", rr.Points2D([[x, lane_y[-1] + 2 * half] for x in stops[: len(cols)]],
                                                  colors=cols, radii=2.0))
        grid = np.frombuffer(s.grid, dtype=np.uint8).reshape(s.grid_rows, s.grid_cols)
        rec.log("/grid", rr.Image((grid[::-1] * 255).astype(np.uint8)))  # ahead at the top
        if s.requested_lateral:
            rec.log("/events", rr.TextLog(f"lane change requested: k={s.requested_lateral:+d}",
                                          level="INFO"))
        if s.applied_lateral:
            rec.log("/events", rr.TextLog(f"lane change executed: k={s.applied_lateral:+d}", level="WARN"))
    idx = rr.TimeColumn("sim_time", duration=times)
    cols = {
        "speed": [s.speed for s in steps],
        "requested_accel": [s.requested_accel if s.has_request else np.nan for s in steps],
        "applied_accel": [s.applied_accel for s in steps],
        "energy_step": [s.energy_step for s in steps],
        "energy_total": [s.energy_total for s in steps],
        "reward": [s.reward for s in steps],
    }
    for name, vals in cols.items():
        rec.send_columns(f"/series/{name}", indexes=[idx], columns=rr.Scalars.columns(scalars=np.asarray(vals, float)))
    speed_views = ["/series/speed"]
    if plan:
        rec.send_columns("/series/planned_speed", indexes=[rr.TimeColumn("sim_time", duration=plan["time"])],
                         columns=rr.Scalars.columns(scalars=np.asarray(plan["speed"], float)))
        speed_views.append("/series/planned_speed")
    for c in COMPONENTS:
        vals = np.array([getattr(s.components, c) for s in steps])
        rec.send_columns(f"/series/reward_parts/{c}", indexes=[idx], columns=rr.Scalars.columns(scalars=vals))
    log_ego_frame(rec, steps)
    closeup, td = views(steps, lane_y, half, x_end, log_time_distance(rec, steps, geo, links, plan))
    blueprint = rrb.Blueprint(rrb.Vertical(
        # the grid (cells along the road x lanes, ahead at the top) is tall and narrow: it gets the
        # drive row's height, where a cell is some 15 px at 1600x860, beside the close-up it describes
        rrb.Horizontal(closeup, rrb.Spatial2DView(name="occupancy grid", origin="/grid"), td,
                       column_shares=[3, 1, 2]),
        rrb.Spatial2DView(name="corridor", origin="/world", background=ROAD),
        rrb.Horizontal(
            rrb.TimeSeriesView(name="speed [m/s]", origin="/series", contents=speed_views),
            rrb.TimeSeriesView(name="acceleration [m/s^2]", origin="/series",
                               contents=["/series/requested_accel", "/series/applied_accel"]),
            rrb.TimeSeriesView(name="energy [Wh]", origin="/series",
                               contents=["/series/energy_step", "/series/energy_total"]),
            rrb.TimeSeriesView(name="reward", origin="/series", contents=["/series/reward", "/series/reward_parts/**"]),
            rrb.TextLogView(name="lane decisions", origin="/events"),
        ),
        row_shares=[4, 1, 2],
    ), collapse_panels=True)
    rec.send_blueprint(blueprint)
    return len(steps), data.warning


def has_display() -> bool:
    """Whether a viewer window can open: on Linux an X or Wayland display must be named (without
    one Rerun's viewer fails to start and the recording waits for it); elsewhere assumed."""
    if not sys.platform.startswith("linux"):
        return True
    return any(os.environ.get(k) for k in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET"))


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__)
    ap.add_argument("mcap", type=Path, help="a step log (.mcap, or a killed run's .mcap.part)")
    ap.add_argument("--save", type=Path, default=None,
                    help="write an .rrd (a new path: an existing file is never overwritten) instead of spawning the viewer")
    args = ap.parse_args(argv)
    if args.save is not None and args.save.suffix != ".rrd":
        return fail(ap.prog, f"--save {args.save}: a recording is written as an .rrd file; accepted: a path ending in "
                             f".rrd (e.g. {args.save.with_suffix('.rrd')})")
    import rerun as rr

    try:
        data = read_log(args.mcap)  # read once; a file that is not a step log is refused before a viewer starts
        if args.save:
            if args.save.exists():
                return fail(ap.prog, f"--save {args.save} exists; give a new path (nothing is overwritten)")
            writable_dir(args.save.parent)
    except (LogError, Unwritable) as e:
        return fail(ap.prog, str(e))
    if args.save is None and not has_display():
        return fail(ap.prog, "no display to open the viewer on (DISPLAY and WAYLAND_DISPLAY are unset); write a "
                             "recording instead, --save out.rrd, and open it with `rerun out.rrd` where there is one")
    rec = rr.RecordingStream("ecodrive")
    part = None if args.save is None else args.save.with_name(f".{args.save.name}.part")
    done = False
    try:
        if part is not None:
            part.unlink(missing_ok=True)  # a stale one, or a link planted under its name: never written through
            rec.save(part)  # renamed to --save once complete: no half-written recording under its name
        else:
            rec.spawn()
        n, warning = build_recording(data, rec)
        rec.flush()
        done = True
    except LogError as e:
        return fail(ap.prog, str(e))
    finally:
        rec.disconnect()
        if part is not None and not done:
            part.unlink(missing_ok=True)
    if warning:
        print(f"warning: {warning} (showing the {n} steps read)", file=sys.stderr)
    if part is not None:
        os.replace(part, args.save)
        print(f"saved {n} steps to {args.save}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
