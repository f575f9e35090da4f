"""Shared machinery for case files: a strict base model and readable errors.

Every error names the key (dotted path in the TOML file), the value that was given and
what would have been valid, before any computation starts.
"""

from __future__ import annotations

import difflib
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import tomli_w
from pydantic import BaseModel, ConfigDict, PrivateAttr, ValidationError

from grainscale import __version__


class ConfigError(ValueError):
    """A case file, a parameter or a command-line value is invalid."""


class StrictModel(BaseModel):
    """Base of all case-file tables: unknown keys are errors, values are re-validated,
    also when assigned from Python, where an invalid value or an unknown key raises
    ConfigError with the key's dotted path in the case (`_path`), as a file's would."""

    model_config = ConfigDict(extra="forbid", validate_assignment=True, frozen=False)
    _path: str = PrivateAttr(default="")

    def model_post_init(self, context: Any) -> None:
        _label(self, self._path)

    def __setattr__(self, name: str, value: Any) -> None:
        if name.startswith("_"):
            return super().__setattr__(name, value)
        where = f"{self._path}.{name}" if self._path else name
        fields = {f.alias or n for n, f in type(self).model_fields.items()}
        if name not in fields:
            close = difflib.get_close_matches(name, sorted(fields), n=1, cutoff=0.6)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise ConfigError(f"{where}: unknown key; {hint}valid keys here: "
                              f"{', '.join(sorted(fields))}")
        try:
            super().__setattr__(name, value)
        except ValidationError as err:
            raise ConfigError(format_validation_error(err, prefix=self._path,
                                                      model=type(self))) from None
        _label(self, self._path)


def _label(model: BaseModel, path: str) -> None:
    """Give every table under `model` its dotted path in the case (for messages)."""
    for name in type(model).model_fields:
        value = getattr(model, name, None)
        key = f"{path}.{name}" if path else name
        items = (value.items() if isinstance(value, dict) else
                 ((f"[{i}]", v) for i, v in enumerate(value))
                 if isinstance(value, list) else [("", value)])
        for sub, v in items:
            if isinstance(v, StrictModel):
                here = key if not sub else (f"{key}{sub}" if sub.startswith("[")
                                            else f"{key}.{sub}")
                object.__setattr__(v, "__pydantic_private__",
                                   {**(v.__pydantic_private__ or {}), "_path": here})
                _label(v, here)


M = TypeVar("M", bound=BaseModel)


def _strip(annotation):
    """The type inside Annotated[...] and Optional[...] (None removed from a union)."""
    while typing.get_origin(annotation) is typing.Annotated:
        annotation = typing.get_args(annotation)[0]
    if typing.get_origin(annotation) in (typing.Union, types.UnionType):
        members = [a for a in typing.get_args(annotation) if a is not type(None)]
        if len(members) == 1:
            return _strip(members[0])
    return annotation


def _is_model(t) -> bool:
    return isinstance(t, type) and issubclass(t, BaseModel)


def _tagged(union, tag):
    """The member of a tagged union of models whose Literal field holds `tag`."""
    for member in typing.get_args(union):
        member = _strip(member)
        if _is_model(member) and any(
                tag in typing.get_args(_strip(f.annotation))
                for f in member.model_fields.values()
                if typing.get_origin(_strip(f.annotation)) is typing.Literal):
            return member
    return None


def _walk(model, loc: tuple[Any, ...]):
    """The key as the user writes it (pydantic's location with the tags of tagged unions
    left out), the model holding the last item (None where the walk got lost) and the
    type at the end of the location."""
    parts, cur, parent = [], model, None
    for item in loc:
        cur = _strip(cur)
        if _is_model(cur) and isinstance(item, str):
            fields = {f.alias or n: f for n, f in cur.model_fields.items()}
            parent = cur
            parts.append(item)
            cur = fields[item].annotation if item in fields else None
        elif isinstance(item, int):
            parts.append(f"[{item}]")
            args = typing.get_args(cur)
            cur = args[0] if args else None
            parent = None
        elif typing.get_origin(cur) is dict:
            parts.append(str(item))
            cur = typing.get_args(cur)[1]
            parent = None
        elif typing.get_origin(cur) in (typing.Union, types.UnionType):
            member = _tagged(cur, item)
            if member is None:  # not a tag: pydantic's own segment, e.g. a validator's
                parts.append(str(item))
            cur = member
        else:
            parts.append(str(item))
            cur, parent = None, None
    return ".".join(parts).replace(".[", "["), parent, cur


def _message(e: dict, parent, end) -> str:
    """The reason of one pydantic error, in the case file's words."""
    kind = e["type"]
    if kind == "missing":
        return "required key is missing"
    if kind == "extra_forbidden":
        unknown = str(e["loc"][-1])
        hint = ""
        if parent is not None:
            valid = sorted(f.alias or n for n, f in parent.model_fields.items())
            close = difflib.get_close_matches(unknown, valid, n=1, cutoff=0.6)
            hint = (f"did you mean {close[0]!r}? " if close else "") + \
                f"valid keys here: {', '.join(valid)}"
        return f"unknown key; {hint or 'see docs/case-files.md for valid keys'}"
    if kind in ("tuple_type", "too_short", "too_long") and \
            typing.get_origin(_strip(end)) is tuple:
        n = len(typing.get_args(_strip(end)))
        return f"expected a list of {n} values, e.g. [{', '.join(['0.0'] * n)}]"
    msg = e["msg"]
    for prefix in ("Value error, ", "Assertion failed, "):
        if msg.startswith(prefix):
            msg = msg[len(prefix):]
    return msg


def format_validation_error(err: ValidationError, source: str = "", prefix: str = "",
                            model=None) -> str:
    """One line per problem: `key = value: reason`, the key as the file writes it (with
    `model`, the validated class: tagged unions' tags left out, and unknown keys get the
    valid ones and the nearest match)."""
    lines = []
    for e in err.errors():
        loc = e["loc"]
        key, parent, end = _walk(model, loc) if model is not None else (None, None, None)
        if key is None:
            key = ".".join(f"[{i}]" if isinstance(i, int) else str(i) for i in loc)
            key = key.replace(".[", "[")
        if prefix:
            key = f"{prefix}.{key}" if key else prefix
        if e["type"] == "extra_forbidden" and model is not None:
            parent = _walk(model, loc[:-1])[2]
            parent = _strip(parent) if parent is not None else None
            parent = parent if _is_model(parent) else None
        value = e.get("input")
        shown = ("" if e["type"] == "missing" or isinstance(value, (dict, BaseModel))
                 else f" = {value!r}")
        lines.append(f"  {key}{shown}: {_message(e, parent, end)}")
    head = f"invalid input in {source}:" if source else "invalid input:"
    return "\n".join([head, *lines])


def validate(model: type[M], data: dict[str, Any], source: str = "", prefix: str = "") -> M:
    """Validate a dict against `model`, raising ConfigError with readable messages."""
    try:
        return model.model_validate(data)
    except ValidationError as err:
        raise ConfigError(format_validation_error(err, source, prefix, model)) from None


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
