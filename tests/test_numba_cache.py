"""The test run's numba cache is keyed on the package's sources (tests/conftest.py), so a
kernel whose callee was edited cannot be served from an old cache."""

import importlib.util
import os
from pathlib import Path

import numba


def _root_conftest():
    spec = importlib.util.spec_from_file_location(
        "root_conftest", Path(__file__).with_name("conftest.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_numba_caches_in_the_folder_of_this_source_tree():
    # set before numba was imported: numba read it (an explicit NUMBA_CACHE_DIR aside)
    folder = os.environ["NUMBA_CACHE_DIR"]
    assert numba.config.CACHE_DIR == folder
    if Path(folder).parent.name == "grainscale-numba-cache":
        assert Path(folder).name == _root_conftest()._source_hash()
