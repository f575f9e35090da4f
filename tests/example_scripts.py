"""Load a script under examples/ as a module, so that tests can call its functions."""

import importlib.util
from pathlib import Path
from types import ModuleType

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def load_example(relpath: str) -> ModuleType:
    """examples/<relpath> (e.g. "intrusion/analyse.py") imported under its stem."""
    path = EXAMPLES / relpath
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
