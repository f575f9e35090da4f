"""The public surface (docs/api.md): what users' scripts may import, and its docs.

Issue 34's rules: no script under examples/ or studies/ (nor the tour notebook) imports
a module outside the public ones, every public name is documented in docs/api.md, and
every folder of examples/ has a README."""

import ast
import json
import re
from pathlib import Path

import pytest

import grainscale

ROOT = Path(__file__).resolve().parents[1]
PUBLIC = {"grainscale": grainscale.__all__}
for _name in ("analysis", "blocks", "rve"):
    _mod = getattr(grainscale, _name)
    PUBLIC[f"grainscale.{_name}"] = _mod.__all__
SCRIPTS = sorted([*(ROOT / "examples").rglob("*.py"), *(ROOT / "studies").rglob("*.py")])
NOTEBOOKS = sorted((ROOT / "examples").rglob("*.ipynb"))


def grainscale_imports(source: str) -> list[tuple[str, str | None]]:
    """(module, name) for every import of grainscale or a submodule in `source`."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(a.name, None) for a in node.names if a.name.split(".")[0] == "grainscale"]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module and \
                node.module.split(".")[0] == "grainscale":
            found += [(node.module, a.name) for a in node.names]
    return found


def private_imports(source: str) -> list[str]:
    bad = []
    for module, name in grainscale_imports(source):
        if module not in PUBLIC:
            bad.append(module)
        elif name is not None and name not in PUBLIC[module]:
            bad.append(f"{module}.{name}")
    return bad


def test_the_check_sees_a_private_import():
    assert private_imports("from grainscale.io.vtk import read_points_vtu") == ["grainscale.io.vtk"]
    assert private_imports("import grainscale.mpm.step as s") == ["grainscale.mpm.step"]
    assert private_imports("from grainscale import api") == ["grainscale.api"]
    assert private_imports("import grainscale as gs\nfrom grainscale import rve, blocks\n"
                           "from grainscale.analysis import k_phi") == []


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_scripts_import_only_the_public_api(path):
    assert private_imports(path.read_text()) == []


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: str(p.relative_to(ROOT)))
def test_notebooks_import_only_the_public_api(path):
    cells = json.loads(path.read_text())["cells"]
    code = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")
    assert private_imports(code) == []


def test_every_public_name_is_documented():
    text = (ROOT / "docs" / "api.md").read_text()
    missing = [f"{module}.{name}" for module, names in PUBLIC.items() for name in names
               if name != "__version__" and not re.search(rf"\b{re.escape(name)}\b", text)]
    assert missing == []


def test_every_examples_folder_has_a_readme():
    folders = [p for p in (ROOT / "examples").iterdir() if p.is_dir()
               and not p.name.startswith((".", "_")) and p.name != "tour_out"]
    assert folders and [p.name for p in folders if not (p / "README.md").is_file()] == []
