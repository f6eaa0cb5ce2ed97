"""Your own agent in the table: a factory given on the command line (or registered as an entry
point) is evaluated like the built-in methods, and a bad one is one line with exit code 2."""
from __future__ import annotations

import sys
import textwrap

import pandas as pd
import pytest

from ecodrive_bench.bench.harness.options import parse
from ecodrive_bench.bench.harness.run import run
from ecodrive_bench.bench.harness.run_command import main
from ecodrive_bench.bench.methods.external import AgentError, build, load_factory

AGENT = textwrap.dedent('''
    import numpy as np

    class Cruise:
        """Keeps the lane and holds a gentle acceleration: a user's 20-line agent."""
        name = "cruise"
        action_interface = "parameterized"
        env_overrides = {}

        def __init__(self, observation_space, action_space, accel=0.5):
            self.accel = accel

        def act(self, obs, info, explore=False):
            return 1, np.full(3, self.accel, dtype=np.float32)

        def observe(self, *args):
            return {}

        def state_dict(self):
            return {}

        def load_state_dict(self, state):
            pass

    def make(observation_space, action_space):
        return Cruise(observation_space, action_space)

    def too_fast(observation_space, action_space):
        return Cruise(observation_space, action_space, accel=9.0)

    def not_an_agent(observation_space, action_space):
        return object()
''')


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    (tmp_path / "myagents.py").write_text(AGENT)
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setenv("PYTHONPATH", str(tmp_path))  # the pool's workers import it too
    sys.modules.pop("myagents", None)
    return tmp_path


def test_a_user_agent_lands_in_the_results_beside_the_baseline(user_module, tmp_path):
    logs = tmp_path / "logs"
    df = run(parse(["--profile", "smoke", "--logs", str(logs), "--methods", "baseline", "--signals", "coordinated",
                    "--agent", "myagents:make", "--name", "cruise", "--workers", "2"]), progress=False)
    table = pd.read_parquet(logs / "smoke" / "results.parquet")
    assert sorted(set(table.method)) == ["baseline", "cruise"] and len(table) == 6
    mine = table[table.method == "cruise"]
    assert (mine.train_seed == -1).all() and (mine.lane_changes_requested == 0).all()
    assert all((logs / "smoke" / p).is_file() for p in mine.mcap)
    assert not mine.energy.equals(table[table.method == "baseline"].energy.reset_index(drop=True))
    assert len(df) == 6


@pytest.mark.parametrize("spec, words", [
    ("myagents:nothing", "has no callable 'nothing'"),
    ("no_such_module:make", "cannot import no_such_module"),
    ("not a spec", "expected package.module:factory"),
    ("myagents:not_an_agent", "does not satisfy agents.base.Agent"),
])
def test_a_bad_factory_is_one_line_and_runs_nothing(spec, words, user_module, tmp_path, capsys):
    rc = main(["--profile", "smoke", "--logs", str(tmp_path / "logs"), "--agent", spec, "--methods", "baseline"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and len(err) == 1 and words in err[0]
    assert not list((tmp_path / "logs").rglob("*.mcap"))


def test_an_action_outside_the_space_stops_the_run_with_one_line(user_module, tmp_path, capsys):
    rc = main(["--profile", "smoke", "--logs", str(tmp_path / "logs"), "--agent", "myagents:too_fast",
               "--methods", "baseline", "--signals", "coordinated", "--workers", "1"])
    err = [ln for ln in capsys.readouterr().err.strip().splitlines()
           if ln.strip() and not ln.startswith("episodes:")]  # progress bar
    assert rc == 3 and len(err) == 1 and "outside the action space" in err[0] and "9." in err[0]  # the agent failed
    assert "too_fast/coordinated case 000" in err[0] and "step 0" in err[0]
    table = pd.read_parquet(tmp_path / "logs" / "smoke" / "results.parquet")  # the baseline's rows are kept
    assert set(table.method) == {"baseline"} and len(table) == 3


def test_a_name_taken_by_a_built_in_method_is_refused(user_module, capsys):
    with pytest.raises(SystemExit) as e:
        parse(["--agent", "myagents:make", "--name", "prl"])
    assert e.value.code == 2 and "taken" in capsys.readouterr().err


def test_build_checks_the_protocol(user_module):
    from gymnasium import spaces

    obs, act = spaces.Dict({}), spaces.Discrete(3)
    with pytest.raises(AgentError, match="missing name"):
        build("myagents:not_an_agent", obs, act)
    assert callable(load_factory("myagents:make"))


def test_an_installed_entry_point_runs_by_name(user_module, tmp_path):
    """A package that declares ``[project.entry-points."ecodrive_bench.agents"] cruise2 = ...`` is
    found by importlib.metadata; here its installed metadata is written by hand."""
    info = user_module / "theirpkg-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: theirpkg\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[ecodrive_bench.agents]\ncruise2 = myagents:make\n")
    logs = tmp_path / "logs"
    run(parse(["--profile", "smoke", "--logs", str(logs), "--methods", "cruise2", "--signals", "uncoordinated",
               "--workers", "2"]), progress=False)
    table = pd.read_parquet(logs / "smoke" / "results.parquet")
    assert set(table.method) == {"cruise2"} and len(table) == 3


def test_the_documented_agent_builds_under_each_action_interface(tmp_path, monkeypatch):
    """docs/your-agent.md's example, as printed, and with the class's ``action_interface`` changed
    as its comment suggests: the factory follows it, and an interface set on the class alone is
    one message that says where to set it."""
    import re
    from pathlib import Path

    from ecodrive_bench.bench.methods.external import interface_of

    doc = (Path(__file__).parents[3] / "docs" / "your-agent.md").read_text()
    code = re.search(r"```python\n(# myagents.py.*?)```", doc, re.S).group(1)
    monkeypatch.syspath_prepend(str(tmp_path))
    for i, interface in enumerate(("parameterized", "longitudinal", "discrete27")):
        (tmp_path / f"doc{i}.py").write_text(code.replace('action_interface = "parameterized"',
                                                          f'action_interface = "{interface}"', 1))
        factory = load_factory(f"doc{i}:make")
        assert interface_of(factory) == interface and interface_of(load_factory(f"doc{i}:Cruise")) == interface
    (tmp_path / "bare.py").write_text(code.replace('action_interface = "parameterized"', 'action_interface = "longitudinal"', 1)
                                      .replace("make.action_interface = Cruise.action_interface", ""))
    with pytest.raises(AgentError, match="set the factory's action_interface = 'longitudinal' too"):
        build("bare:make", None, None)


def test_the_documented_agent_runs_from_its_own_folder(tmp_path):
    """docs/your-agent.md's ``myagents.py`` in the folder ``ecodrive run`` is started from, as the
    console script (whose ``sys.path`` lacks the current folder), with no PYTHONPATH: it is found."""
    import os
    import re
    import subprocess
    from pathlib import Path

    doc = (Path(__file__).parents[3] / "docs" / "your-agent.md").read_text()
    (tmp_path / "myagents.py").write_text(re.search(r"```python\n(# myagents.py.*?)```", doc, re.S).group(1))
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    out = subprocess.run([str(Path(sys.executable).parent / "ecodrive"), "run", "--profile", "smoke", "--methods",
                          "baseline", "--signals", "coordinated", "--agent", "myagents:make", "--name", "cruise",
                          "--workers", "2", "--logs", "logs"], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=600)
    assert out.returncode == 0, out.stderr
    table = pd.read_parquet(tmp_path / "logs" / "smoke" / "results.parquet")
    assert sorted(set(table.method)) == ["baseline", "cruise"] and len(table) == 6


def test_an_agent_module_found_nowhere_names_the_folder_and_the_fix(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", list(sys.path))
    with pytest.raises(AgentError) as e:
        load_factory("myagents_nowhere:make")
    assert f"no module 'myagents_nowhere' in the current folder ({tmp_path})" in str(e.value)
    assert "run from the folder that holds myagents_nowhere.py" in str(e.value) and "PYTHONPATH" in str(e.value)
    (tmp_path / "myagents_here.py").write_text("def make(observation_space, action_space):\n    return None\n")
    sys.modules.pop("myagents_here", None)
    assert callable(load_factory("myagents_here:make"))  # from the current folder, as `python -m` finds it


def test_the_agents_identity_covers_its_whole_package(tmp_path, monkeypatch):
    """A change to any module of the agent's package, one the factory's module only imports
    included, changes the code's sha256; a lone module's identity is its own file."""
    import importlib
    import sys

    from ecodrive_bench.bench.methods.external import code_sha256

    pkg = tmp_path / "theiragents"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "helpers.py").write_text("GAIN = 0.5\n")
    (pkg / "agent.py").write_text(
        "import numpy as np\nfrom .helpers import GAIN\n\n\nclass A:\n    name = 'a'\n    action_interface = 'parameterized'\n"
        "    env_overrides = {}\n\n    def act(self, obs, info, explore=False):\n        return 1, np.full(3, GAIN, dtype=np.float32)\n\n\n"
        "def make(observation_space, action_space):\n    return A()\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    for m in ("theiragents", "theiragents.agent", "theiragents.helpers"):
        sys.modules.pop(m, None)
    agent = importlib.import_module("theiragents.agent").make(None, None)
    before = code_sha256("theiragents.agent:make", agent)
    (pkg / "helpers.py").write_text("GAIN = 0.6\n")  # only a module the agent imports
    assert code_sha256("theiragents.agent:make", agent) != before
