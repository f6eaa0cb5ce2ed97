"""Ratios from one pytest-benchmark JSON file (all numbers from the same run): env step against
raw SUMO, logging overhead, the projected training run, each learner's update against its FLOP
floor (the update's counted FLOPs at this core's measured matmul rate), each learned method's
greedy act against a raw SUMO step, the main job's logged episodes of each method against SUMO's
own time in them, and the DP: mpc's re-plan (median, p99) and a cold solve against the reference
solver (numpy kernel, unpruned global pass) timed in the same rounds, beside the CPU numba
compiled the DP for and its vector extensions.

    ecodrive perf .benchmarks/perf.json
"""
from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from ecodrive_bench.bench import registry
from ecodrive_bench.bench.args import Parser, fail

STEPS_PER_EPISODE = 250  # ~ mean training episode length (exploring episodes run longer than greedy ones)
LEARNERS = registry.names("learned", generalist=False)  # test_learner_update[...] benchmarks
CONV_PARTS = ("forward", "backward")  # test_prl_conv_pass[...]: the conv blocks' share of a PRL update
KINDS = ("matmul", "elementwise", "view", "optimizer")  # test_prl_update_by_kind: a PRL update's op time by kind
COMPILED = "test_prl_update_compiled"  # the autograd formulation under torch.compile: the alternative
REPLAN_MEDIAN_MS, REPLAN_P99_MS = 20.0, 100.0  # [ms] one mpc re-plan on one core
COLD_SOLVE_LIMIT = 0.1  # a whole case's bound at least 10x faster than the reference solver (numpy, unpruned)
FLOOR_LIMIT = 1.5  # an update within this factor of its FLOP floor (one thread)
ACT_LIMIT_S = 0.3e-3  # [s] a greedy batch-1 act (test_greedy_act[...], one thread)
FAMILY_RESET_LIMIT = 1.2  # [-] a warm family env's reset against a plain env's (test_family_reset, same rounds)
MAIN_JOB_LIMIT = 1.3  # [-] nox -s benchmark's goal, wall time x workers / SUMO's time; test_episode_over_floor[...]
# measures one process's logged episodes against it (without the pool's few percent)
VECTOR_PREFIXES = ("sse", "ssse3", "avx", "fma", "neon", "sve")  # LLVM's names of vector extensions
TIERS = (("AVX-512", "avx512f"), ("AVX2", "avx2"), ("AVX", "avx"), ("SSE4.2", "sse4.2"), ("SVE", "sve"), ("NEON", "neon"))
TARGETS = {  # name: (numerator, denominator, limit, what)
    "env_step_over_raw_step": ("test_env_step", "test_raw_sumo_step", 2.0, "env.step / raw step (medians)"),
    "env_step_over_sim_in_run": ("", "", 2.0, "env.step / its own simulationStep"),
    "real_env_step_over_raw_step": ("test_real_env_step", "test_real_raw_sumo_step", 1.5,
                                    "env.step / raw step on ingolstadt7 (medians)"),
    "logging_overhead": ("test_episode_logged", "test_episode_unlogged", 1.05, "episode with / without MCAP"),
    "log_overhead_in_run": ("", "", 1.05, "episode incl. logger / excl. logger"),
}


def numba_target() -> dict[str, Any]:
    """The CPU numba compiles for in this process, as LLVM names it: ``cpu`` (the host's,
    ``host_cpu``, unless ``NUMBA_CPU_NAME`` names another), ``features`` (the feature string numba
    hands LLVM: the host's whole list, or ``NUMBA_CPU_FEATURES`` where set, which adjusts the named
    CPU's own) and ``vector``, the vector extensions that string turns on. Read from numba's
    configuration and llvmlite, which numba compiles with: the DP's kernel runs what they select,
    whatever else the CPU has."""
    from llvmlite import binding as llvm
    from numba.core import config
    from numba.core.codegen import get_host_cpu_features

    features = config.CPU_FEATURES if config.CPU_FEATURES is not None else get_host_cpu_features()
    vector = sorted(f[1:] for f in features.split(",") if f.startswith("+") and f[1:].startswith(VECTOR_PREFIXES))
    host = llvm.get_host_cpu_name()
    return {"cpu": config.CPU_NAME or host, "host_cpu": host, "features": features, "vector": vector}


def tier(vector: list[str]) -> str:
    """The widest vector instruction set in ``vector`` (LLVM's feature names), e.g. ``AVX2``."""
    return next((name for name, feature in TIERS if feature in vector), "no vector extension listed")


def target(path: Path) -> dict[str, Any] | None:
    """``numba_target()`` as the run that wrote the JSON recorded it (tests/benchmarks/conftest.py)."""
    data = json.loads(path.read_text())
    info = data.get("machine_info") if isinstance(data, dict) else None
    found = info.get("numba") if isinstance(info, dict) else None
    if not (isinstance(found, dict) and all(isinstance(found.get(k), str) for k in ("cpu", "host_cpu", "features"))
            and isinstance(found.get("vector"), list)):
        return None
    return found


def ratios(path: Path) -> dict[str, float]:
    data = json.loads(path.read_text())
    med = {b["name"]: b["stats"]["median"] for b in data["benchmarks"]}
    out = {k: med[n] / med[d] for k, (n, d, _, _) in TARGETS.items() if n in med and d in med}

    extra = {b["name"]: b.get("extra_info", {}) for b in data["benchmarks"]}
    mean = {b["name"]: b["stats"]["mean"] for b in data["benchmarks"]}
    for name, e in extra.items():  # paired with the reference matmul (round by round): the op's own time
        if "time_s" in e:
            med[name], mean[name] = e["time_s"], e.get("mean_s", e["time_s"])
    overall = extra["test_matmul_rate"]["flops"] / med["test_matmul_rate"] if "test_matmul_rate" in med else None

    def rate(name: str) -> float | None:
        """The core's matmul rate [FLOP/s] while ``name`` ran: from its own rounds where paired."""
        e = extra.get(name, {})
        return e["matmul_flops"] / e["matmul_s"] if "matmul_s" in e else overall

    if "step_over_sim" in extra.get("test_env_step", {}):
        out["env_step_over_sim_in_run"] = extra["test_env_step"]["step_over_sim"]
    if "log_overhead" in extra.get("test_episode_logged", {}):
        out["log_overhead_in_run"] = 1.0 + extra["test_episode_logged"]["log_overhead"]
    if "control_over_sim" in extra.get("test_fleet_step_200_cvs", {}):
        out["fleet_control_over_sim"] = extra["test_fleet_step_200_cvs"]["control_over_sim"]
        out["fleet_cvs"] = extra["test_fleet_step_200_cvs"]["cvs_mean"]
    sumo_steps = extra.get("test_raw_sumo_step", {}).get("steps")  # a round's simulationStep calls
    if "test_raw_sumo_step" in med and sumo_steps:
        out["sumo_step_us"] = med["test_raw_sumo_step"] / sumo_steps * 1e6
    for m in LEARNERS:
        name = f"test_greedy_act[{m}]"
        if name not in med:
            continue
        out[f"act_us_{m}"] = med[name] * 1e6
        if "sumo_step_us" in out:
            out[f"act_over_sumo_step_{m}"] = out[f"act_us_{m}"] / out["sumo_step_us"]
        if f"test_greedy_act_torch[{m}]" in med:
            out[f"act_torch_us_{m}"] = med[f"test_greedy_act_torch[{m}]"] * 1e6
            if extra[f"test_greedy_act_torch[{m}]"].get("episode_act_s"):
                out[f"act_torch_in_episode_us_{m}"] = extra[f"test_greedy_act_torch[{m}]"]["episode_act_s"] * 1e6
        e = extra[name]
        if e.get("episode_step_s"):  # the same act inside a greedy episode, beside its env.step
            out[f"act_in_episode_us_{m}"] = e["episode_act_s"] * 1e6
            out[f"act_over_env_step_in_episode_{m}"] = e["episode_act_s"] / e["episode_step_s"]
    if "test_env_reset" in med:
        out["reset_ms"] = med["test_env_reset"] * 1e3
    plan = extra.get("test_clairvoyant_plan", {})
    if "over_episode" in plan:
        out["clairvoyant_plan_over_episode"] = plan["over_episode"]
        out["clairvoyant_plan_s"] = plan["plan_s"]
    fam = extra.get("test_family_reset", {})
    if "over_plain" in fam:
        out["family_reset_over_plain"] = fam["over_plain"]
        out["family_reset_ms"] = fam["family_reset_s"] * 1e3
        out["plain_reset_ms"] = fam["plain_reset_s"] * 1e3
    for name, e in extra.items():  # the main job's episodes, method by method, against SUMO's own time
        if name.startswith("test_episode_over_floor[") and "floor_ratio" in e:
            method = name[len("test_episode_over_floor["):-1]
            out[f"episode_over_floor_{method}"] = e["floor_ratio"]
            if "floor_ratio_without_act" in e:
                out[f"without_act_over_floor_{method}"] = e["floor_ratio_without_act"]
    if "median_s" in extra.get("test_dp_replan", {}):  # one re-plan of mpc, against the cold solve
        out["replan_median_ms"] = extra["test_dp_replan"]["median_s"] * 1e3
        out["replan_p99_ms"] = extra["test_dp_replan"]["p99_s"] * 1e3
        if "test_dp_cold_solve" in med:
            out["replan_over_cold_solve"] = extra["test_dp_replan"]["median_s"] / med["test_dp_cold_solve"]
    cold = extra.get("test_dp_cold_solve", {})
    if "over_reference" in cold:  # the rounds' ratios: each cold solve against the reference solve after it
        out["cold_solve_over_numpy"] = cold["over_reference"]
        out["cold_solve_s"] = cold["time_s"]
    if "test_learner_update[prl]" in med and "test_training_env_step" in med:
        per_step = mean["test_learner_update[prl]"] + mean["test_training_env_step"]
        out["updates_per_s"] = 1.0 / mean["test_learner_update[prl]"]
        out["env_steps_per_s"] = 1.0 / mean["test_training_env_step"]
        out["prl_1000_episodes_min"] = per_step * STEPS_PER_EPISODE * 1000 / 60
        flops = extra.get("test_learner_update[prl]", {}).get("flops")
        if flops and rate("test_learner_update[prl]"):
            floor = flops / rate("test_learner_update[prl]")  # [s] the update at the matmul rate, no overhead
            out["update_gflop"] = flops / 1e9
            out["matmul_gflops"] = rate("test_learner_update[prl]") / 1e9
            out["update_over_floor"] = med["test_learner_update[prl]"] / floor
            out["prl_1000_episodes_floor_min"] = floor * STEPS_PER_EPISODE * 1000 / 60
    if overall or any("matmul_s" in e for e in extra.values()):
        for m in LEARNERS:
            name = f"test_learner_update[{m}]"
            flops = extra.get(name, {}).get("flops")
            if name in med and flops and rate(name):
                out[f"update_gflop_{m}"] = flops / 1e9
                out[f"update_over_floor_{m}"] = med[name] * rate(name) / flops
                out[f"updates_per_s_{m}"] = 1.0 / med[name]  # median: one update's typical time
        for part in CONV_PARTS:
            name = f"test_prl_conv_pass[{part}]"
            flops = extra.get(name, {}).get("flops")
            if name in med and flops and rate(name):
                out[f"conv_{part}_over_floor"] = med[name] * rate(name) / flops
                if "test_learner_update[prl]" in med:
                    out[f"conv_{part}_share"] = med[name] / med["test_learner_update[prl]"]
        upd = "test_learner_update[prl]"
        flops = extra.get(upd, {}).get("flops")  # the same update's floor as the hand-written one's
        if COMPILED in med and flops and rate(COMPILED):
            out["prl_compiled_over_floor"] = med[COMPILED] * rate(COMPILED) / flops
            out["prl_compiled_gflop"] = extra[COMPILED].get("flops", 0) / 1e9
            out["prl_compiled_over_update"] = med[COMPILED] / med[upd]
        parts = [f"test_prl_conv_pass[{p}]" for p in CONV_PARTS]
        if (all(n in med and extra[n].get("flops") for n in parts) and extra.get(upd, {}).get("flops") and upd in med
                and rate(upd)):
            # the update less its conv blocks, each time in matmul-equivalent FLOPs at its own rounds' rate
            rest = med[upd] * rate(upd) - sum(med[n] * rate(n) for n in parts)
            rest_flops = extra[upd]["flops"] - sum(extra[n]["flops"] for n in parts)
            out["dense_over_floor"] = rest / rest_flops
        kinds = "test_prl_update_by_kind"
        by_kind = extra.get(kinds, {})
        if (all(f"ops_{k}_s" in by_kind for k in KINDS) and "update_s" in by_kind and extra.get(upd, {}).get("flops")
                and rate(kinds)):
            for k in KINDS:
                out[f"prl_{k}_ms"] = by_kind[f"ops_{k}_s"] * 1e3
            out["prl_between_ops_ms"] = by_kind["update_s"] * 1e3 - sum(out[f"prl_{k}_ms"] for k in KINDS)
            # every counted FLOP is a matmul's or a convolution's
            out["prl_matmul_over_floor"] = by_kind["ops_matmul_s"] * rate(kinds) / extra[upd]["flops"]
    return out


def main(argv: list[str] | None = None) -> int:
    ap = Parser(description=__doc__)
    ap.add_argument("benchmark_json", type=Path, help="a file written by pytest --benchmark-json (nox -s perf)")
    args = ap.parse_args(argv)
    if not args.benchmark_json.is_file():
        what = "not a file" if args.benchmark_json.exists() else "no such file"
        return fail(ap.prog, f"{args.benchmark_json}: {what} (expected a pytest-benchmark JSON)")
    try:
        r = ratios(args.benchmark_json)
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError) as e:
        return fail(ap.prog, f"{args.benchmark_json}: not a pytest-benchmark JSON file ({type(e).__name__}: {e})")
    if not r:
        return fail(ap.prog, f"{args.benchmark_json}: none of the suite's benchmarks (tests/benchmarks) in it; "
                             "write one with nox -s perf")
    ok = True
    for key, (_, _, limit, what) in TARGETS.items():
        if key in r:
            good = r[key] <= limit
            ok &= good
            print(f"{what:40s} {r[key]:6.3f}x  (target <= {limit}x) {'ok' if good else 'MISSED'}")
    if "reset_ms" in r:
        good = r["reset_ms"] <= 50
        ok &= good
        print(f"{'env.reset':40s} {r['reset_ms']:6.1f} ms (target <= 50 ms) {'ok' if good else 'MISSED'}")
    if "clairvoyant_plan_over_episode" in r:  # no target: a shipped case costs one episode
        print(f"{'clairvoyant: planning an unshipped case':40s} {r['clairvoyant_plan_s']:6.2f} s "
              f"({r['clairvoyant_plan_over_episode']:.1f} baseline episodes of the same case)")
    if "family_reset_over_plain" in r:
        good = r["family_reset_over_plain"] <= FAMILY_RESET_LIMIT
        ok &= good
        print(f"{'family env reset / plain env reset':40s} {r['family_reset_over_plain']:6.3f}x "
              f"({r['family_reset_ms']:.0f} ms against {r['plain_reset_ms']:.0f} ms, warm cache; "
              f"target <= {FAMILY_RESET_LIMIT:g}x) {'ok' if good else 'MISSED'}")
    if "fleet_control_over_sim" in r:
        good = r["fleet_control_over_sim"] <= 3.0
        ok &= good
        print(f"{'mixed traffic: control / sim step':40s} {r['fleet_control_over_sim']:6.2f}x "
              f"({r['fleet_cvs']:.0f} CVs; target <= 3x) {'ok' if good else 'MISSED'}")
    if "replan_median_ms" in r:
        good = r["replan_median_ms"] <= REPLAN_MEDIAN_MS and r["replan_p99_ms"] <= REPLAN_P99_MS
        ok &= good
        vs = f", {r['replan_over_cold_solve']:.4f}x a cold solve" if "replan_over_cold_solve" in r else ""
        print(f"{'mpc re-plan (median, p99)':40s} {r['replan_median_ms']:6.2f} ms, {r['replan_p99_ms']:.2f} ms "
              f"(target <= {REPLAN_MEDIAN_MS:g} ms, <= {REPLAN_P99_MS:g} ms{vs}) {'ok' if good else 'MISSED'}")
    if "cold_solve_over_numpy" in r:
        good = r["cold_solve_over_numpy"] <= COLD_SOLVE_LIMIT
        ok &= good
        cpu = target(args.benchmark_json)
        on = f"; numba: {cpu['cpu']}, {tier(cpu['vector'])}" if cpu else ""
        print(f"{'DP cold solve / reference solve':40s} {r['cold_solve_over_numpy']:6.3f}x ({r['cold_solve_s']:.2f} s; "
              f"target <= {COLD_SOLVE_LIMIT:g}x{on}) {'ok' if good else 'MISSED'}")
        if cpu:
            host = "" if cpu["host_cpu"] == cpu["cpu"] else f" (host: {cpu['host_cpu']})"
            print(f"{'numba compiles for':40s} {cpu['cpu']}{host}: {' '.join(cpu['vector']) or cpu['features'] or '-'}")
    if "sumo_step_us" in r:
        print(f"{'raw SUMO step':40s} {r['sumo_step_us']:6.0f} us")
    for key in sorted(k for k in r if k.startswith("episode_over_floor_")):  # one process: no pool overhead
        good = r[key] <= MAIN_JOB_LIMIT
        ok &= good
        free = r.get(f"without_act_over_floor_{key[len('episode_over_floor_'):]}")
        print(f"{key[len('episode_over_floor_'):] + ': logged episode / SUMO time':40s} {r[key]:6.3f}x  "
              f"(the main job's target <= {MAIN_JOB_LIMIT}x) {'ok' if good else 'MISSED'}"
              + (f"; {free:.3f}x with a free act" if free is not None else ""))
    for m in LEARNERS:
        if f"act_us_{m}" in r:
            good = r[f"act_us_{m}"] <= ACT_LIMIT_S * 1e6
            ok &= good
            ratio = (f"{r[f'act_over_sumo_step_{m}']:6.3f}x a SUMO step" if f"act_over_sumo_step_{m}" in r
                     else "(no raw SUMO step in this run)")
            notes = [f"{r[f'act_us_{m}']:.0f} us, target <= {ACT_LIMIT_S * 1e6:.0f} us"]
            if f"act_torch_us_{m}" in r:
                notes.append(f"torch forward {r[f'act_torch_us_{m}']:.0f} us")
            if f"act_in_episode_us_{m}" in r:
                torch_ep = r.get(f"act_torch_in_episode_us_{m}")
                notes.append(f"in an episode {r[f'act_in_episode_us_{m}']:.0f} us"
                             + (f" (torch {torch_ep:.0f} us)" if torch_ep else "")
                             + f" = {r[f'act_over_env_step_in_episode_{m}']:.2f}x its env.step")
            print(f"{m.upper() + ' greedy act (batch 1)':40s} {ratio} ({'; '.join(notes)}) {'ok' if good else 'MISSED'}")
    if "prl_1000_episodes_min" in r:
        good = r["prl_1000_episodes_min"] <= 30
        ok &= good
        print(f"{'PRL learner updates/s':40s} {r['updates_per_s']:6.1f}")
        print(f"{'training env steps/s (act+step+store)':40s} {r['env_steps_per_s']:6.1f}")
        print(f"{'projected 1000-episode PRL run':40s} {r['prl_1000_episodes_min']:6.1f} min "
              f"(target <= 30 min, {STEPS_PER_EPISODE} steps/episode) {'ok' if good else 'MISSED'}")
    if "update_over_floor" in r:
        print(f"{'PRL update: floating-point work':40s} {r['update_gflop']:6.3f} GFLOP "
              f"(one core's matmul rate: {r['matmul_gflops']:.1f} GFLOP/s)")
        print(f"{'1000 episodes of updates at the floor':40s} {r['prl_1000_episodes_floor_min']:6.1f} min "
              f"(no env steps; one update of batch 128 per step)")
    for m in LEARNERS:
        if f"update_over_floor_{m}" in r:
            good = r[f"update_over_floor_{m}"] <= FLOOR_LIMIT
            ok &= good
            print(f"{m.upper() + ' update / its FLOP floor':40s} {r[f'update_over_floor_{m}']:6.2f}x  "
                  f"(target <= {FLOOR_LIMIT}x; {r[f'update_gflop_{m}']:.3f} GFLOP, "
                  f"{r[f'updates_per_s_{m}']:.0f} updates/s) {'ok' if good else 'MISSED'}")
    if "prl_compiled_over_floor" in r:
        print(f"{'PRL update, compiled autograd / floor':40s} {r['prl_compiled_over_floor']:6.2f}x  "
              f"(torch.compile of the autograd formulation, not used in training: "
              f"{r['prl_compiled_over_update']:.2f}x the hand-written update's time; "
              f"it counts {r['prl_compiled_gflop']:.3f} GFLOP)")
    for part in CONV_PARTS:
        if f"conv_{part}_over_floor" in r:
            share = r.get(f"conv_{part}_share")
            print(f"{'PRL conv blocks ' + part + ' / its floor':40s} {r[f'conv_{part}_over_floor']:6.2f}x  "
                  + (f"(alone: {share:.0%} of an update's time)" if share is not None else ""))
    if "dense_over_floor" in r:
        print(f"{'PRL update less its conv blocks / floor':40s} {r['dense_over_floor']:6.2f}x  "
              "(dense layers, losses, Adam, target updates, sampling)")
    if "prl_matmul_over_floor" in r:
        print(f"{'PRL update by kind of op':40s} " + ", ".join(
            f"{k} {r[f'prl_{k}_ms']:.2f} ms" for k in (*KINDS, "between_ops")))
        print(f"{'PRL matmuls and convolutions / floor':40s} {r['prl_matmul_over_floor']:6.2f}x  "
              "(the update if every other op, view and line of Python were free)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
