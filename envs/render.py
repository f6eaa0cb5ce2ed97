"""Rendering of ``EcoDrive-v0`` (gymnasium's ``render_mode``): an ego close-up as an RGB frame, and
the same frame with the ego's speed, energy and reward streamed live to a Rerun viewer.

The close-up is drawn in numpy, top-down, in the ego's frame: the ego's front bumper sits at a
fixed column, from ``BEHIND`` metres behind it to ``AHEAD`` metres ahead, every lane of the
arterial, the vehicles in that window (from SUMO), the stop lines, and the head of the ego's
next signal in its state's colour. A frame is a few filled rectangles, so numpy slicing is all it
takes (about 2 ms a frame, most of it SUMO's position queries; matplotlib would cost tens of
milliseconds). Rerun is imported only for ``render_mode="rerun"`` and ``"human"``.
"""
from __future__ import annotations

from typing import Any

import numpy as np

BEHIND = 60.0  # [m] shown behind the ego's front bumper
AHEAD = 150.0  # [m] shown ahead of it
PX_X = 4.0  # [px/m] along the road
PX_Y = 10.0  # [px/m] across it
LANE_WIDTH = 3.2  # [m] SUMO's default lane width
MARGIN = 2.0  # [m] of verge above and below the lanes
VEHICLE_WIDTH = 1.8  # [m]
DASH_LENGTH, DASH_PERIOD = 3.0, 9.0  # [m] lane markings: 3 m of paint every 9 m
COLOURS = {  # RGB
    "verge": (40, 90, 40), "road": (70, 70, 70), "marking": (230, 230, 230), "ego": (30, 120, 255),
    "other": (200, 200, 200), "green": (40, 200, 60), "yellow": (250, 200, 0), "red": (230, 40, 40),
    "off": (120, 120, 120),
}
RENDER_MODES = ("human", "rgb_array", "rerun")


def _state_colour(state: str) -> tuple[int, int, int]:
    if state in "gG":
        return COLOURS["green"]
    if state in "yY":
        return COLOURS["yellow"]
    if state in "rRu":
        return COLOURS["red"]
    return COLOURS["off"]


class CloseUp:
    """Draws the ego close-up of one env's corridor (``lane_y``: lane centres, index 0 rightmost)."""

    def __init__(self, lane_y: tuple[float, ...], stop_lines: tuple[float, ...], vehicle_length: float) -> None:
        self.lane_y, self.stop_lines, self.vehicle_length = tuple(lane_y), tuple(stop_lines), vehicle_length
        self.y_top = max(lane_y) + LANE_WIDTH / 2 + MARGIN  # [m] the frame's first row
        self.y_bottom = min(lane_y) - LANE_WIDTH / 2 - MARGIN
        self.shape = (int(round((self.y_top - self.y_bottom) * PX_Y)), int(round((BEHIND + AHEAD) * PX_X)), 3)

    def _cols(self, x0: float, x1: float, ego_x: float) -> tuple[int, int]:
        a = int(np.floor((x0 - ego_x + BEHIND) * PX_X))
        b = int(np.ceil((x1 - ego_x + BEHIND) * PX_X))
        return max(a, 0), min(b, self.shape[1])

    def _rows(self, y0: float, y1: float) -> tuple[int, int]:
        a = int(np.floor((self.y_top - y1) * PX_Y))
        b = int(np.ceil((self.y_top - y0) * PX_Y))
        return max(a, 0), min(b, self.shape[0])

    def _box(self, img: np.ndarray, x0: float, x1: float, y0: float, y1: float, ego_x: float, colour) -> None:
        (c0, c1), (r0, r1) = self._cols(x0, x1, ego_x), self._rows(y0, y1)
        if c0 < c1 and r0 < r1:
            img[r0:r1, c0:c1] = colour

    def frame(self, ego: tuple[float, float], others: list[tuple[float, float]],
              signal: tuple[float, str] | None) -> np.ndarray:
        """The frame: ``ego`` and ``others`` as (front bumper x, y) [m]; ``signal``: the ego's next
        stop line x [m] and its state character, or None."""
        ego_x, ego_y = ego
        img = np.empty(self.shape, dtype=np.uint8)
        img[:] = COLOURS["verge"]
        half = LANE_WIDTH / 2
        lo, hi = min(self.lane_y) - half, max(self.lane_y) + half
        self._box(img, ego_x - BEHIND, ego_x + AHEAD, lo, hi, ego_x, COLOURS["road"])
        world_x = ego_x - BEHIND + (np.arange(self.shape[1]) + 0.5) / PX_X
        dashes = np.mod(world_x, DASH_PERIOD) < DASH_LENGTH  # markings fixed to the road, not to the ego
        for y in sorted(self.lane_y)[:-1]:  # dashed markings between lanes
            r0, r1 = self._rows(y + half - 0.08, y + half + 0.08)
            img[r0:r1, dashes] = COLOURS["marking"]
        for x in self.stop_lines:
            if ego_x - BEHIND <= x <= ego_x + AHEAD:
                self._box(img, x - 0.4, x, lo, hi, ego_x, COLOURS["marking"])
        if signal is not None:
            x, state = signal
            self._box(img, x - 1.5, x + 1.5, hi + 0.3, hi + 1.8, ego_x, _state_colour(state))
        w = VEHICLE_WIDTH / 2
        for x, y in others:
            self._box(img, x - self.vehicle_length, x, y - w, y + w, ego_x, COLOURS["other"])
        self._box(img, ego_x - self.vehicle_length, ego_x, ego_y - w, ego_y + w, ego_x, COLOURS["ego"])
        return img


class RerunStream:
    """``render_mode="rerun"`` (and ``"human"``): every step's close-up, speed, energy and reward
    streamed to a Rerun viewer on the simulation's clock. ``target``: ``"spawn"`` (start a viewer),
    ``"connect"`` or ``"connect:URL"`` (a running viewer, e.g. ``rerun+http://127.0.0.1:9876/proxy``),
    or a path ending in ``.rrd`` (a recording file)."""

    def __init__(self, target: str = "spawn") -> None:
        import rerun as rr

        self.rr = rr
        self.rec = rr.RecordingStream("ecodrive-live")
        if target == "spawn":
            self.rec.spawn()
        elif target == "connect" or target.startswith("connect:"):
            url = target.partition(":")[2]
            self.rec.connect_grpc(url) if url else self.rec.connect_grpc()
        elif target.endswith(".rrd"):
            self.rec.save(target)
        else:
            raise ValueError(f"rerun target {target!r} is not accepted; give spawn, connect[:URL] or a path.rrd")
        self.episode = -1

    def log(self, time: float, frame: np.ndarray, scalars: dict[str, float], new_episode: bool) -> None:
        rr, rec = self.rr, self.rec
        if new_episode:
            self.episode += 1
        rec.set_time("episode", sequence=self.episode)
        rec.set_time("sim_time", duration=time)
        rec.log("/closeup", rr.Image(frame))
        for name, value in scalars.items():
            rec.log(f"/series/{name}", rr.Scalars(float(value)))

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()


def check_mode(render_mode: str | None) -> None:
    if render_mode is not None and render_mode not in RENDER_MODES:
        raise ValueError(f"render_mode={render_mode!r} is not accepted; choose one of {', '.join(RENDER_MODES)} "
                         f"(or None)")


def others_in_view(session: Any, ego_id: str, ego_x: float, y_range: tuple[float, float]) -> list[tuple[float, float]]:
    """(x, y) of the vehicles other than the ego inside the close-up (read from SUMO)."""
    out = []
    for vid in session.vehicle_ids():
        if vid == ego_id:
            continue
        x, y = session.position(vid)
        if ego_x - BEHIND - 20.0 <= x <= ego_x + AHEAD + 20.0 and y_range[0] <= y <= y_range[1]:
            out.append((x, y))
    return out
