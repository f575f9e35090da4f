"""studies/intrusion/kphi_angles.py (K_phi against the friction angle) and its cases,
examples/intrusion/noslip.toml and noslip_cuboid.toml."""

import json

import numpy as np
import pytest

import grainscale as gs
from example_scripts import EXAMPLES, load_example
from grainscale.analysis import k_phi
from grainscale.analysis import t95 as fa_t95

HERE = EXAMPLES / "intrusion"
kphi = load_example("intrusion/kphi_angles.py")
reshape = load_example("intrusion/reshape.py")


def _physics(case: gs.Case) -> dict:
    d = case.check().model_dump(mode="json")
    d.pop("title")
    return d


def test_noslip_is_quick_toml_reshaped_as_its_comments_say():
    """noslip.toml is quick.toml in a 2 x 2 m quarter of a 2 m bed with the no-slip
    intruder driven to d/R 2: the case the twin convergence study runs through
    reshape.py (baselines.py --quarter 2 2 --contact nodes --to-depth 2), key for key."""
    made = reshape.reshape(gs.load_case(HERE / "quick.toml"), width=2.0, depth=2.0)
    reshape.to_depth(made, 2.0)
    reshape.surface(made, "nodes")
    assert _physics(gs.load_case(HERE / "noslip.toml")) == _physics(made)


def test_noslip_cuboid_differs_only_in_its_intruder():
    cyl = _physics(gs.load_case(HERE / "noslip.toml"))
    box = _physics(gs.load_case(HERE / "noslip_cuboid.toml"))
    assert box.pop("rigid")["shape"] == "box" and cyl.pop("rigid")["shape"] == "cylinder"
    assert box == cyl


def test_noslip_fine_differs_only_in_grid_bed_and_depth():
    """noslip_fine.toml is noslip.toml on a graded grid of 6 cells over R near the
    intruder, in a 3 m quarter of a 3 m bed, to d/R 3: the intruder's base and the
    probes keep their depth below the surface (the probes within the same fine cell),
    everything else is the same."""
    fine = _physics(gs.load_case(HERE / "noslip_fine.toml"))
    base = _physics(gs.load_case(HERE / "noslip.toml"))
    for a in "xyz":
        assert fine["grid"][f"nodes_{a}"]["cell"] == pytest.approx(0.5 / 6)
    assert fine["bodies"][0]["hi"] == [3.0, 3.0, 3.0]
    assert fine["rigid"]["center"] == [0.0, 0.0, 3.0] and base["rigid"]["center"][2] == 2.0
    assert fine["time"]["end"] == pytest.approx(0.1 + 1.5 / 0.25)  # d = 1.5 m = 3 R
    for a, b in zip(fine["output"]["probes"], base["output"]["probes"], strict=True):
        assert a["position"][2] - 3.0 == pytest.approx(b["position"][2] - 2.0)
    for d in (fine, base):
        for key in ("grid", "time"):
            d.pop(key)
        d["bodies"][0].pop("hi")
        d["rigid"].pop("center")
        d["output"].pop("probes")
    assert fine == base


def test_angle_case_sets_the_rolling_resistance():
    plain = kphi.angle_case(0.0).check()
    assert plain.rve.rolling_stiffness == 0.0 and plain.rve.rolling_friction == 0.0
    rolled = kphi.angle_case(0.15, "cuboid").check()
    assert (rolled.rve.rolling_stiffness, rolled.rve.rolling_friction) == (1.0, 0.15)
    assert rolled.rigid.shape == "box"
    # only the [rve] table and the title differ from the plain case
    a, b = _physics(plain), _physics(kphi.angle_case(0.15))
    assert a.pop("rve") != b.pop("rve") and a == b
    with pytest.raises(SystemExit, match="ETA_R 1.5: valid 0 to 1"):
        kphi.angle_case(1.5)
    with pytest.raises(SystemExit, match="--eta-r 0.07: no measured angle"):
        kphi.phi_file(0.07)
    for eta in kphi.PHI_FILES:  # every angle the table may name is committed
        assert json.loads(kphi.phi_file(eta).read_text())["phi_deg"] > 0


def _collected(folder, k, p0, meta, ripple=0.0, library=2, bend=None):
    """A collected run whose intrusion stage is p = k d/R + p0 (plus a one-cell ripple
    of amplitude `ripple`, in units of p; with `bend`, curved as
    k (bend - d)^2 / (2 bend) above it until d/R = bend) after a geostatic row at t < 0,
    its bed drawn from `library` packings."""
    folder.mkdir(parents=True)
    x = np.linspace(0.0, 2.0, 81)
    y = k * x + p0 + ripple * np.sin(2 * np.pi * x / 0.25)
    if bend is not None:
        y += np.where(x < bend, k * (bend - x) ** 2 / (2 * bend), 0.0)
    rows = ["time,depth_over_R,force_normalized", "-0.1,0.0,0.0"]
    rows += [f"{0.1 + xi / 2:.6f},{xi:.6f},{yi:.9f}" for xi, yi in zip(x, y, strict=True)]
    (folder / "history.csv").write_text("\n".join(rows) + "\n")
    (folder / "meta.json").write_text(json.dumps(meta))
    (folder / "case.resolved.toml").write_text(
        f'[grid]\ncell_size = 0.125\n\n[materials.sand]\ntype = "dem"\nlibrary = {library}\n')


def test_table_fits_each_run_and_says_which_angle_it_follows(tmp_path):
    """Straight lines come back as their slope; a slope 1.1 times Kang's law at the
    steady angle of a bed of the 8 measured packings follows it (within 25 %) and not the
    peak angle's (the law is 2.4 times larger at 26.2 deg than at 19.56); a slope 0.7
    times follows neither."""
    phi = json.loads(kphi.phi_file(0.0).read_text())
    k_steady, k_peak = k_phi(phi["phi_deg"]), k_phi(phi["peak_phi_deg"])
    assert k_peak / k_steady > 1.25 / 0.75  # the two definitions are told apart
    multi = {"kind": "multiscale", "eta_r": 0.0, "shape": "cylinder",
             "phi_file": "studies/rolling/data/q_e0.json"}
    _collected(tmp_path / "a", 1.1 * k_steady, 3.0, multi, library=8)
    _collected(tmp_path / "b", 0.7 * k_steady, 3.0, multi, library=8)
    _collected(tmp_path / "twin", 15.0, 2.0, {"kind": "twin", "phi_deg": 20.0,
                                                "shape": "cylinder"}, ripple=0.5)
    table = {r["name"]: r for r in kphi.rows(tmp_path, 0.8)}
    a, b, twin = table["a"], table["b"], table["twin"]
    assert a["K_phi"] == pytest.approx(1.1 * k_steady, rel=1e-9)  # exact line: exact fit
    assert a["p_0"] == pytest.approx(3.0, abs=1e-9)
    assert a["follows_steady"] and not a["follows_peak"]
    assert not b["follows_steady"] and not b["follows_peak"]
    assert a["steady"] and a["window"][1] == pytest.approx(2.0)
    # the ripple's full periods within the window leave the slope within a few %
    assert twin["K_phi"] == pytest.approx(15.0, rel=0.03) and "follows_steady" not in twin
    assert a["K_kang_steady_band95"][0] < k_steady < a["K_kang_steady_band95"][1]
    png = tmp_path / "k.png"
    kphi.figure(list(table.values()), tmp_path, png)
    assert png.stat().st_size > 10_000


def test_the_bed_is_judged_by_the_angles_of_its_own_packings(tmp_path):
    """A bed of 2 packings is compared with the angles of packings 0 and 1 (their mean
    and Student's 95 % band, computed here from the measured per-packing angles), a bed
    of 8 with the recipe's 8: Kang's law is evaluated at the ends of each band, the
    peak angle's with the peak band and the steady angle's with the steady band."""
    phi = json.loads(kphi.phi_file(0.15).read_text())
    multi = {"kind": "multiscale", "eta_r": 0.15, "shape": "cylinder",
             "phi_file": "studies/rolling/data/q_a1_e0.15.json"}
    _collected(tmp_path / "two", 80.0, 3.0, multi, library=2)
    _collected(tmp_path / "eight", 80.0, 3.0, multi, library=8)
    table = {r["name"]: r for r in kphi.rows(tmp_path, 0.8)}
    for name, n in (("two", 2), ("eight", 8)):
        r = table[name]
        for key, per in (("phi", "phi_per_packing_deg"), ("peak_phi", "peak_phi_per_packing_deg")):
            a = np.array(phi[per][:n])
            mean = a.mean()
            band = fa_t95(n - 1) * a.std(ddof=1) / np.sqrt(n)
            assert r[f"{key}_deg"] == pytest.approx(mean, abs=0.006)  # 2 decimals
            assert r[f"{key}_band95_deg"] == pytest.approx(band, abs=0.006)
        assert r["library"] == n
        assert r["K_kang_steady_band95"] == [k_phi(r["phi_deg"] - r["phi_band95_deg"]),
                                             k_phi(r["phi_deg"] + r["phi_band95_deg"])]
        assert r["K_kang_peak_band95"] == [k_phi(r["peak_phi_deg"] - r["peak_phi_band95_deg"]),
                                           k_phi(r["peak_phi_deg"] + r["peak_phi_band95_deg"])]
        assert r["K_kang_peak"] == k_phi(r["peak_phi_deg"])
    assert table["eight"]["phi_deg"] == phi["phi_deg"]  # the quoted angle: all 8 packings
    assert table["two"]["phi_deg"] != phi["phi_deg"]
    assert table["two"]["phi_recipe_deg"] == phi["phi_deg"]


def test_a_slope_is_steady_only_over_a_long_straight_window(tmp_path):
    """A run that bends until d/R 1.4 then is straight: the rule's window starts late, is
    shorter than 0.8 R or curved, and is not called steady; the straight run is, over
    d/R 0-2. Verdicts over the fixed windows 0-2 and 1-2 are reported beside the rule's."""
    twin = {"kind": "twin", "phi_deg": 20.0, "shape": "cylinder"}
    _collected(tmp_path / "bent", 20.0, 2.0, twin, bend=1.4)
    _collected(tmp_path / "straight", 20.0, 2.0, twin)
    table = {r["name"]: r for r in kphi.rows(tmp_path, 0.8)}
    bent, straight = table["bent"], table["straight"]
    assert not bent["steady"] and bent["window"][0] >= 1.0
    assert straight["steady"] and straight["window"] == [0.0, 2.0]
    assert [w["window"] for w in straight["windows"]] == [[0.0, 2.0], [1.0, 2.0]]
    assert straight["windows"][1]["K_phi"] == pytest.approx(20.0, rel=1e-9)
    assert bent["windows"][0]["linear"] is False  # the bend is seen over d/R 0-2


def test_verdicts_say_when_the_uncertainty_decides():
    assert kphi.verdict(100.0, 10.0, 100.0) == "follows"
    assert kphi.verdict(100.0, 30.0, 100.0) == "undecided"  # 70-130: straddles 75
    assert kphi.verdict(50.0, 10.0, 100.0) == "not"
    assert kphi.verdict(140.0, 10.0, 100.0) == "not"
    assert kphi.verdict(120.0, 10.0, 100.0) == "undecided"


def test_ratios_are_taken_over_the_common_window(tmp_path):
    """A cuboid and a cylinder run at the same eta_r, each a straight line (slopes 21 and
    20) but the cylinder's bent until d/R 0.8: their ratio is taken over the span both
    windows share, where both are nearly straight, and is 1.05 (within the rule's 0.2 %
    tolerance, which lets the cylinder's window keep the bend's last, nearly tangent
    part)."""
    multi = {"kind": "multiscale", "eta_r": 0.0, "shape": "cylinder",
             "phi_file": "studies/rolling/data/q_e0.json"}
    _collected(tmp_path / "cyl", 20.0, 2.0, multi, bend=0.8)
    _collected(tmp_path / "box", 21.0, 2.0, {**multi, "shape": "cuboid"})
    table = {r["name"]: r for r in kphi.rows(tmp_path, 0.8)}
    c = table["box"]["over_cylinder"]
    assert c["name"] == "cyl" and c["window"][0] == table["cyl"]["window"][0] > 0.5
    assert c["ratio"] == pytest.approx(1.05, rel=2e-3)


def test_table_refuses_an_empty_folder(tmp_path):
    with pytest.raises(SystemExit, match="no collected runs"):
        kphi.rows(tmp_path, 0.8)


def test_collect_refuses_an_unfinished_run_unless_partial(tmp_path):
    """A run folder whose history stops before time.end (noslip.toml's 4.1 s) is refused,
    naming the time; with partial=True it is collected and the d/R it reached recorded."""
    run = tmp_path / "run"
    run.mkdir()
    (run / "case.resolved.toml").write_text((HERE / "noslip.toml").read_text())
    rows = ["time,depth_over_R,force_normalized"]
    rows += [f"{t:.2f},{2 * max(t - 0.1, 0) / 4:.4f},{3 + 16 * max(t - 0.1, 0) / 2:.4f}"
             for t in np.arange(0.0, 3.01, 0.05)]
    (run / "history.csv").write_text("\n".join(rows) + "\n")
    data = tmp_path / "data"
    with pytest.raises(SystemExit, match="stopped at t = 3 s before time.end 4.1 s"):
        kphi.collect(run, "mc", None, 20.0, data)
    kphi.collect(run, "mc", None, 20.0, data, partial=True)
    meta = json.loads((data / "mc" / "meta.json").read_text())
    assert meta == {"shape": "cylinder", "stopped_at_d_over_R": 1.45, "kind": "twin",
                    "phi_deg": 20.0}
    # a box intruder is collected as the cuboid
    (run / "case.resolved.toml").write_text((HERE / "noslip_cuboid.toml").read_text())
    kphi.collect(run, "box", None, 20.0, data, partial=True)
    assert json.loads((data / "box" / "meta.json").read_text())["shape"] == "cuboid"
    assert (data / "mc" / "history.csv").read_text() == (run / "history.csv").read_text()
