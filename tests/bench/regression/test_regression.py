from __future__ import annotations

from ecodrive_bench.bench.regression.check import against_record


def test_recorded_failures_are_known_and_strict():
    rows = [("a", "FAIL", "x"), ("b", "PASS", "y"), ("c", "FAIL", "z"), ("d", "NOT CHECKED", "w")]
    record = {"a": "FAIL", "b": "FAIL", "c": "PASS", "d": "NOT CHECKED"}
    out = {name: status for name, status, _ in against_record(rows, record)}
    assert out == {"a": "KNOWN FAIL", "b": "FAIL", "c": "FAIL", "d": "NOT CHECKED"}
    assert [s for _, s, _ in against_record([("new", "FAIL", "")], {})] == ["FAIL"]  # unrecorded: a real failure


def test_a_policy_shipped_for_one_setting_runs_and_is_checked_there_only(tmp_path):
    import pandas as pd

    from ecodrive_bench.bench.harness.options import parse
    from ecodrive_bench.bench.harness.run import resolve_methods
    from ecodrive_bench.bench.regression.check import claims

    models = tmp_path / "models"
    for m, s in (("prl", "coordinated"), ("prl", "uncoordinated"), ("ddpg", "coordinated")):
        (models / f"{m}-{s}" / "s0").mkdir(parents=True)
        (models / f"{m}-{s}" / "s0" / "manifest.json").write_text("{}")
    (models / "prl-coordinated" / "s3").mkdir()
    (models / "prl-coordinated" / "s3" / "manifest.json").write_text("{}")
    opts = parse(["--logs", str(tmp_path / "logs")])
    opts.models = models
    runs, skipped = resolve_methods(opts)
    assert ("ddpg", "coordinated", 0) in runs and not any(r[:2] == ("ddpg", "uncoordinated") for r in runs)
    assert ("prl", "coordinated", 0) in runs and ("prl", "coordinated", 3) in runs  # every shipped seed
    assert "ddpg/uncoordinated" in skipped and "dqn/coordinated" in skipped
    assert ("baseline", "uncoordinated", -1) in runs

    rows = [{"method": m, "signals": s, "energy": e, "travel_time": 180.0, "collisions": 0}
            for m, s, e in (("baseline", "coordinated", 230.0), ("baseline", "uncoordinated", 250.0),
                            ("prl", "coordinated", 190.0), ("prl", "uncoordinated", 240.0),
                            ("ddpg", "coordinated", 200.0))]
    status = {name: st for name, st, _ in claims(pd.DataFrame(rows))}
    assert status["PRL uses less energy than DDPG+LC2013 (coordinated)"] == "PASS"
    assert status["PRL uses less energy than DDPG+LC2013 (uncoordinated)"] == "NOT CHECKED"
    assert status["PRL saves energy against the baseline (uncoordinated)"] == "PASS"


def test_ddpg_uncoordinated_travel_time_claim():
    import pandas as pd

    from ecodrive_bench.bench.regression.check import claims

    name = "DDPG+LC2013 slower than the baseline uncoordinated, and more so than coordinated"

    def status(ddpg_c: float, ddpg_u: float) -> str:
        rows = [{"method": m, "signals": s, "energy": 200.0, "travel_time": t, "collisions": 0}
                for m, s, t in (("baseline", "coordinated", 190.0), ("baseline", "uncoordinated", 250.0),
                                ("ddpg", "coordinated", ddpg_c), ("ddpg", "uncoordinated", ddpg_u))]
        return {n: st for n, st, _ in claims(pd.DataFrame(rows))}[name]

    assert status(190.0, 300.0) == "PASS"  # 0% vs +20%
    assert status(190.0, 240.0) == "FAIL"  # faster than the baseline uncoordinated
    assert status(247.0, 300.0) == "FAIL"  # +30% coordinated, +20% uncoordinated
    rows = [{"method": "baseline", "signals": s, "energy": 1.0, "travel_time": 1.0, "collisions": 0}
            for s in ("coordinated", "uncoordinated")]
    assert {n: st for n, st, _ in claims(pd.DataFrame(rows))}[name] == "NOT CHECKED"


def test_a_reference_written_without_the_mixed_cells_keeps_their_recorded_claims():
    from ecodrive_bench.bench.regression.check import record_rows

    earlier = [("a", "PASS", "old"), ("mixed x", "FAIL", "stalls"), ("gone", "NOT CHECKED", "")]
    now = [("a", "FAIL", "new"), ("mixed-traffic claims", "NOT CHECKED", "--no-mixed given")]
    assert record_rows(now, earlier) == [("a", "FAIL", "new"), ("mixed x", "FAIL", "stalls")]
    assert record_rows(now + [("mixed x", "PASS", "fixed")], earlier)[-1] == ("mixed x", "PASS", "fixed")
    assert record_rows([("a", "PASS", "new")], earlier) == [("a", "PASS", "new")]  # all checked: no stale row kept


def test_a_shipped_policy_that_cannot_drive_is_one_error_line(tmp_path, monkeypatch, capsys):
    """``ecodrive regress`` over models/ with a policy of the wrong structure (its manifest's
    sha256 matching): one line naming the file, exit code 2, before any episode runs."""
    import json
    import shutil

    import torch

    import ecodrive_bench.bench.harness.options as br
    from ecodrive_bench.bench.io import sha256
    from ecodrive_bench.bench.methods.policies import policy_dir
    from ecodrive_bench.bench.regression.check import main

    models = tmp_path / "models"
    folder = policy_dir("prl", "coordinated", models)
    shutil.copytree(policy_dir("prl", "coordinated"), folder)
    path = folder / "policy.pt"
    torch.save([1, 2, 3], path)
    man = json.loads((folder / "manifest.json").read_text())
    (folder / "manifest.json").write_text(json.dumps({**man, "sha256": sha256(path)}))
    monkeypatch.setattr(br, "MODELS", models)  # regress evaluates the default models folder
    logs = tmp_path / "logs"
    rc = main(["--logs", str(logs), "--no-mixed"])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and str(path) in err
    assert not logs.exists()
    assert "regression" not in br.PROFILES  # regress's profile is its own, not left for `ecodrive run`


def test_the_reference_allows_cross_host_float_noise_in_energy_only():
    """Energy may differ by the ~1e-7 relative a different CPU kernel gives a continuous action;
    anything more, or any change in a count or a time, fails."""
    import pandas as pd

    from ecodrive_bench.bench.regression.check import REF_COLUMNS, REFERENCE, reference

    ref = pd.read_csv(REFERENCE)
    group = ref[(ref.method == "prl") & (ref.signals == "coordinated") & (ref.train_seed == 0)]
    def status(col: str, factor: float) -> str:
        ours = group[REF_COLUMNS].astype({col: float})
        ours.loc[ours.index[3], col] *= factor
        return next(s for name, s, _ in reference(ours) if name == "reference prl/coordinated/0")

    assert status("energy", 1.0) == "PASS"
    assert status("energy", 1 + 1e-7) == "PASS"
    assert status("energy", 1 + 1e-5) == "FAIL"
    assert status("travel_time", 1 + 1e-7) == "FAIL"
