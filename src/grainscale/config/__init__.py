"""Typed case files: pydantic models of every TOML table, strict about unknown keys."""

from grainscale.config.base import ConfigError, StrictModel, load_toml, resolved_toml

__all__ = ["ConfigError", "StrictModel", "load_toml", "resolved_toml"]
