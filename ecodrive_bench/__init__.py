"""ecodrive-bench's import name. Its subpackages live in the repository's top-level folders
(``envs``, ``agents``, ``bench``, ``reports``, ``models``; pyproject.toml's ``package-dir`` maps
them), so ``import ecodrive_bench.envs`` works from an install and from a checkout alike."""
from pkgutil import extend_path

__path__ = extend_path(__path__, __name__)
