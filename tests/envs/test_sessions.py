"""Several envs in one process each drive their own simulation, and the env keeps to its spaces.

libsumo holds one simulation per process (``envs.sumo``): the first env to reset runs there, one
that resets while another is mid-episode runs its own SUMO through TraCI. These tests compare
every step with the same case driven alone, and an in-process (sync) vector env with one process
per env (async).
"""
from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import ecodrive_bench.envs  # noqa: F401  (registers EcoDrive-v0)
from ecodrive_bench.envs.action import InvalidAction

A = {"sumo_seed": 7, "insert_time": 210.0}
B = {"sumo_seed": 99, "insert_time": 160.0}
ACTION = (1, np.array([0.0, 1.0, 0.0], dtype=np.float32))


def _trace(env, steps: int) -> list[tuple[float, float, float, float]]:
    out = []
    for _ in range(steps):
        _, r, _, _, info = env.step(ACTION)
        out.append((info["time"], info["energy_step"], info["energy"], r))
    return out


def _alone(signals: str, case: dict, steps: int) -> list[tuple[float, float, float, float]]:
    env = gym.make("EcoDrive-v0", signals=signals).unwrapped
    env.reset(options=case)
    out = _trace(env, steps)
    env.close()
    return out


def test_two_envs_interleaved_equal_each_alone_libsumo_and_traci():
    alone_a, alone_b = _alone("coordinated", A, 40), _alone("uncoordinated", B, 40)
    a = gym.make("EcoDrive-v0", signals="coordinated").unwrapped
    b = gym.make("EcoDrive-v0", signals="uncoordinated").unwrapped
    a.reset(options=A)
    b.reset(options=B)  # a is mid-episode in libsumo: b gets a SUMO of its own
    assert (a.session.backend, b.session.backend) == ("libsumo", "traci")
    both_a, both_b = [], []
    for _ in range(40):
        both_a += _trace(a, 1)
        both_b += _trace(b, 1)
    a.close()
    b.close()
    assert both_a[0][0] == alone_a[0][0] == 212.0  # the symptom: a stepped b's simulation (162.0)
    # every step's time, energy and reward equal the case driven alone in libsumo
    assert both_a == alone_a
    assert both_b == alone_b
    assert sum(e for _, e, _, _ in both_b) > 0


def test_sync_vector_env_equals_one_process_per_env():
    def rollout(mode: str) -> tuple[np.ndarray, np.ndarray]:
        vec = gym.make_vec("EcoDrive-v0", num_envs=2, vectorization_mode=mode)
        obs, _ = vec.reset(seed=[1, 2])
        logics, rewards = [obs["logic"].copy()], []
        for _ in range(25):
            acts = (np.array([1, 1]), np.tile(np.array([0.0, 0.5, 0.0], dtype=np.float32), (2, 1)))
            obs, r, _, _, _ = vec.step(acts)
            logics.append(obs["logic"].copy())
            rewards.append(r.copy())
        vec.close()
        return np.array(logics), np.array(rewards)

    sync_logic, sync_r = rollout("sync")
    async_logic, async_r = rollout("async")
    np.testing.assert_array_equal(sync_logic, async_logic)
    np.testing.assert_array_equal(sync_r, async_r)
    assert sync_r[0, 0] > -10  # the shared-simulation symptom was a first reward of -52


def test_an_ended_episode_hands_libsumo_to_the_next_env():
    a = gym.make("EcoDrive-v0", signals="coordinated", config={"max_episode_time": 10.0}).unwrapped
    a.reset(options=A)
    ended = False
    while not ended:
        _, _, te, tr, _ = a.step(ACTION)
        ended = te or tr
    with pytest.raises(RuntimeError, match="episode has ended"):
        a.step(ACTION)
    b = gym.make("EcoDrive-v0", signals="coordinated").unwrapped
    b.reset(options=A)
    assert b.session.backend == "libsumo"  # a's episode was over: no second SUMO process
    with pytest.raises(RuntimeError, match="not running"):
        a.session.time()
    a.reset(options=A)  # b is mid-episode: a runs beside it through TraCI
    assert a.session.backend == "traci"
    a.close()
    b.close()


@pytest.fixture(scope="module")
def env():
    e = gym.make("EcoDrive-v0", signals="uncoordinated").unwrapped
    e.reset(options=B)
    yield e
    e.close()


@pytest.mark.parametrize("action", [
    (-1, np.zeros(3)), (3, np.zeros(3)), (1.7, np.zeros(3)), (True, np.zeros(3)),
    (1, np.full(3, np.nan)), (1, np.array([0.0, 100.0, 0.0])), (1, np.zeros(5)), (1, "abc"),
    (1, np.array([0.0, np.inf, 0.0])), (1, np.zeros(3), 0), np.zeros(4), None, 1,
    (1, np.array([0.0, 100.0, 0.0], dtype=np.float32)), (1, np.full(3, np.nan, dtype=np.float32)),
    (1, np.array([0.0, -np.inf, 0.0], dtype=np.float32)), (1, np.array([0.0, 0.0, np.nextafter(np.float32(3.0), 4)])),
    (1, np.array([np.nextafter(np.float32(-4.0), -5), 0.0, 0.0], dtype=np.float32)),
])
def test_an_action_outside_the_space_is_refused_and_not_simulated(env, action):
    t = env.session.time()
    with pytest.raises(InvalidAction, match=r"outside the action space Tuple\(Discrete\(3\), Box"):
        env.step(action)
    assert env.session.time() == t


def test_numbers_of_any_width_inside_the_space_are_accepted(env):
    for action in [(np.int64(1), np.zeros(3)), (1, [0.0, 3.0, -4.0]), [0, np.zeros(3, dtype=np.float64)],
                   (np.array(2), np.full(3, -4.0, dtype=np.float32)), (0, np.array([-4.0, 3.0, 0.5], dtype=np.float32))]:
        env.step(action)


@pytest.mark.parametrize("kind,bad", [("discrete27", 27), ("discrete27", -1), ("discrete27", 2.0),
                                      ("longitudinal", np.array([3.5])), ("longitudinal", np.zeros(2)),
                                      ("longitudinal", np.array([np.nan])), ("longitudinal", np.array([3.5], dtype=np.float32)),
                                      ("longitudinal", np.array([np.inf], dtype=np.float32)), ("sumo", 1)])
def test_other_action_types_enforce_their_space(kind, bad):
    e = gym.make("EcoDrive-v0", signals="uncoordinated", action=kind).unwrapped
    e.reset(options=B)
    with pytest.raises(InvalidAction, match=f"action .* outside the action space {type(e.action_space).__name__}"):
        e.step(bad)
    e.step(e.action_space.sample())
    e.close()


@settings(max_examples=300, deadline=None, derandomize=True)
@given(k=st.one_of(st.integers(-5, 5), st.floats(allow_nan=True), st.booleans(), st.none(), st.text(max_size=2)),
       params=st.one_of(st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), max_size=5),
                        st.just("x"), st.none()),
       dtype=st.sampled_from([np.float64, np.float32]))
def test_action_check_agrees_with_the_space(k, params, dtype):
    """The action parser accepts exactly the actions of the space (fuzzed), never raising
    anything but ``InvalidAction``; float32 arrays take the parser's fast form."""
    from ecodrive_bench.envs.action import make_action
    from ecodrive_bench.envs.config import ScenarioConfig

    at = make_action("parameterized", ScenarioConfig.from_dict({"signals": "uncoordinated"}))
    if params is None or isinstance(params, str):
        action = (k, params)
    else:
        with np.errstate(over="ignore"):  # float64 beyond float32's range becomes an infinity
            action = (k, np.asarray(params, dtype=np.float64).astype(dtype))
    arr = action[1] if isinstance(action[1], np.ndarray) else None
    inside = (isinstance(k, int) and not isinstance(k, bool) and 0 <= k < 3 and arr is not None
              and arr.shape == (3,) and bool(np.isfinite(arr).all())
              and bool(np.all(arr.astype(np.float32) >= -4.0) and np.all(arr.astype(np.float32) <= 3.0)))
    if inside:
        at.check(action)
    else:
        with pytest.raises(InvalidAction):
            at.check(action)


@settings(max_examples=300, deadline=None, derandomize=True)
@given(k=st.integers(0, 2), params=st.lists(st.floats(allow_nan=True, allow_infinity=True, width=32), min_size=3,
                                             max_size=3),
       bounds=st.sampled_from([(-4.0, 3.0), (-3.3, 2.6), (-0.1, 0.1), (-4, 3), (np.float64(-3.3), np.float64(2.6))]),
       dtype=st.sampled_from([np.float32, np.float64]))
def test_decode_clips_as_numpy_does(k, params, bounds, dtype):
    """The parameterized action's acceleration is ``np.clip`` of the chosen parameter, value for
    value, on float32 arrays (decoded without numpy) as on others, with bounds a float32 cannot
    hold exactly (2.6: numpy clips a float32 at float32(2.6), a float64 at 2.6) and bounds given as
    numpy float64 (which numpy promotes the float32 parameter to)."""
    from ecodrive_bench.envs.action import make_action
    from ecodrive_bench.envs.config import ScenarioConfig

    at = make_action("parameterized", ScenarioConfig.from_dict({"signals": "uncoordinated", "a_min": bounds[0],
                                                                "a_max": bounds[1]}))
    arr = np.asarray(params, dtype=dtype)
    edges = np.array([np.nextafter(np.float32(b), np.float32(d)) for b in bounds for d in (-9, 9)], dtype=dtype)
    for a in (arr, edges[:3], edges[1:]):
        want = float(np.clip(a[k], *bounds))
        got = at.decode((k, a)).accel
        assert got == want or (np.isnan(got) and np.isnan(want)), (a[k], got, want)
        assert at.decode((k, a)).lateral == (-1, 0, 1)[k]


@pytest.mark.parametrize("options,match", [
    ({"sumo_seed": 2**70}, r"sumo_seed=1180591620717411303424 is not accepted; accepted: an integer in \[0, "),
    ({"sumo_seed": -1}, "sumo_seed=-1 is not accepted"), ({"sumo_seed": "7"}, "sumo_seed='7' is not accepted"),
    ({"sumo_seed": 7.5}, "sumo_seed=7.5"), ({"insert_time": -1.0}, r"insert_time=-1.0 is not accepted; accepted: "
                                                                  r"a number in \[0, 86400\] s"),
    ({"insert_time": float("nan")}, "insert_time=nan"), ({"sumo-seed": 7}, "reset option.*'sumo-seed' not accepted"),
])
def test_bad_reset_options_are_one_line(options, match):
    e = gym.make("EcoDrive-v0", signals="uncoordinated").unwrapped
    with pytest.raises(ValueError, match=match) as err:
        e.reset(options=options)
    assert "\n" not in str(err.value)
    e.close()

