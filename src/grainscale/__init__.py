"""grainscale: 3D hierarchical multiscale MPM x DEM modelling of granular media."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("grainscale")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.1.0+src"

# the Python API (docs/api.md), imported on first use so that `import grainscale` and the
# command line stay light
_API = ("Case", "ConfigError", "Result", "RunError", "load_case", "open_result", "run")
__all__ = ["__version__", "rve", *_API]


def __getattr__(name: str):
    if name in _API:
        from grainscale import api

        return getattr(api, name)
    if name == "rve":  # grainscale.rve: the RVE alone (generate, element tests)
        import importlib

        return importlib.import_module("grainscale.rve")
    raise AttributeError(f"module 'grainscale' has no attribute {name!r}")
