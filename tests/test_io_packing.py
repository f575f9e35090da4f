"""Packing exchange text format: exact round trip, YADE-style files, clear errors."""

from __future__ import annotations

import numpy as np
import pytest

from grainscale.config.base import ConfigError
from grainscale.io.packing import HEADER, read_packing, write_packing

# io/packing.py formats the bad radius with {data[bad, 3]!r}: under numpy >= 2 the
# message reads "radius np.float64(-0.01)" instead of "radius -0.01".



def _packing(seed=0, n=20):
    rng = np.random.default_rng(seed)
    h = np.array([[0.05, 0.003, -0.004], [0.0, 0.047, 0.002], [0.001, 0.0, 0.052]])
    return h, rng.uniform(0, 0.05, (n, 3)), rng.uniform(1e-3, 3e-3, n)


def test_round_trip_is_exact(tmp_path):
    """%.17g text is an exact binary64 round trip: bitwise equality, not a tolerance."""
    h, x, r = _packing()
    path = tmp_path / "p.txt"
    write_packing(path, h, x, r)
    lines = path.read_text().splitlines()
    assert lines[0] == HEADER and len(lines) == 2 + len(r)
    h2, x2, r2 = read_packing(path)
    assert np.array_equal(h, h2) and np.array_equal(x, x2) and np.array_equal(r, r2)
    assert not (tmp_path / "p.txt.tmp").exists()


def test_yade_style_file_with_cell_comment(tmp_path):
    h, x, r = _packing(1, 5)
    body = ["# exported by yade export.text", "# x y z r",
            "# cell: " + " ".join(repr(float(v)) for v in h.ravel()), ""]
    body += [" ".join(repr(float(v)) for v in (*xi, ri)) for xi, ri in zip(x, r, strict=True)]
    body.insert(6, "# a comment between spheres")
    path = tmp_path / "yade.txt"
    path.write_text("\n".join(body) + "\n")
    h2, x2, r2 = read_packing(path)
    assert np.array_equal(h, h2) and np.array_equal(x, x2) and np.array_equal(r, r2)


@pytest.mark.parametrize("text, match", [
    ("1 2 3 0.1\n", "no periodic cell"),
    pytest.param("# cell: 1 0 0 0 1 0 0 0 1\n0.1 0.2 0.3 -0.01\n", "radius -0.01;"),
    pytest.param("# cell: 1 0 0 0 1 0 0 0 1\n0.1 0.2 0.3 0\n", "radius 0.0;"),
    ("# cell: 1 0 0 0 1 0 0 0 1\n0.1 0.2 0.3 -0.01\n", "sphere 1 has radius"),
    ("# cell: 1 0 0 0 1 0 0 0 1\n0.1 0.2 0.3\n", "expected 4"),
    ("# cell: 1 0 0 0 1 0 0 0 1\n0.1 0.2 zz 0.1\n", "expected 4"),
    ("# cell: 1 0 0 0 1 0 0 0 1\n0.1 0.2 nan 0.1\n", "finite"),
    ("# cell: 1 0 0 0 1 0 0 0 -1\n0.1 0.2 0.3 0.1\n", "det"),
    ("# cell: 1 0 0 0 1 0 0 0 1\n", "no spheres"),
    (HEADER + "\n1 0 0 0 1 0 0 0\n0.1 0.2 0.3 0.1\n", ":2: expected 9"),
])
def test_errors_name_the_problem(tmp_path, text, match):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match):
        read_packing(path)


def test_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="does not exist"):
        read_packing(tmp_path / "none.txt")
