"""ecodrive_bench.bench.perf's arithmetic on a pytest-benchmark JSON (no timing here), and the CPU numba
compiles for, which the JSON records."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from ecodrive_bench.bench.perf import STEPS_PER_EPISODE, main, numba_target, ratios, target, tier


def _bench(name: str, median: float, mean: float | None = None, **extra) -> dict:
    return {"name": name, "stats": {"median": median, "mean": mean or median}, "extra_info": extra}


def test_flop_floor_and_projection(tmp_path, capsys):
    data = {"benchmarks": [
        _bench("test_learner_update[prl]", 0.020, flops=500_000_000),
        _bench("test_training_env_step", 0.002),
        _bench("test_matmul_rate", 0.001, flops=50_000_000),  # 50 GFLOP/s
    ]}
    path = tmp_path / "perf.json"
    path.write_text(json.dumps(data))
    r = ratios(path)
    assert r["matmul_gflops"] == pytest.approx(50.0)
    assert r["update_over_floor"] == pytest.approx(0.020 / 0.010)  # 0.5 GFLOP at 50 GFLOP/s = 10 ms
    assert r["prl_1000_episodes_floor_min"] == pytest.approx(0.010 * STEPS_PER_EPISODE * 1000 / 60)
    assert r["prl_1000_episodes_min"] == pytest.approx(0.022 * STEPS_PER_EPISODE * 1000 / 60)
    assert main([str(path)]) == 1  # the projected run misses 30 minutes
    assert "FLOP floor" in capsys.readouterr().out


def test_conv_share_and_floor(tmp_path, capsys):
    data = {"benchmarks": [
        _bench("test_learner_update[prl]", 0.010, flops=400_000_000),
        _bench("test_prl_conv_pass[forward]", 0.003, flops=50_000_000),
        _bench("test_prl_conv_pass[backward]", 0.002, flops=100_000_000),
        _bench("test_matmul_rate", 0.001, flops=100_000_000),  # 100 GFLOP/s
    ]}
    path = tmp_path / "perf.json"
    path.write_text(json.dumps(data))
    r = ratios(path)
    assert r["conv_forward_over_floor"] == pytest.approx(0.003 / 0.0005)
    assert r["conv_backward_over_floor"] == pytest.approx(0.002 / 0.001)
    assert r["conv_forward_share"] == pytest.approx(0.3)
    assert r["dense_over_floor"] == pytest.approx(0.005 / 0.0025)  # 5 ms for 250 MFLOP at 100 GFLOP/s
    main([str(path)])
    assert "PRL conv blocks backward / its floor" in capsys.readouterr().out


def test_update_by_kind_of_op(tmp_path, capsys):
    data = {"benchmarks": [
        _bench("test_learner_update[prl]", 0.010, flops=400_000_000),
        _bench("test_prl_conv_pass[forward]", 0.003, flops=50_000_000),
        _bench("test_prl_conv_pass[backward]", 0.002, flops=100_000_000),
        _bench("test_prl_update_by_kind", 0.015, ops_matmul_s=0.006, ops_elementwise_s=0.002, ops_view_s=0.0005,
               ops_optimizer_s=0.0005, update_s=0.0095, matmul_s=0.0005, matmul_flops=25_000_000),  # 50 GFLOP/s
        _bench("test_matmul_rate", 0.001, flops=100_000_000),  # 100 GFLOP/s
    ]}
    path = tmp_path / "perf.json"
    path.write_text(json.dumps(data))
    r = ratios(path)
    assert r["prl_matmul_over_floor"] == pytest.approx(0.006 / 0.008)  # 400 MFLOP at its own 50 GFLOP/s = 8 ms
    assert r["prl_between_ops_ms"] == pytest.approx(9.5 - 6.0 - 2.0 - 0.5 - 0.5)
    main([str(path)])
    out = capsys.readouterr().out
    assert "matmul 6.00 ms" in out and "between_ops 0.50 ms" in out


def test_paired_rounds_take_their_own_matmul_rate(tmp_path):
    """A benchmark timed beside the reference matmul in the same rounds is judged at that rate and by
    its own time, not by the run's separate matmul benchmark or its stats (which include the matmul)."""
    data = {"benchmarks": [
        _bench("test_learner_update[dqn]", 0.0101, flops=200_000_000, time_s=0.010, mean_s=0.011, matmul_s=0.0005,
               matmul_flops=25_000_000),  # 50 GFLOP/s in its own rounds
        _bench("test_learner_update[ddpg]", 0.010, flops=200_000_000),  # not paired: the run's rate
        _bench("test_matmul_rate", 0.001, flops=100_000_000),  # 100 GFLOP/s
    ]}
    path = tmp_path / "perf.json"
    path.write_text(json.dumps(data))
    r = ratios(path)
    assert r["update_over_floor_dqn"] == pytest.approx(0.010 / 0.004)
    assert r["updates_per_s_dqn"] == pytest.approx(100.0)
    assert r["update_over_floor_ddpg"] == pytest.approx(0.010 / 0.002)


def test_compiled_alternative_is_reported_not_judged(tmp_path, capsys):
    """The torch.compile'd autograd update is judged against the hand-written update's floor (the
    same update), at its own rounds' rate, and against the hand-written update's time; it is not a
    target, so a slow one does not fail the run."""
    data = {"benchmarks": [
        _bench("test_learner_update[prl]", 0.0101, flops=400_000_000, time_s=0.010, matmul_s=0.0005,
               matmul_flops=25_000_000),
        _bench("test_prl_update_compiled", 0.0201, flops=480_000_000, time_s=0.020, matmul_s=0.0004,
               matmul_flops=25_000_000),  # 62.5 GFLOP/s in its own rounds: the 400 MFLOP floor is 6.4 ms
        _bench("test_matmul_rate", 0.001, flops=100_000_000),
    ]}
    path = tmp_path / "perf.json"
    path.write_text(json.dumps(data))
    r = ratios(path)
    assert r["prl_compiled_over_floor"] == pytest.approx(0.020 / 0.0064)
    assert r["prl_compiled_over_update"] == pytest.approx(2.0)
    assert r["prl_compiled_gflop"] == pytest.approx(0.48)
    assert main([str(path)]) == 0  # the hand-written update is within 1.5x (1.25x); the compiled one is not judged
    out = capsys.readouterr().out
    assert "PRL update, compiled autograd / floor      3.12x" in out and "2.00x the hand-written" in out


def test_not_a_benchmark_file(tmp_path, capsys):
    bad = tmp_path / "x.json"
    bad.write_text("{}")
    assert main([str(bad)]) == 2 and "not a pytest-benchmark JSON" in capsys.readouterr().err


def test_a_benchmark_file_without_the_suites_benchmarks_is_refused(tmp_path, capsys):
    other = tmp_path / "other.json"
    other.write_text('{"benchmarks": [{"name": "test_something_else", "stats": {"median": 1.0, "mean": 1.0}}]}')
    assert main([str(other)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "other.json" in err[0]


def test_greedy_act_against_a_sumo_step(tmp_path, capsys):
    """One SUMO step is a raw-step round over its steps; each method's act is judged by its median
    against ``ACT_LIMIT_S`` and shown beside the torch forward and its share of an episode's step."""
    data = {"benchmarks": [
        _bench("test_raw_sumo_step", 0.150, steps=150),  # 1 ms a step
        _bench("test_greedy_act[prl]", 75e-6, episode_act_s=150e-6, episode_step_s=600e-6),
        _bench("test_greedy_act_torch[prl]", 300e-6, episode_act_s=450e-6, episode_step_s=650e-6),
        _bench("test_greedy_act[dqn]", 400e-6),  # too slow
    ]}
    path = tmp_path / "perf.json"
    path.write_text(json.dumps(data))
    r = ratios(path)
    assert r["sumo_step_us"] == pytest.approx(1000.0)
    assert r["act_over_sumo_step_prl"] == pytest.approx(0.075)
    assert r["act_torch_us_prl"] == pytest.approx(300.0) and r["act_torch_in_episode_us_prl"] == pytest.approx(450.0)
    assert r["act_over_env_step_in_episode_prl"] == pytest.approx(0.25)
    assert "act_torch_us_dqn" not in r and "act_in_episode_us_dqn" not in r
    assert main([str(path)]) == 1  # DQN's act misses the target
    out = capsys.readouterr().out.splitlines()
    prl = next(line for line in out if line.startswith("PRL greedy act"))
    assert "0.075x a SUMO step" in prl and "torch forward 300 us" in prl
    assert "in an episode 150 us (torch 450 us) = 0.25x its env.step" in prl
    assert prl.endswith(" ok") and next(line for line in out if line.startswith("DQN greedy act")).endswith("MISSED")
    data["benchmarks"] = data["benchmarks"][1:2]  # no SUMO step in the run: the act alone
    path.write_text(json.dumps(data))
    assert "act_over_sumo_step_prl" not in ratios(path) and main([str(path)]) == 0


def test_dp_replan_and_cold_solve_lines(tmp_path, capsys):
    data = {"benchmarks": [  # the cold solve's round is the solve and the reference solve after it
        _bench("test_dp_cold_solve", 2.4, time_s=0.8, reference_s=1.6, over_reference=0.52),
        _bench("test_dp_replan", 0.2, replans=200, median_s=0.001, p99_s=0.05),
    ]}
    path = tmp_path / "perf.json"
    path.write_text(json.dumps(data))
    r = ratios(path)
    assert r["replan_median_ms"] == pytest.approx(1.0) and r["replan_p99_ms"] == pytest.approx(50.0)
    assert r["replan_over_cold_solve"] == pytest.approx(0.001 / 0.8)  # the solve's own time, not the round's
    assert r["cold_solve_over_numpy"] == 0.52 and r["cold_solve_s"] == 0.8  # the rounds' ratio, as recorded
    assert main([str(path)]) == 1  # the re-plan meets its goal, the cold solve misses 10x
    out = capsys.readouterr().out
    assert "mpc re-plan" in out and "ok" in out.splitlines()[0] and "MISSED" in out.splitlines()[1]
    assert "numba" not in out  # an older file: no CPU recorded


AVX2 = {"NUMBA_CPU_NAME": "haswell", "NUMBA_CPU_FEATURES": "+avx2,+fma,-avx512f"}  # docs/performance.md's AVX2 target


def test_the_dp_ratio_is_printed_beside_numbas_cpu(tmp_path, capsys):
    data = {"benchmarks": [_bench("test_dp_cold_solve", 1.0, time_s=0.05, reference_s=0.95, over_reference=0.053)],
            "machine_info": {"numba": {"cpu": "haswell", "host_cpu": "emeraldrapids", "features": AVX2["NUMBA_CPU_FEATURES"],
                                       "vector": ["avx2", "fma"]}}}
    path = tmp_path / "perf.json"
    path.write_text(json.dumps(data))
    assert main([str(path)]) == 0
    dp, cpu = capsys.readouterr().out.splitlines()
    assert dp.startswith("DP cold solve / reference solve") and "0.053x" in dp and "numba: haswell, AVX2) ok" in dp
    assert cpu.split() == ["numba", "compiles", "for", "haswell", "(host:", "emeraldrapids):", "avx2", "fma"]
    data["machine_info"]["numba"] = {"cpu": "znver3"}  # not what numba_target writes: left out
    path.write_text(json.dumps(data))
    assert main([str(path)]) == 0 and "numba" not in capsys.readouterr().out


def test_numba_target_is_what_numba_compiles_for():
    """This process's target is the host's unless numba's variables name another; the vector
    extensions are the feature string's, and the widest names the tier."""
    here = numba_target()
    assert here["cpu"] == (os.environ.get("NUMBA_CPU_NAME") or here["host_cpu"])
    assert set(here["vector"]) <= {f[1:] for f in here["features"].split(",")}
    code = "import json; from ecodrive_bench.bench.perf import numba_target; print(json.dumps(numba_target()))"
    out = subprocess.run([sys.executable, "-c", code], env={**os.environ, **AVX2}, capture_output=True, text=True,
                         check=True, timeout=120).stdout
    avx2 = json.loads(out)
    assert avx2["cpu"] == "haswell" and avx2["features"] == AVX2["NUMBA_CPU_FEATURES"] and avx2["vector"] == ["avx2", "fma"]
    assert tier(avx2["vector"]) == "AVX2" and tier(["avx2", "avx512f", "sse4.2"]) == "AVX-512" and tier([]) != "AVX2"


@pytest.mark.slow
def test_the_benchmark_json_records_numbas_cpu(tmp_path):
    """``nox -s perf``'s JSON carries ``numba_target()`` in its machine info (tests/benchmarks/conftest.py),
    here from one cheap benchmark of the suite."""
    path = tmp_path / "perf.json"
    root = Path(__file__).parents[2]
    subprocess.run([sys.executable, "-m", "pytest", "tests/benchmarks/test_perf_train.py::test_matmul_rate", "-q",
                    "-p", "no:cacheprovider", "--benchmark-only", f"--benchmark-json={path}"],
                   cwd=root, env={**os.environ, **AVX2}, capture_output=True, text=True, check=True, timeout=600)
    assert target(path) == {"cpu": "haswell", "host_cpu": numba_target()["host_cpu"],
                            "features": AVX2["NUMBA_CPU_FEATURES"], "vector": ["avx2", "fma"]}


def test_episode_floor_lines_give_the_ratio_with_a_free_act(tmp_path, capsys):
    data = {"benchmarks": [
        _bench("test_episode_over_floor[prl]", 1.0, floor_ratio=1.48, floor_ratio_without_act=1.34),
        _bench("test_episode_over_floor[baseline]", 1.0, floor_ratio=1.29),  # an older file: no act's share
    ]}
    path = tmp_path / "perf.json"
    path.write_text(json.dumps(data))
    r = ratios(path)
    assert r["episode_over_floor_prl"] == 1.48 and r["without_act_over_floor_prl"] == 1.34
    assert "without_act_over_floor_baseline" not in r
    assert main([str(path)]) == 1  # prl misses 1.3x
    out = capsys.readouterr().out.splitlines()
    prl = next(line for line in out if line.startswith("prl: logged episode"))
    base = next(line for line in out if line.startswith("baseline: logged episode"))
    assert "MISSED; 1.340x with a free act" in prl and "ok" in base and "free act" not in base


def test_family_reset_target_and_the_clairvoyant_plan(tmp_path, capsys):
    def write(over_plain: float) -> Path:
        data = {"benchmarks": [
            _bench("test_family_reset", 1.0, over_plain=over_plain, family_reset_s=0.3, plain_reset_s=0.25, resets=10),
            _bench("test_clairvoyant_plan", 30.0, over_episode=10.5, plan_s=9.0, episode_s=0.86),
        ]}
        path = tmp_path / f"perf-{over_plain}.json"
        path.write_text(json.dumps(data))
        return path

    r = ratios(write(1.1))
    assert r["family_reset_over_plain"] == 1.1 and r["family_reset_ms"] == pytest.approx(300.0)
    assert r["clairvoyant_plan_over_episode"] == 10.5 and r["clairvoyant_plan_s"] == 9.0
    assert main([str(write(1.1))]) == 0
    out = capsys.readouterr().out
    assert "family env reset / plain env reset" in out and "ok" in out and "10.5 baseline episodes" in out
    assert main([str(write(1.3))]) == 1 and "MISSED" in capsys.readouterr().out
