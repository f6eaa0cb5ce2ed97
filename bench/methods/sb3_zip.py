"""Reading a Stable-Baselines3 model ``.zip`` without running code from it.

Files from elsewhere are data, not code. An SB3 zip holds ``data`` (JSON; what JSON cannot hold is
cloudpickled, base64, under a ``":serialized:"`` key), the weights as ``*.pth`` (``torch.save``)
and version files. SB3's own ``Algo.load`` unpickles every serialized entry with cloudpickle, and
unpickling calls whatever the pickle names: a model file from elsewhere could run code on load.

``read`` opens the zip itself (once, into memory: SB3 later reads these very bytes; a regular file
of at most ``MAX_ZIP_BYTES``, checked before it is read) and

- decodes only ``observation_space``, ``action_space``, ``policy_class`` and ``policy_kwargs``,
  with ``SafeUnpickler``, which resolves only the names on an allow list (gymnasium spaces, the
  numpy helpers that rebuild arrays, dtypes and random generators, torch activation and optimizer
  classes, SB3 policy and feature-extractor classes, a few builtins) and refuses any other before
  anything is called;
- replaces every other serialized entry, unread, by a constant (``custom_objects`` for SB3's load;
  SB3 skips the entries named there), so SB3 unpickles nothing itself. They are the training
  state: schedules (lambdas, i.e. code), the last rollout's observations, noise objects, buffers.

The weights are read by SB3's ``load_from_zip_file`` with ``torch.load(weights_only=True)``
(checked in SB3 2.9.2), torch's own restricted unpickler.

What this cannot do: an allowed class is still called with the file's arguments (a ``Box``, a
``ReLU``, a policy), so a hostile file can build such objects (say, a huge ``net_arch`` that eats
memory) but not run code of its own. A model whose ``policy_kwargs`` name a class of the user's
(a custom feature extractor) is refused: that class is code. The classes allowed by rule are
looked up only in modules already imported (nothing is imported on the file's behalf but the
numpy modules of the fixed list). Old zips whose spaces are ``gym`` (not gymnasium) spaces are
refused.
"""
from __future__ import annotations

import base64
import binascii
import hashlib
import io
import json
import pickle
import sys
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ecodrive_bench.bench.args import InputError, read_regular

DECODED = ("observation_space", "action_space", "policy_class", "policy_kwargs")
# [bytes] largest --sb3 zip read (into memory, once): SB3 zips of policies for this env's observation
# are well under 10 MiB (weights and optimizer state); 256 MiB leaves room for wide networks
MAX_ZIP_BYTES = 256 * 2**20
MAX_DATA_BYTES = 64 * 2**20  # the JSON ``data`` entry; SB3's own are tens of kB
# constants for the serialized entries that are never decoded (None for any other)
CONSTANTS: dict[str, Any] = {"learning_rate": 0.0, "clip_range": 0.0, "train_freq": 1, "target_entropy": 0.0}
# JSON entries replaced when present: no replay memory for a model that only acts; no env (SB3
# would gym.make an "env" string, importing the module a "module:Env-v0" id names); the CPU
OVERRIDES: dict[str, Any] = {"buffer_size": 1, "env": None, "device": "cpu"}

ALLOWED: dict[str, frozenset[str]] = {k: frozenset(v) for k, v in {
    "builtins": ("set", "frozenset"),
    "collections": ("OrderedDict",),
    "copyreg": ("_reconstructor",),
    "numpy": ("dtype", "ndarray"),
    "numpy._core.multiarray": ("_reconstruct", "scalar"),
    "numpy.core.multiarray": ("_reconstruct", "scalar"),
    "numpy._core.numeric": ("_frombuffer",),
    "numpy.core.numeric": ("_frombuffer",),
    "numpy.random._pickle": ("__generator_ctor", "__bit_generator_ctor", "__randomstate_ctor"),
    "numpy.random.bit_generator": ("SeedSequence", "__pyx_unpickle_SeedSequence"),
    "numpy.random._pcg64": ("PCG64", "PCG64DXSM"),
    "numpy.random._mt19937": ("MT19937",),
    "numpy.random._philox": ("Philox",),
    "numpy.random._sfc64": ("SFC64",),
    "numpy.random._generator": ("Generator",),
    "numpy.random.mtrand": ("RandomState",),
}.items()}
ALLOWED_KINDS = "gymnasium spaces, numpy arrays and dtypes, torch activations and optimizers, SB3 policies"


class ZipError(ValueError):
    """An SB3 zip that cannot be used; one line."""


class Refused(pickle.UnpicklingError):
    """A pickle naming something off the allow list."""


def _class_rules() -> list[tuple[str, tuple[type, ...]]]:
    """(module prefix, base classes): a class from a module under the prefix that subclasses one of
    the bases is allowed."""
    import gymnasium
    import numpy as np
    import torch
    from stable_baselines3.common.policies import BasePolicy
    from stable_baselines3.common.torch_layers import BaseFeaturesExtractor

    return [("gymnasium.spaces.", (gymnasium.spaces.Space,)), ("torch.nn.modules.activation", (torch.nn.Module,)),
            ("torch.optim.", (torch.optim.Optimizer,)), ("numpy.dtypes", (np.dtype,)),
            ("stable_baselines3.", (BasePolicy, BaseFeaturesExtractor))]


class SafeUnpickler(pickle.Unpickler):
    """Resolves only allowed names (``ALLOWED`` and the class rules); anything else is ``Refused``
    before it is called. Persistent ids are refused by ``pickle.Unpickler`` itself."""

    rules: list[tuple[str, tuple[type, ...]]] = []

    def find_class(self, module: str, name: str) -> Any:
        if name in ALLOWED.get(module, ()):
            return getattr(sys.modules.get(module) or __import__(module, fromlist=[name]), name)
        mod = sys.modules.get(module)  # only modules already imported: nothing runs on the file's behalf
        if mod is not None and name.isidentifier():
            obj = getattr(mod, name, None)
            for prefix, bases in self.rules:  # "a.b.": any module under a.b; "a.b": that module
                under = module.startswith(prefix) if prefix.endswith(".") else module == prefix
                if under and isinstance(obj, type) and issubclass(obj, bases) and obj.__module__ == module:
                    return obj
        raise Refused(f"{module}.{name}")


def safe_loads(blob: bytes) -> Any:
    if not SafeUnpickler.rules:
        SafeUnpickler.rules = _class_rules()
    return SafeUnpickler(io.BytesIO(blob)).load()


@dataclass
class Saved:
    """What ``read`` got from a zip: its bytes and the decoded entries."""

    path: Path
    blob: bytes
    sha256: str
    observation_space: Any
    action_space: Any
    policy_class: type
    custom_objects: dict[str, Any] = field(default_factory=dict)  # for SB3's load: every serialized entry


def read(path: Path) -> Saved:
    """The zip at ``path``, its decodable entries decoded safely; ``ZipError`` (one line) for a
    file that is missing, not a regular file, larger than ``MAX_ZIP_BYTES``, not a zip, without
    ``data``, or with a refused or undecodable entry."""
    try:  # a regular file of at most MAX_ZIP_BYTES, checked before it is read (not /dev/zero, a FIFO)
        blob = read_regular(Path(path), f"--sb3 {str(path)!r}", MAX_ZIP_BYTES, "zip file", "cannot read it")
    except InputError as e:
        raise ZipError(f"{e}; expected a model saved by Stable-Baselines3's model.save()") from None
    from gymnasium import spaces
    from stable_baselines3.common.policies import BasePolicy

    try:
        with zipfile.ZipFile(io.BytesIO(blob)) as archive:
            info = archive.getinfo("data")
            if info.file_size > MAX_DATA_BYTES:
                raise ZipError(f"--sb3 {str(path)!r}: its 'data' entry is {info.file_size} bytes; accepted: "
                               f"up to {MAX_DATA_BYTES}")
            text = archive.read(info).decode()
    except zipfile.BadZipFile:
        raise ZipError(f"--sb3 {str(path)!r} is not a zip file; expected a model saved by Stable-Baselines3's "
                       f"model.save()") from None
    except KeyError:
        raise ZipError(f"--sb3 {str(path)!r} has no 'data' entry; expected a model saved by Stable-Baselines3's "
                       f"model.save()") from None
    except (UnicodeDecodeError, RuntimeError, OSError, EOFError) as e:  # RuntimeError: encrypted entries
        raise ZipError(f"--sb3 {str(path)!r}: its 'data' entry is unreadable ({type(e).__name__})") from None
    try:
        data = json.loads(text)
    except ValueError:
        data = None
    if not isinstance(data, dict):
        raise ZipError(f"--sb3 {str(path)!r}: its 'data' entry is not a JSON object, as SB3 writes it")
    decoded, custom = {}, {}
    for key, item in data.items():
        if isinstance(item, dict) and ":serialized:" in item:
            if key in DECODED:
                decoded[key] = custom[key] = _decode(path, key, item[":serialized:"])
            else:
                custom[key] = CONSTANTS.get(key)  # never decoded: SB3 takes the constant instead
        elif key in DECODED:
            decoded[key] = item
    custom.update({k: _override(k) for k in OVERRIDES if k in data})
    missing = [k for k in DECODED[:3] if k not in decoded]
    if missing:
        raise ZipError(f"--sb3 {str(path)!r}: its 'data' lacks {', '.join(missing)}; expected a model saved by "
                       f"Stable-Baselines3's model.save()")
    obs, act, cls = decoded["observation_space"], decoded["action_space"], decoded["policy_class"]
    if not isinstance(obs, spaces.Space) or not isinstance(act, spaces.Space):
        raise ZipError(f"--sb3 {str(path)!r}: its observation_space and action_space are not gymnasium spaces")
    if not (isinstance(cls, type) and issubclass(cls, BasePolicy)):
        raise ZipError(f"--sb3 {str(path)!r}: its policy_class {cls!r} is not a Stable-Baselines3 policy class")
    if not isinstance(decoded.get("policy_kwargs", {}), dict):
        raise ZipError(f"--sb3 {str(path)!r}: its policy_kwargs is not a dict")
    return Saved(Path(path), blob, hashlib.sha256(blob).hexdigest(), obs, act, cls, custom)


def _override(key: str) -> Any:
    if key == "device":
        import torch

        return torch.device("cpu")
    return OVERRIDES[key]


def _decode(path: Path, key: str, text: Any) -> Any:
    try:
        return safe_loads(base64.b64decode(str(text), validate=True))
    except Refused as e:
        raise ZipError(f"--sb3 {str(path)!r}: data[{key!r}] names {e}, which a model file may not "
                       f"(accepted: {ALLOWED_KINDS}); refused without running it") from None
    except (binascii.Error, pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError,
            IndexError, KeyError, MemoryError, RecursionError) as e:
        raise ZipError(f"--sb3 {str(path)!r}: data[{key!r}] cannot be decoded ({type(e).__name__})") from None
