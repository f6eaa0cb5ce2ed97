from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from ecodrive_bench.agents import BaselineAgent
from ecodrive_bench.bench.harness.episode import run_episode
from ecodrive_bench.bench.methods.env import make_env

ENTITIES = ("/world/ego", "/world/neighbours", "/world/signals", "/world/trail", "/grid", "/series/speed",
            "/series/requested_accel", "/series/applied_accel", "/series/energy_total", "/series/reward_parts/speed",
            "/world/ego_frame", "/td/ego")


@pytest.fixture(scope="module")
def log(tmp_path_factory, cases):
    out = tmp_path_factory.mktemp("view")
    agent = BaselineAgent()
    env = make_env(agent, "uncoordinated")
    row = run_episode(env, agent, cases[0], "baseline", log_path=out / "case-000.mcap")
    env.close()
    return out / "case-000.mcap", row


def _view(*args):
    return subprocess.run([sys.executable, "-m", "ecodrive_bench.bench.logs.view", *map(str, args)], capture_output=True, text=True,
                          timeout=300)


def _read_rrd(path):
    import rerun as rr

    srv = rr.server.Server(host="127.0.0.1", datasets={"ds": [str(path)]})
    try:
        client = srv.client()  # keep every handle alive while DataFusion reads
        dataset = client.get_dataset("ds")
        return dataset.reader(index="sim_time").to_pandas()
    finally:
        srv.shutdown()


def test_saved_recording_has_the_entities_and_rows(log, tmp_path):
    mcap, row = log
    out = _view(mcap, "--save", tmp_path / "a.rrd")
    assert out.returncode == 0, out.stderr
    df = _read_rrd(tmp_path / "a.rrd")
    steps = row["steps"] + 1
    for entity in ENTITIES:
        cols = [c for c in df.columns if c.startswith(entity + ":")]
        assert cols, entity
    assert df["/series/speed:Scalars:scalars"].notna().sum() == steps
    assert df["/world/ego:Boxes2D:centers"].notna().sum() == steps
    assert df["/grid:Image:buffer"].notna().sum() == steps
    assert df["/world/ego_frame:Transform3D:translation"].notna().sum() == steps
    assert df["/td/ego:Scalars:scalars"].notna().sum() == steps
    assert df.sim_time.nunique() == steps


def test_truncated_log_gives_a_partial_view_with_a_warning(log, tmp_path):
    data = log[0].read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    out = _view(cut, "--save", tmp_path / "b.rrd")
    assert out.returncode == 0 and "warning:" in out.stderr and "Traceback" not in out.stderr
    df = _read_rrd(tmp_path / "b.rrd")
    assert 0 < df["/series/speed:Scalars:scalars"].notna().sum() < log[1]["steps"]


def test_garbage_is_a_clear_error(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 10)
    out = _view(bad, "--save", tmp_path / "c.rrd")
    assert out.returncode == 2 and "error:" in out.stderr and "bad.mcap" in out.stderr
    assert "Traceback" not in out.stderr


@pytest.mark.parametrize("save, words", [
    ("out.txt", ["--save out.txt: a recording is written as an .rrd file", "accepted: a path ending in .rrd"]),
    ("", ["argument --save: '' is not accepted"]),
])
def test_a_save_path_that_is_no_rrd_is_one_line(save, words, log, tmp_path, monkeypatch, capsys):
    from ecodrive_bench.bench.logs.view import main

    monkeypatch.chdir(tmp_path)
    try:
        rc = main([str(log), "--save", save])
    except SystemExit as e:  # refused by the parser
        rc = e.code
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and all(w in err[0] for w in words), err
    assert not any(tmp_path.iterdir())


@pytest.fixture(scope="module")
def oracle(tmp_path_factory, cases):
    """An oracle episode alone on the corridor (its log carries the plan) and its saved recording."""
    from ecodrive_bench.bench.methods.oracle_agent import OracleAgent

    out = tmp_path_factory.mktemp("oracle")
    env = make_env(OracleAgent, "coordinated", {"arterial_flow": 0.0, "side_flow": 0.0})
    try:
        row = run_episode(env, OracleAgent(env.cfg), cases[0], "oracle", log_path=out / "o.mcap")
    finally:
        env.close()
    done = _view(out / "o.mcap", "--save", out / "o.rrd")
    assert done.returncode == 0, done.stderr
    return out / "o.mcap", row, _read_rrd(out / "o.rrd")


@pytest.fixture(scope="module")
def baseline_rrd_path(log, tmp_path_factory):
    rrd = tmp_path_factory.mktemp("view-rrd") / "base.rrd"
    out = _view(log[0], "--save", rrd)
    assert out.returncode == 0, out.stderr
    return rrd


@pytest.fixture(scope="module")
def baseline_rrd(baseline_rrd_path):
    return _read_rrd(baseline_rrd_path)


def _values(df, entity):
    """sim_time [s] -> the row's scalars (an empty list where the entity was cleared) for rows that have any."""
    col = df[f"{entity}:Scalars:scalars"]
    keep = col.notna()
    return dict(zip(df.sim_time[keep].dt.total_seconds().round(6), (list(v) for v in col[keep])))


def test_a_plan_shows_beside_the_driven_trajectory(oracle):
    """The oracle's log carries its plan: the recording has the planned speed and the ghost."""
    _, row, df = oracle
    assert df["/series/planned_speed:Scalars:scalars"].notna().sum() >= row["steps"]
    assert df["/world/plan:Boxes2D:centers"].notna().sum() >= row["steps"] - 1


def test_the_plan_is_dashed_in_the_time_distance_view_for_the_oracle_only(oracle, baseline_rrd):
    """The oracle's plan is drawn as dashes: position samples on the plan, broken by holes (clears)
    every DASH + GAP seconds over the whole plan; a baseline log has no plan entity at all."""
    from ecodrive_bench.bench.logs.drive import DASH, GAP
    from ecodrive_bench.bench.logs.mcaplog import read_log

    plan = read_log(oracle[0]).plan
    vals = _values(oracle[2], "/td/plan")
    drawn = {t: v[0] for t, v in vals.items() if v}
    holes = sorted(t for t, v in vals.items() if not v)
    span = plan["time"][-1] - plan["time"][0]
    assert len(holes) >= int(span // (DASH + GAP)) - 1 > 5  # a hole every dash, from start to end
    assert min(drawn) == plan["time"][0] and max(drawn) > plan["time"][-1] - (DASH + GAP)
    t = np.array(sorted(drawn))
    np.testing.assert_allclose([drawn[k] for k in t], np.interp(t, plan["time"], plan["x"]), atol=1e-6)
    assert not any(c.startswith("/td/plan") for c in baseline_rrd.columns)
    assert not any(c.startswith("/world/plan") for c in baseline_rrd.columns)


def test_the_closeup_keeps_the_ego_at_its_origin(log, baseline_rrd):
    """The close-up is /world seen from /world/ego_frame: that frame sits at the ego's x at every step,
    so the ego's box is at the same place in it all episode, and the view's bounds are fixed around it."""
    from ecodrive_bench.bench.logs.drive import AHEAD, BEHIND, views
    from ecodrive_bench.bench.logs.mcaplog import read_log

    steps = read_log(log[0]).steps
    df = baseline_rrd
    frame = df["/world/ego_frame:Transform3D:translation"].dropna()
    assert len(frame) == len(steps)
    fx = np.array([v[0][0] for v in frame])
    box = np.array([v[0][0] for v in df["/world/ego:Boxes2D:centers"].dropna()])
    np.testing.assert_allclose(fx, [s.x for s in steps], atol=1e-9)
    np.testing.assert_allclose(box - fx, -2.5, atol=1e-9)  # the box's centre, half a car behind the front
    assert np.ptp(fx) > 1000  # the ego does drive: a frame that stayed at 0 would fail above
    closeup, _ = views(steps, [185.6, 198.4], 1.6, 2400.0, ["/td/ego"])
    bounds = closeup.properties["VisualBounds2D"].range.as_arrow_array().to_pylist()[0]
    assert closeup.origin == "/world/ego_frame" and "/world/**" in closeup.contents
    assert bounds["x_range"] == [-BEHIND, AHEAD] and bounds["y_range"][0] < 185.6 - 1.6


def _red_and_yellow(steps, geo):
    """Independently of the viewer: per signal the ego reached, the times its link showed red / yellow."""
    link = {}
    for s in steps:
        if s.signal.tls:
            link[s.signal.tls] = s.signal.link  # the lane it crossed on
    out = {}
    for j, tls in enumerate(geo["tls"]):
        if tls in link:
            chars = [s.tls_states[j][link[tls]] for s in steps]
            out[tls] = ({round(s.time, 6) for s, c in zip(steps, chars) if c in "rs"},
                        {round(s.time, 6) for s, c in zip(steps, chars) if c in "yY"})
    return out


def test_signal_bands_cover_the_red_and_yellow_the_log_shows(log, baseline_rrd):
    """At each stop line the ego reached, the red band has the stop line's position at exactly the
    steps its link is red in the log's tls_states (yellow likewise), and a hole where each red ends."""
    import json

    from ecodrive_bench.bench.logs.mcaplog import read_log

    data = read_log(log[0])
    geo = json.loads(data.metadata.geometry_json)
    expected = _red_and_yellow(data.steps, geo)
    assert len(expected) == len(geo["tls"])  # the ego crossed every signal
    times = [round(s.time, 6) for s in data.steps]
    for tls, (red, yellow) in expected.items():
        x = geo["stop_lines"][geo["tls"].index(tls)]
        for name, want in (("red", red), ("yellow", yellow)):
            vals = _values(baseline_rrd, f"/td/signals/{tls}/{name}")
            assert {t for t, v in vals.items() if v} == want, (tls, name)
            assert all(v == [x] for v in vals.values() if v)
            ends = {b for a, b in zip(times, times[1:]) if a in want and b not in want}
            assert {t for t, v in vals.items() if not v} == ends, (tls, name)
        assert red and yellow  # the case's signals do cycle: an empty band would not pass vacuously


def test_dashes_alternate_drawn_and_hole():
    from ecodrive_bench.bench.logs.drive import DASH, GAP, PLAN_STEP, dashes

    out = dashes(np.array([0.0, 20.0]), np.array([0.0, 200.0]))
    drawn = [t for t, v in out if v is not None]
    holes = [t for t, v in out if v is None]
    assert holes == pytest.approx(list(np.arange(DASH + PLAN_STEP, 20.0 + 1e-9, DASH + GAP)))  # one per period
    assert all(v == pytest.approx(10 * t) for t, v in out if v is not None)  # on the line
    assert drawn[0] == 0.0 and not any((t % (DASH + GAP)) > DASH + 1e-9 for t in drawn)


def test_an_existing_save_path_is_refused_and_kept(log, tmp_path):
    keep = tmp_path / "keep.rrd"
    keep.write_bytes(b"precious")
    out = _view(log[0], "--save", keep)
    assert out.returncode == 2 and str(keep) in out.stderr and len(out.stderr.strip().splitlines()) == 1
    assert keep.read_bytes() == b"precious"
    folder = tmp_path / "a-folder"
    folder.mkdir()
    out = _view(log[0], "--save", folder)
    assert out.returncode == 2 and "Traceback" not in out.stderr and folder.is_dir()


def test_without_a_display_the_viewer_is_refused_in_one_line(log):
    """On a machine with no display, spawning Rerun's viewer cannot work: one line naming the way
    out (--save), exit 2, at once instead of a wait for a viewer that never starts."""
    import os

    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY", "WAYLAND_SOCKET")}
    out = subprocess.run([sys.executable, "-m", "ecodrive_bench.bench.logs.view", str(log[0])], capture_output=True,
                         text=True, timeout=120, env=env)
    lines = out.stderr.strip().splitlines()
    assert out.returncode == 2 and len(lines) == 1 and "no display" in lines[0] and "--save out.rrd" in lines[0]


def test_a_refused_log_leaves_no_recording(tmp_path):
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(b"\x89MCAP0\r\n" + b"\x00" * 10)
    _view(bad, "--save", tmp_path / "c.rrd")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.mcap"]


# --- the saved recording in Rerun's web viewer under headless Chromium ---------------------------------------------
# Needs Chromium (Debian's ``chromium``; ``$ECODRIVE_BROWSER`` names another binary); without one the test skips,
# unless ``ECODRIVE_REQUIRE_BROWSER=1``, where it fails. The viewer (shipped in rerun-sdk) and the .rrd are served
# from a child process; Chromium is driven over ``--remote-debugging-pipe`` (stdlib only) and screenshotted.
SIZE = (1600, 1000)  # [px] browser window
LOAD_S = 90.0  # [s] for the viewer's wasm to load and draw under a software rasterizer on a busy machine
PLAY_S = 20.0  # [s] of playback (1x, from the episode's start) between the two looks at the close-up
SERVE = """
import functools, http.server, sys, threading, time
import rerun as rr
class H(http.server.SimpleHTTPRequestHandler):
    def end_headers(self):
        self.send_header("Access-Control-Allow-Origin", "*")
        super().end_headers()
    def log_message(self, *a):
        pass
files = http.server.ThreadingHTTPServer(("127.0.0.1", 0), functools.partial(H, directory=sys.argv[1]))
threading.Thread(target=files.serve_forever, daemon=True).start()
rr.serve_web_viewer(web_port=int(sys.argv[2]), open_browser=False)
print(files.server_address[1], flush=True)
time.sleep(3600)
"""


def _chromium() -> str:
    import os
    import shutil

    exe = os.environ.get("ECODRIVE_BROWSER") or next(
        (p for p in map(shutil.which, ("chromium", "chromium-browser", "google-chrome")) if p), None)
    if exe is not None and shutil.which(exe) is None:
        pytest.fail(f"$ECODRIVE_BROWSER={exe!r} is not an executable")
    if exe is None:
        if os.environ.get("ECODRIVE_REQUIRE_BROWSER") == "1":
            pytest.fail(f"ECODRIVE_REQUIRE_BROWSER=1 but no Chromium ({exe!r}): apt-get install chromium")
        pytest.skip("no Chromium (apt-get install chromium, or set $ECODRIVE_BROWSER)")
    return exe


class _Browser:
    """Headless Chromium over the DevTools pipe (fd 3 in, fd 4 out, NUL-separated JSON)."""

    def __init__(self, exe: str, profile) -> None:
        import os

        r_in, self._w = os.pipe()
        self._r, w_out = os.pipe()

        def fds() -> None:
            os.dup2(r_in, 3)
            os.dup2(w_out, 4)

        self.proc = subprocess.Popen(
            [exe, "--headless", "--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
             "--no-first-run", "--disable-background-networking", "--disable-component-update", "--disable-sync",
             "--hide-scrollbars", f"--window-size={SIZE[0]},{SIZE[1]}", f"--user-data-dir={profile}",
             "--remote-debugging-pipe", "about:blank"],
            pass_fds=(3, 4), preexec_fn=fds, start_new_session=True,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        os.close(r_in)
        os.close(w_out)
        self._n, self._buf = 0, b""
        target = self.call("Target.createTarget", url="about:blank")["targetId"]
        self.session = self.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
        self.call("Emulation.setDeviceMetricsOverride", self.session, width=SIZE[0], height=SIZE[1],
                  deviceScaleFactor=1, mobile=False)

    def call(self, method: str, session: str | None = None, **params):
        import json
        import os

        self._n += 1
        msg = {"id": self._n, "method": method, "params": params, **({"sessionId": session} if session else {})}
        os.write(self._w, json.dumps(msg).encode() + b"\0")
        while True:
            while b"\0" not in self._buf:
                chunk = os.read(self._r, 1 << 20)
                if not chunk:
                    raise RuntimeError("chromium closed its DevTools pipe")
                self._buf += chunk
            raw, self._buf = self._buf.split(b"\0", 1)
            reply = json.loads(raw)
            if reply.get("id") == self._n:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]

    def screenshot(self):
        import base64
        import io

        from PIL import Image

        data = base64.b64decode(self.call("Page.captureScreenshot", self.session, format="png")["data"])
        return np.asarray(Image.open(io.BytesIO(data)).convert("RGB")).astype(int)

    def close(self) -> None:
        import os
        import signal

        try:
            self.call("Browser.close")
            self.proc.wait(10)
        except Exception:
            os.killpg(self.proc.pid, signal.SIGKILL)  # our own Chromium's process group, by its id
            self.proc.wait(10)
        os.close(self._w)
        os.close(self._r)


def _near(img, rgb, tol: int = 24):
    return (np.abs(img - np.array(rgb)) <= tol).all(axis=-1)


def _drive_views(img) -> dict:
    """Find the close-up (the road-coloured panel in the top half) and the time-distance view right of it;
    report where the ego is drawn in the close-up and what the time-distance view holds."""
    from ecodrive_bench.bench.logs.drive import AHEAD, BEHIND, EGO, RED, ROAD

    top = img[: img.shape[0] // 2]
    road = _near(top, ROAD, 2)
    if road.sum() < 10000:
        return {"closeup": None}
    ys, xs = np.nonzero(road)
    y0, y1, x0, x1 = ys.min(), ys.max(), xs.min(), xs.max()
    ego = _near(top[y0:y1, x0:x1], EGO, 30)
    td = top[y0:y1, x1 + 20:]
    ex = np.nonzero(ego)[1]
    return {"closeup": (int(x0), int(x1)), "ego_px": int(ego.sum()),
            "ego_front": (ex.max() / (x1 - x0)) if len(ex) else None, "expected_front": BEHIND / (BEHIND + AHEAD),
            "td_ego_px": int(_near(td, EGO, 30).sum()), "td_red_px": int(_near(td, RED, 30).sum())}


def _drawn(r: dict) -> bool:
    return (r["closeup"] is not None and r["ego_px"] > 20 and r["ego_front"] is not None
            and abs(r["ego_front"] - r["expected_front"]) < 0.03 and r["td_ego_px"] > 300 and r["td_red_px"] > 300)


def test_the_recording_draws_the_drive_in_the_web_viewer(baseline_rrd_path, tmp_path):
    """Rerun's own web viewer opens the saved recording and plays it: the close-up is drawn with the ego's
    front at 60/210 of its width, and still there PLAY_S later (the ego has driven some 200 m by then, so a
    close-up that did not follow would have lost it); the time-distance view holds the trajectory and red
    bands. The viewer without a recording must fail the same check."""
    import socket
    import time

    exe = _chromium()
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        web = s.getsockname()[1]
    server = subprocess.Popen([sys.executable, "-c", SERVE, str(baseline_rrd_path.parent), str(web)],
                              stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    browser = None
    try:
        files = int(server.stdout.readline())
        browser = _Browser(exe, tmp_path / "profile")
        viewer = f"http://127.0.0.1:{web}/"
        browser.call("Page.navigate", browser.session, url=viewer)
        time.sleep(15.0)
        empty = _drive_views(browser.screenshot())
        browser.call("Page.navigate", browser.session, url=f"{viewer}?url=http://127.0.0.1:{files}/{baseline_rrd_path.name}")
        end, first = time.monotonic() + LOAD_S, None
        while first is None and time.monotonic() < end:
            time.sleep(2.0)
            shot = browser.screenshot()
            r = _drive_views(shot)
            first = r if _drawn(r) else None
        assert first is not None, f"the drive was not drawn within {LOAD_S:.0f} s: {r}"
        time.sleep(PLAY_S)
        shot2 = browser.screenshot()
        later = _drive_views(shot2)
    finally:
        if browser is not None:
            browser.close()
        server.kill()  # the child started above, by its handle
        server.wait(10)
    assert not _drawn(empty), empty  # the bare viewer does not pass for a drawn drive
    assert _drawn(later), later
    x0, x1 = first["closeup"]
    moved = (np.abs(shot[:SIZE[1] // 2, x0:x1] - shot2[:SIZE[1] // 2, x0:x1]).sum(axis=-1) > 30).sum()
    assert moved > 1000  # playback went on: the neighbours and lanes moved under the ego
    assert abs(first["ego_front"] - later["ego_front"]) * (x1 - x0) <= 2  # [px] while the ego stayed put


def test_mpc_draws_the_plan_in_force_from_each_replan(cases, tmp_path):
    """An mpc episode in traffic: each re-plan's look-ahead is drawn at its step, and the first
    plan's ghost stops where the re-planning starts."""
    from ecodrive_bench.bench.logs.mcaplog import read_log
    from ecodrive_bench.bench.methods.mpc_agent import MPCAgent

    env = make_env(MPCAgent, "uncoordinated", None)
    try:
        run_episode(env, MPCAgent(env.cfg), cases[0], "mpc", log_path=tmp_path / "m.mcap")
    finally:
        env.close()
    replans = read_log(tmp_path / "m.mcap").plan["replans"]
    assert replans, "no re-plan in traffic"
    done = _view(tmp_path / "m.mcap", "--save", tmp_path / "m.rrd")
    assert done.returncode == 0, done.stderr
    df = _read_rrd(tmp_path / "m.rrd")
    drawn = df[df["/world/plan_ahead:Points2D:positions"].notna()].sim_time.dt.total_seconds().round(6)
    assert sorted(drawn) == sorted(round(r["time"], 6) for r in replans)
    ghost = df[df["/world/plan:Boxes2D:centers"].notna()].sim_time.dt.total_seconds()
    assert ghost.max() < replans[0]["time"]
