"""docs/case-files.md lists every key of every table: each field of the case models
(config/case.py, config/rve.py), walked recursively, appears in its TOML listing as
`key = ...` (commented or not) or as a table name."""

import re
import typing
from pathlib import Path

from pydantic import BaseModel

from grainscale.config.case import Case

DOC = Path(__file__).resolve().parents[1] / "docs" / "case-files.md"


def _models(annotation) -> list[type[BaseModel]]:
    """The pydantic models inside a field's annotation (Optional, list, dict, Union)."""
    if typing.get_origin(annotation) is None:
        ok = isinstance(annotation, type) and issubclass(annotation, BaseModel)
        return [annotation] if ok else []
    return [m for a in typing.get_args(annotation) for m in _models(a)]


def _keys(model, path: str, seen: set) -> list[tuple[str, str]]:
    if model in seen:
        return []
    seen.add(model)
    out = []
    for name, field in model.model_fields.items():
        key = field.alias or name
        out.append((f"{path}.{key}", key))
        for sub in _models(field.annotation):
            out += _keys(sub, f"{path}.{key}", seen)
    return out


def test_every_key_of_every_table_is_listed():
    listing = "\n".join(re.findall(r"```toml\n(.*?)```", DOC.read_text(), re.S))
    keys = _keys(Case, "case", set())
    assert len(keys) > 150  # the walk reached the nested tables
    missing = [path for path, key in keys
               if not re.search(rf"(^|[#\s{{,]){re.escape(key)}\s*=", listing, re.M)
               and not re.search(rf"\[[\w.]*\b{re.escape(key)}\b[\w.]*\]", listing)]
    assert not missing, f"docs/case-files.md lists no {missing}"
