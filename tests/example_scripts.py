"""Load a script under examples/ or studies/ as a module, so that tests can call its
functions."""

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
STUDIES = EXAMPLES.parent / "studies"


def load_example(relpath: str, root: Path | None = None) -> ModuleType:
    """examples/<relpath> or, where examples/ has none, studies/<relpath> (e.g.
    "intrusion/analyse.py"; or root/<relpath>) imported under its stem, its folder on
    sys.path as when it runs as a script (so that it finds its siblings)."""
    if root is None:
        root = EXAMPLES if (EXAMPLES / relpath).is_file() else STUDIES
    path = root / relpath
    if str(path.parent) not in sys.path:
        sys.path.insert(0, str(path.parent))
    spec = importlib.util.spec_from_file_location(path.stem, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod
