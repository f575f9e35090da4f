"""grainscale: 3D hierarchical multiscale MPM x DEM modelling of granular media."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("grainscale")
except PackageNotFoundError:  # running from a source tree without install
    __version__ = "0.1.0+src"
