"""gymnasium render modes of ``EcoDrive-v0`` and the scenario's ``max_episode_steps``."""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)
from ecodrive_bench.envs.render import BEHIND, COLOURS, PX_X, PX_Y

CASE = {"sumo_seed": 7, "insert_time": 210.0}
ACTION = (1, np.array([0.0, 1.0, 0.0], dtype=np.float32))


def test_max_episode_steps_comes_from_the_scenario():
    assert gym.make("EcoDrive-v0").spec.max_episode_steps == 900
    env = gym.make("EcoDrive-v0", config={"max_episode_time": 300.0, "step_length": 0.5})
    assert env.spec.max_episode_steps == 600 and env.unwrapped.max_episode_steps == 600
    assert "TimeLimit" not in repr(env)  # the env truncates itself


def test_rgb_array_passes_the_env_checker_and_draws_the_ego_close_up(tmp_path):
    # check_env also makes the env in each other render mode: those stream to a file here (a
    # headless machine has no viewer to spawn)
    env = gym.make("EcoDrive-v0", signals="uncoordinated", render_mode="rgb_array",
                   rerun_target=str(tmp_path / "check.rrd"))
    check_env(env.unwrapped)
    env.reset(options=CASE)
    for _ in range(40):
        env.step(ACTION)
    frame = env.render()
    u = env.unwrapped
    c = u._closeup
    assert frame.dtype == np.uint8 and frame.shape == c.shape and frame.shape[2] == 3
    # the ego's front bumper at a fixed column, in its lane's row, in the ego's colour
    col = int(BEHIND * PX_X) - 2
    row = int((c.y_top - u.ego.kin.y) * PX_Y)
    assert tuple(frame[row, col]) == COLOURS["ego"]
    assert (frame == COLOURS["other"]).all(axis=2).sum() > 0  # traffic in view
    sig = u.ego.signal  # the next signal's head, in its state's colour, above its stop line
    head_col = int((BEHIND + sig.distance) * PX_X)
    if head_col < frame.shape[1]:
        assert tuple(frame[2:int(2 * PX_Y), head_col].max(axis=0)) != COLOURS["verge"]
    env.close()


def test_record_video_writes_the_close_up(tmp_path):
    from gymnasium.wrappers import RecordVideo

    env = RecordVideo(gym.make("EcoDrive-v0", signals="uncoordinated", render_mode="rgb_array",
                               config={"max_episode_time": 20.0}), str(tmp_path), episode_trigger=lambda e: True)
    env.reset(options=CASE)
    done = False
    while not done:
        _, _, te, tr, _ = env.step(ACTION)
        done = te or tr
    env.close()
    videos = list(tmp_path.glob("*.mp4"))
    assert len(videos) == 1 and videos[0].stat().st_size > 1000


def test_rerun_mode_streams_every_step_into_a_real_recording(tmp_path):
    import rerun as rr

    path = tmp_path / "live.rrd"
    env = gym.make("EcoDrive-v0", signals="uncoordinated", render_mode="rerun", rerun_target=str(path))
    env.reset(options=CASE)
    steps = 15
    for _ in range(steps):
        env.step(ACTION)
    assert env.render() is None
    env.close()
    srv = rr.server.Server(host="127.0.0.1", datasets={"ds": [str(path)]})
    try:
        client = srv.client()  # every handle stays alive while DataFusion reads
        dataset = client.get_dataset("ds")
        df = dataset.reader(index="sim_time").to_pandas()
    finally:
        srv.shutdown()
    assert df["/closeup:Image:buffer"].notna().sum() == steps + 1
    assert df["/series/speed:Scalars:scalars"].notna().sum() == steps + 1


def test_a_bad_render_mode_or_target_is_one_line():
    with pytest.raises(ValueError, match="render_mode='video' is not accepted; choose one of human, rgb_array, rerun"):
        gym.make("EcoDrive-v0", render_mode="video")
    env = gym.make("EcoDrive-v0", render_mode="rerun", rerun_target="ftp://x")
    with pytest.raises(ValueError, match="rerun target 'ftp://x' is not accepted"):
        env.reset(options=CASE)
    env.close()
