"""Shared machinery for case files: a strict base model and readable errors.

Every error names the key (dotted path in the TOML file), the value that was given and
what would have been valid, before any computation starts.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, TypeVar

import tomli_w
from pydantic import BaseModel, ConfigDict, ValidationError

from grainscale import __version__


class ConfigError(ValueError):
    """A case file, a parameter or a command-line value is invalid."""


class StrictModel(BaseModel):
    """Base of all case-file tables: unknown keys are errors, values are re-validated."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False)


M = TypeVar("M", bound=BaseModel)


def _fmt_key(loc: tuple[Any, ...], prefix: str) -> str:
    parts = [prefix] if prefix else []
    for item in loc:
        parts.append(f"[{item}]" if isinstance(item, int) else str(item))
    return ".".join(parts).replace(".[", "[")


def format_validation_error(err: ValidationError, source: str = "", prefix: str = "") -> str:
    """One line per problem: `key = value: reason`."""
    lines = []
    for e in err.errors():
        key = _fmt_key(e["loc"], prefix)
        msg = e["msg"]
        if e["type"] == "extra_forbidden":
            msg = "unknown key (check the spelling; see docs/case-files.md for valid keys)"
        value = e.get("input")
        shown = "" if e["type"] == "missing" else f" = {value!r}"
        if e["type"] == "missing":
            msg = "required key is missing"
        lines.append(f"  {key}{shown}: {msg}")
    head = f"invalid input in {source}:" if source else "invalid input:"
    return "\n".join([head, *lines])


def validate(model: type[M], data: dict[str, Any], source: str = "", prefix: str = "") -> M:
    """Validate a dict against `model`, raising ConfigError with readable messages."""
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise ConfigError(format_validation_error(err, source, prefix)) from None


def read_toml(path: str | Path) -> dict[str, Any]:
    """The tables of a TOML file; ConfigError if it is missing or not TOML."""
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"case file {str(path)!r} does not exist")
    try:
        return tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: not valid TOML: {err}") from None


def load_toml(path: str | Path, model: type[M]) -> M:
    """Read and validate a TOML case file."""
    return validate(model, read_toml(path), source=str(path))


def resolved_toml(model: BaseModel) -> str:
    """The model with every default filled in, plus the package version, as TOML text."""
    data = model.model_dump(mode="json", exclude_none=True)
    header = f"# resolved by grainscale {__version__}: every default filled in\n"
    return header + tomli_w.dumps({"grainscale_version": __version__, **data})
