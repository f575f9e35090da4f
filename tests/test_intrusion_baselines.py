"""studies/intrusion/baselines.py (the continuum twin of a multiscale intrusion case) and
reshape.py (the same case on another grid or in another bed)."""

import subprocess
import sys
import tomllib

import pytest

import grainscale as gs
from example_scripts import EXAMPLES, STUDIES, load_example

HERE = EXAMPLES / "intrusion"


baselines = load_example("intrusion/baselines.py")
reshape = load_example("intrusion/reshape.py")


@pytest.mark.parametrize("name", ["quick.toml", "quick_cuboid.toml", "mohr_coulomb.toml"])
def test_reshape_keeps_the_intruder_on_the_surface(name):
    """A 5 x 5 m quarter of a 4 m bed on 0.125 m cells, one point a cell: the grid spans
    the bed and ABOVE more, the intruder's base sits on the new surface at the same x, y,
    and the case passes the loader's checks."""
    path = HERE / name
    case = (baselines.baseline_case(path, "mohr_coulomb", 20.0) if name.startswith("quick")
            else gs.load_case(path))
    rigid0 = {k: list(getattr(case.rigid, k)) for k in ("center", "lo", "hi")
              if hasattr(case.rigid, k)}
    out = reshape.reshape(case, 0.125, 1, 5.0, 4.0)
    assert list(out.grid.cells) == [40, 40, round((4.0 + reshape.ABOVE) / 0.125)]
    assert list(out.bodies[0].hi) == [5.0, 5.0, 4.0]
    assert out.bodies[0].points_per_cell == 1
    rigid = out.rigid
    base = rigid.center[2] if hasattr(rigid, "center") else rigid.lo[2]
    assert base == pytest.approx(4.0, abs=1e-12)
    for key, v0 in rigid0.items():
        assert list(getattr(rigid, key)[:2]) == v0[:2]
    out.check()


def test_reshape_defaults_leave_the_case_as_it_was():
    case = baselines.baseline_case(HERE / "quick.toml", "mohr_coulomb", 20.0)
    before = case.model_dump(mode="json", exclude_unset=True)  # what case.save writes
    assert reshape.reshape(case).model_dump(mode="json", exclude_unset=True) == before


def test_reshape_keeps_a_graded_grid_and_refuses_to_rescale_it():
    """seed_quick.toml's twin runs on its own graded grid (no option: unchanged; points a
    cell may still change); asking for a cell size or a bed names the option."""
    case = baselines.baseline_case(HERE / "seed_quick.toml", "mohr_coulomb", 20.0)
    before = case.model_dump(mode="json", exclude_unset=True)
    assert reshape.reshape(case).model_dump(mode="json", exclude_unset=True) == before
    assert reshape.reshape(case, points_per_cell=2).bodies[0].points_per_cell == 2
    with pytest.raises(SystemExit, match="--cell-size: .* graded grid"):
        reshape.reshape(case, 0.125)
    with pytest.raises(SystemExit, match="--quarter: .* graded grid"):
        reshape.reshape(case, width=5.0, depth=4.0)


def test_reshape_cli_writes_the_multiscale_case_in_a_deeper_bed(tmp_path):
    """The written case keeps the probes at their depth below the surface (same x, y),
    passes the loader's checks, and an existing file is not overwritten."""
    out = tmp_path / "seed_bed.toml"
    cmd = [sys.executable, str(STUDIES / "intrusion" / "reshape.py"), str(HERE / "quick.toml"),
           "--quarter", "5", "4", "--out", str(out)]
    subprocess.run(cmd, check=True, capture_output=True)
    old = tomllib.loads((HERE / "quick.toml").read_text())
    new = tomllib.loads(out.read_text())
    lift = 4.0 - old["bodies"][0]["hi"][2]
    for p0, p1 in zip(old["output"]["probes"], new["output"]["probes"], strict=True):
        assert p1["position"] == pytest.approx([*p0["position"][:2], p0["position"][2] + lift])
    assert new["rve"] == old["rve"] and new["materials"] == old["materials"]
    gs.load_case(out)
    again = subprocess.run(cmd, capture_output=True, text=True)
    assert again.returncode != 0 and "not overwritten" in again.stderr
    bad = subprocess.run(cmd[:3] + ["--quarter", "0.8", "4", "--out", str(tmp_path / "x.toml")],
                         capture_output=True, text=True)
    assert bad.returncode != 0 and "--quarter" in bad.stderr and "> 1 m" in bad.stderr


def test_to_depth_sets_the_end_time_from_ramp_and_velocity(tmp_path):
    """quick.toml ends at 2.3 s, where its header says the cylinder is 0.55 m (1.1 R)
    deep: 0.2 s of linear ramp to 0.25 m/s (0.025 m) then 2.1 s steady. Within the ramp
    d = v t^2 / (2 t_ramp); the two branches meet at the ramp's end."""
    case = gs.load_case(HERE / "quick.toml")
    assert reshape.end_time_for(case, 1.1) == pytest.approx(case.time.end, abs=1e-12)
    assert reshape.end_time_for(case, 0.05) == pytest.approx(0.2, abs=1e-12)
    assert reshape.end_time_for(case, 0.02) == pytest.approx((2 * 0.01 * 0.2 / 0.25) ** 0.5)
    out = tmp_path / "deep.toml"
    cmd = [sys.executable, str(STUDIES / "intrusion" / "reshape.py"), str(HERE / "quick.toml"),
           "--out", str(out)]
    subprocess.run(cmd + ["--to-depth", "1.8"], check=True, capture_output=True)
    assert tomllib.loads(out.read_text())["time"]["end"] == pytest.approx(3.7)
    bad = subprocess.run(cmd[:-1] + [str(tmp_path / "x.toml"), "--to-depth", "3.5"],
                         capture_output=True, text=True)
    assert bad.returncode != 0 and "--to-depth 3.5: valid 0 < d/R < 3" in bad.stderr


def test_surface_replaces_the_intruders_contact():
    """--contact nodes: no-slip, with the penalty-only keys back at their defaults (the
    loader refuses them with nodes); --contact penalty --friction 0.5: a rough penalty
    surface. Both pass the loader's checks and say so in the title."""
    case = baselines.baseline_case(HERE / "quick.toml", "mohr_coulomb", 20.0)
    rough = reshape.surface(case.model_copy(deep=True), "penalty", 0.5)
    assert rough.rigid.contact == "penalty" and rough.rigid.friction == 0.5
    rough.check()
    case.rigid.friction = 0.3  # a penalty key the case sets
    sticky = reshape.surface(case, "nodes")
    assert sticky.rigid.contact == "nodes" and sticky.rigid.friction == 0.0
    assert sticky.title.endswith("no-slip intruder")
    sticky.check()


def test_reshape_cli_makes_the_graded_multiscale_intruder_rough(tmp_path):
    """seed_quick.toml with --contact penalty --friction 0.5: the same case (grid, RVE,
    probes) but for the intruder's friction and the end time; --friction without the
    penalty contact is refused, naming the option and its valid range."""
    out = tmp_path / "rough.toml"
    cmd = [sys.executable, str(STUDIES / "intrusion" / "reshape.py"),
           str(HERE / "seed_quick.toml"), "--out", str(out)]
    subprocess.run(cmd + ["--contact", "penalty", "--friction", "0.5", "--to-depth", "0.45"],
                   check=True, capture_output=True)
    old = tomllib.loads((HERE / "seed_quick.toml").read_text())
    new = tomllib.loads(out.read_text())
    assert new["rigid"]["friction"] == 0.5 and new["rigid"]["contact"] == "penalty"
    assert new["time"]["end"] == pytest.approx(0.1 + 0.45 * 0.5 / 0.25)  # ramp/2 + d/v
    for key in ("grid", "rve", "materials", "bodies"):
        assert new[key] == old[key]
    assert new["output"]["probes"] == old["output"]["probes"]
    assert "friction 0.5" in gs.load_case(out).title
    bad = subprocess.run(cmd[:-1] + [str(tmp_path / "x.toml"), "--friction", "0.5"],
                         capture_output=True, text=True)
    assert bad.returncode != 0 and "--friction 0.5: valid 0 to 2, with --contact penalty" \
        in bad.stderr
