"""Shipped policies: ``models/<method>-<signals>/s<seed>/`` holds one training seed's
``policy.pt``, ``manifest.json`` and per-episode ``metrics.parquet``; a method and setting ships
every seed found there.

Loading checks the file's sha256 against the manifest, the method and scenario config against
what the caller expects, and, in that layout, the manifest's method, signals and training seed
against the folder's (``check_folder``); anything else is a ``CheckpointError`` naming the file.
"""
from __future__ import annotations

import json
import pickle
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ecodrive_bench.bench.io import atomic_json, atomic_torch_save, sha256

if TYPE_CHECKING:
    from ecodrive_bench.envs.config import ScenarioConfig

MODELS = Path(__file__).resolve().parents[2] / "models"


class CheckpointError(RuntimeError):
    pass


def load_torch(path: Path) -> Any:
    """A torch file read as data (``weights_only=True``): tensors and plain Python containers
    only. A pickle that names any other global (a planted ``__reduce__`` payload, say) is a
    ``CheckpointError``, and nothing in it runs."""
    import torch  # here, not at the top: the folders and errors of this module cost no torch import

    try:
        with warnings.catch_warnings():  # a raw pickle (no torch zip) warns of its protocol before it is refused
            warnings.filterwarnings("ignore", message="Detected pickle protocol", category=UserWarning)
            return torch.load(path, map_location="cpu", weights_only=True)
    except pickle.UnpicklingError as e:
        why = next((ln.strip().rstrip(".") for ln in str(e).splitlines() if "GLOBAL" in ln), "not plain data")
        raise CheckpointError(f"{path}: refused, it holds more than tensors and plain data ({why}); "
                              f"policies and checkpoints are loaded as data, never as code") from None
    except Exception as e:
        raise CheckpointError(f"{path}: cannot be loaded ({type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''})") from None


def family_dir(method: str, signals: str, root: Path = MODELS) -> Path:
    """The folder of every shipped training seed of a method and setting."""
    return root / f"{method}-{signals}"


def policy_dir(method: str, signals: str, root: Path = MODELS, seed: int = 0) -> Path:
    """One training seed's policy folder (seed 0 by default: the one the single-policy experiments
    drive, e.g. the CVs of mixed traffic)."""
    return family_dir(method, signals, root) / f"s{seed}"


def shipped_seeds(method: str, signals: str, root: Path = MODELS) -> list[int]:
    """Training seeds with a policy (a manifest) for ``method`` and ``signals``, ascending."""
    folder = family_dir(method, signals, root)
    if not folder.is_dir():
        return []
    return sorted(int(d.name[1:]) for d in folder.iterdir()
                  if d.name[:1] == "s" and d.name[1:].isdigit() and (d / "manifest.json").is_file())


def save_policy(folder: Path, state: dict[str, Any], manifest: dict[str, Any]) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "policy.pt"
    atomic_torch_save(state, path)
    manifest = {**manifest, "file": path.name, "sha256": sha256(path)}
    atomic_json(manifest, folder / "manifest.json", sort_keys=True)
    return path


def load_policy(folder: Path, method: str, scenario: dict[str, Any] | None = None,
                transfer: bool = False) -> tuple[dict, dict]:
    """(state, manifest) of a shipped policy, verified. Given the ``scenario`` (config dict) it is
    to drive, the policy must have been trained on it, or (``transfer``) be able to observe it
    (``transfer_overrides``)."""
    man_path, path = folder / "manifest.json", folder / "policy.pt"
    if not man_path.is_file() or not path.is_file():
        raise CheckpointError(f"{folder}: no trained policy (expected policy.pt and manifest.json); "
                              f"train one with the command in the README")
    manifest = read_manifest(folder)
    digest = sha256(path)
    if manifest.get("sha256") != digest:
        raise CheckpointError(f"{path}: sha256 {digest[:12]}... does not match the manifest's "
                              f"{str(manifest.get('sha256'))[:12]}...: the file is corrupt or was replaced")
    if manifest.get("method") != method:
        raise CheckpointError(f"{path}: policy is for method {manifest.get('method')!r}, not {method!r}")
    check_folder(folder, manifest)
    state = load_torch(path)
    if scenario is not None:
        check_scenario(folder, manifest, scenario, transfer)
    return state, manifest


def policy_agent(folder: Path, method: str, spaces: tuple[Any, Any], manifest: dict[str, Any],
                 state: Any, **overrides: Any) -> Any:
    """A fresh ``method`` agent on ``spaces`` (observation, action), built with the
    ``agent_config`` the policy was trained with (``overrides`` on top) and holding its ``state``
    (from ``load_policy``), to act: its replay buffer holds one batch (``acting_config``), not the
    training run's hundreds of thousands of transitions, and its greedy acts do not re-check the
    weights for edits (``freeze``; an update or a load ends that). A config or a state the agent does not
    accept is a ``CheckpointError`` naming the file: plain data of the wrong structure passes
    ``load_torch`` but not this."""
    from ecodrive_bench.agents.registry import make_agent
    from ecodrive_bench.bench import registry

    config = manifest.get("agent_config") or {}
    try:  # an experiment's policy (ecodrive train --set) is built with the config it trained with
        agent = make_agent(registry.algorithm(method), *spaces, **{**acting_config(config), **overrides})
    except (TypeError, ValueError) as e:
        raise CheckpointError(f"{folder / 'manifest.json'}: agent_config {config!r} not accepted ({e})") from None
    try:
        agent.load_state_dict(state)
    except Exception as e:  # the agents' and torch's errors for a wrong structure have no common base
        why = " ".join(str(e).split())[:300]
        raise CheckpointError(f"{folder / 'policy.pt'}: not the state of a {method} agent ({type(e).__name__}: {why}); "
                              f"expected a policy saved by ecodrive train --method {method}") from None
    bad = _non_finite(state)
    if bad:  # a diverged training's weights: no action they give means anything
        raise CheckpointError(f"{folder / 'policy.pt'}: non-finite weights in {', '.join(bad[:3])}; a policy must hold "
                              f"finite numbers (retrain it)")
    freeze = getattr(agent, "freeze", None)  # the learning agents: act on these weights without re-checking them
    if freeze is not None:
        freeze()
    return agent


def _non_finite(state: Any, where: str = "") -> list[str]:
    """Paths of the floating-point tensors in ``state`` (nested dicts, lists) holding NaN or inf."""
    import torch

    if isinstance(state, dict):
        return [p for k, v in state.items() for p in _non_finite(v, f"{where}.{k}" if where else str(k))]
    if isinstance(state, (list, tuple)):
        return [p for i, v in enumerate(state) for p in _non_finite(v, f"{where}[{i}]")]
    if isinstance(state, torch.Tensor) and state.is_floating_point() and not bool(torch.isfinite(state).all()):
        return [where]
    return []


def acting_config(config: Any) -> dict[str, Any]:
    """``config`` (a policy's ``agent_config``) for an agent that only acts: the replay buffer cut
    to one batch (acting never fills it; at the learners' default of 500 000 transitions it would
    take some 300 MB a policy). Anything not a dict is passed on for ``make_agent`` to refuse."""
    if not isinstance(config, dict):
        return config
    batch = config.get("batch_size", 1)
    batch = batch if type(batch) is int and batch >= 1 else 1  # a bad value: make_agent names it below
    return {**config, "batch_size": config.get("batch_size", batch), "replay_size": batch}


def check_policy(folder: Path, method: str) -> None:
    """Refuse, before anything runs, a policy that could not drive: ``load_policy``'s checks, then
    its state loaded into a fresh agent on the spaces it was trained with. The episodes' workers
    load it again; this is the parent's check, so a bad file is one error before any folder is
    written."""
    import torch

    state, manifest = load_policy(folder, method)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # a few small networks: threads only contend
    try:
        policy_agent(folder, method, policy_spaces(folder, manifest), manifest, state)
    finally:
        torch.set_num_threads(threads)


def check_folder(folder: Path, manifest: dict[str, Any]) -> None:
    """A policy in the shipped layout, ``<method>-<signals>/s<seed>/``, must be the one its folder
    names: the manifest's ``method``, ``signals`` (or its scenario's) and training ``seed`` must be
    the folder's, or its episodes would be labelled with another policy's method, setting or seed.
    A folder outside that layout (a training run's export, a copy for a test) names nothing and
    is not compared; a manifest without one of the fields is compared on the others."""
    from ecodrive_bench.envs.config import SIGNALS

    where = folder / "manifest.json"
    family, _, signals = folder.parent.name.rpartition("-")
    if folder.name[:1] == "s" and folder.name[1:].isdigit() and "seed" in manifest:
        seed = manifest["seed"]
        if type(seed) is not int or seed != int(folder.name[1:]):
            raise CheckpointError(f"{where}: training seed {seed!r}, but the folder {folder.name} is seed "
                                  f"{int(folder.name[1:])}; a policy lives in <method>-<signals>/s<seed>/ of its "
                                  f"own training{_home(folder, manifest)}")
    if family and signals in SIGNALS:
        trained = manifest.get("signals", manifest.get("scenario", {}).get("signals")
                               if isinstance(manifest.get("scenario"), dict) else None)
        if trained is not None and trained != signals:
            raise CheckpointError(f"{where}: trained on signals {trained!r}, but the folder {folder.parent.name} is "
                                  f"{signals!r}; a policy lives in <method>-<signals>/s<seed>/ of its own "
                                  f"training{_home(folder, manifest)}")
        if manifest.get("method") != family:
            raise CheckpointError(f"{where}: a policy of method {manifest.get('method')!r}, but the folder "
                                  f"{folder.parent.name} is method {family!r}; a policy lives in "
                                  f"<method>-<signals>/s<seed>/ of its own training{_home(folder, manifest)}")


def _home(folder: Path, manifest: dict[str, Any]) -> str:
    """Where a misplaced policy belongs, from its manifest ('' if the manifest cannot say)."""
    method, signals, seed = manifest.get("method"), manifest.get("signals"), manifest.get("seed")
    if isinstance(method, str) and isinstance(signals, str) and type(seed) is int:
        return f" (this one belongs in {folder.parent.parent / f'{method}-{signals}' / f's{seed}'})"
    return ""


def read_manifest(folder: Path) -> dict[str, Any]:
    man_path = folder / "manifest.json"
    try:
        manifest = json.loads(man_path.read_text())
    except (OSError, json.JSONDecodeError, UnicodeDecodeError) as e:
        raise CheckpointError(f"{man_path}: manifest is not valid JSON ({e})") from None
    if not isinstance(manifest, dict):
        raise CheckpointError(f"{man_path}: manifest is a JSON {type(manifest).__name__}, expected an object")
    return manifest


def trained_scenario(folder: Path, manifest: dict[str, Any]) -> ScenarioConfig:
    """The scenario the policy was trained on; fields added later read as their absence meant."""
    from ecodrive_bench.envs.config import ConfigError, ScenarioConfig, backfill

    try:
        return ScenarioConfig.from_dict(backfill(manifest.get("scenario", {})))
    except ConfigError as e:
        raise CheckpointError(f"{folder / 'manifest.json'}: scenario config not accepted ({e})") from None


def policy_spaces(folder: Path, manifest: dict[str, Any]) -> tuple[Any, Any]:
    """(observation space, action space) the policy was trained with, from its manifest."""
    from ecodrive_bench.bench import registry
    from ecodrive_bench.envs.action import make_action
    from ecodrive_bench.envs.observation import observation_space

    cfg = trained_scenario(folder, manifest)
    return observation_space(cfg), make_action(registry.interface(manifest["method"]), cfg).space


def check_scenario(folder: Path, manifest: dict[str, Any], scenario: dict[str, Any], transfer: bool = False) -> dict:
    """The scenario overrides the policy needs to drive ``scenario``: {} or the ``obs_lanes`` it
    was trained with. Without ``transfer`` it must be the scenario it was trained on (the signals,
    the GLOSA device and the reward aside); with it, any scenario it can observe
    (``transfer_overrides``)."""
    from ecodrive_bench.envs.config import diff

    trained = trained_scenario(folder, manifest)
    if not transfer:
        # the reward is what the policy was trained for, not what it sees or drives in: not compared;
        # nor is the observation's lane count, which follows the policy (below)
        differs = sorted({k.split(".")[0] for k in diff(manifest.get("scenario", {}), scenario)}
                         - {"signals", "glosa", "reward", "obs_lanes"})
        if differs:
            raise CheckpointError(f"{folder / 'policy.pt'}: trained on a different scenario config (differs in: "
                                  f"{', '.join(differs)}); to evaluate it there anyway, give --transfer")
    return transfer_overrides(folder, trained, scenario)


def transfer_overrides(folder: Path, trained: ScenarioConfig, scenario: dict[str, Any]) -> dict:
    """What a policy trained on ``trained`` needs to observe ``scenario``: its observation shape
    is fixed by training, so the road may have fewer lanes (``obs_lanes`` = the lanes it observed,
    the others padded as occupied) but the grid must have the same cells."""
    from ecodrive_bench.envs.config import ConfigError, ScenarioConfig

    try:
        target = ScenarioConfig.from_dict({**scenario, "obs_lanes": None})
    except ConfigError as e:
        raise CheckpointError(f"scenario not accepted ({e})") from None
    need, given = trained.observed_lanes, scenario.get("obs_lanes")
    where = f"{folder / 'policy.pt'}: cannot drive this scenario:"
    if target.lanes > need:
        raise CheckpointError(f"{where} it observes {need} lanes and the road has {target.lanes} (accepted: 1..{need})")
    if given is not None and given != need:
        raise CheckpointError(f"{where} it observes {need} lanes, not obs_lanes={given}")
    if target.grid_shape[0] != trained.grid_shape[0]:
        raise CheckpointError(f"{where} its grid has {trained.grid_shape[0]} cells along the road, this one "
                              f"{target.grid_shape[0]} (grid_ahead, grid_behind, cell_length)")
    return {} if need == target.lanes else {"obs_lanes": need}
