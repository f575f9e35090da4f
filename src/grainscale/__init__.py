"""grainscale: 3D hierarchical multiscale MPM x DEM modelling of granular media."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("grainscale")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.1.0+src"

# the Python API (docs/api.md), imported on first use so that `import grainscale` and the
# command line stay light
_API = ("Case", "ConfigError", "Result", "RunError", "check", "load_case", "open_result",
        "run")
_MODULES = ("analysis", "blocks", "rve")  # grainscale.rve: the RVE alone; analysis:
# reading and measuring outputs; blocks: the solver's parts for hand-built studies
__all__ = ["__version__", *_MODULES, *_API]


def __getattr__(name: str):
    if name in _API:
        from grainscale import api

        return getattr(api, name)
    if name in _MODULES:
        import importlib

        return importlib.import_module(f"grainscale.{name}")
    raise AttributeError(f"module 'grainscale' has no attribute {name!r}")
