"""`grainscale rve generate|isotropic|undrained|shear` against known answers, on the
150-sphere packing of tests/data/triaxial_150 (`--packing`) or a small generated one,
their CSV, PNG and VTK outputs read back."""

from __future__ import annotations

from pathlib import Path

import matplotlib.image
import meshio
import numpy as np
import pytest

from grainscale.analysis import read_columns
from grainscale.cli import main
from grainscale.config.rve import RVEParams
from grainscale.io.packing import load_packing

DATA = Path(__file__).parent / "data" / "triaxial_150"
PACKING = DATA / "packing.txt"
RVE = """
[rve]
particles = 150
[rve.preparation]
pressure = 100e3
porosity = 0.373
"""


def _run(tmp: Path, command: str, tables: str, *extra: str) -> dict:
    params = tmp / "params.toml"
    params.write_text(RVE + tables)
    out = tmp / f"{command}.csv"
    assert main(["rve", command, str(params), "--packing", str(PACKING), "--out", str(out),
                 "--quiet", *extra]) == 0
    return read_columns(out)


def _voigt_bulk_modulus(batch, young: float) -> float:
    """K_V = (1/9V) sum_c kn |d|^2 over the touching pairs [Pa]: the bulk modulus of the
    contact network under an affine isotropic strain (normal springs kn = E r*; the
    tangential springs see no affine isotropic slip), an upper bound of the relaxed one
    while no contact is added."""
    h = batch.h[0]
    x = (batch.s[0] - np.floor(batch.s[0])) @ h.T
    r = batch.radius[0]
    total = 0.0
    shifts = np.array([(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)])
    for i in range(len(r)):
        d = (x[i + 1:, None, :] + shifts[None] @ h.T) - x[i]
        dist = np.linalg.norm(d, axis=2)
        j, k = np.nonzero(dist < (r[i] + r[i + 1:])[:, None])
        rstar = 2.0 * r[i] * r[i + 1:][j] / (r[i] + r[i + 1:][j])
        total += float(np.sum(young * rstar * dist[j, k] ** 2))
    return total / (9.0 * abs(np.linalg.det(h)))


def test_isotropic_compression_is_as_stiff_as_its_contact_network_allows(tmp_path):
    """100 -> 150 kPa: the secant bulk modulus dp / d(-eps_v) lies below the Voigt bound of
    the packing's contacts (at 150 kPa: K_V(100 kPa) scaled by the contacts gained, the
    coordination rising 5.40 -> 5.52, +2 %), by what the grains relax non-affinely:
    measured 0.894 K_V(100 kPa) = 17.4 MPa. The ratio is a property of this packing's
    contact network and contact law, not of the numerics: halving or doubling the
    strain rate leaves it at 0.894, no local damping gives 0.890. Allowed: 0.87-0.92
    (3 % either side: six times the largest numerical change). Contacts 10 % too soft
    (kn = 0.9 E r*, mutation tried) give 0.81, kt/kn 0.4 instead of 0.8 gives 0.86; a
    sign slip in eps_v = ln(V/V0) or a servo aiming elsewhere fails too."""
    rows = _run(tmp_path, "isotropic", "[isotropic]\npressure_final = 150e3\n"
                "strain_rate = 0.05\noutput_interval = 2e-4\n")
    p, ev = rows["p"], rows["volumetric_strain"]
    assert p[-1] == pytest.approx(150e3, rel=0.01)  # the test stops within 1 %
    k_secant = (p[-1] - p[0]) / -(ev[-1] - ev[0])
    k_voigt = _voigt_bulk_modulus(load_packing(PACKING, RVEParams(particles=150)),
                                  RVEParams().young_modulus)
    z = rows["coordination"]
    assert k_secant < k_voigt * z[-1] / z[0]  # the bound at 150 kPa
    assert 0.87 * k_voigt < k_secant < 0.92 * k_voigt, (k_secant / k_voigt)


def test_undrained_keeps_the_volume_while_the_stress_path_turns(tmp_path):
    """Constant volume (a trace-free velocity gradient): |eps_v| stays below 1e-6 over
    1 % axial strain, where the drained test of the same packing changes it by ~1e-3,
    while q rises. The stress-path plot is written and readable."""
    png = tmp_path / "path.png"
    rows = _run(tmp_path, "undrained", "[undrained]\naxial_strain = 0.01\n"
                "strain_rate = 0.5\noutput_interval = 0.002\n", "--plot", str(png))
    assert np.abs(rows["volumetric_strain"]).max() < 1e-6
    assert rows["axial_strain"][-1] == pytest.approx(0.01, abs=0.002)
    assert rows["q"][-1] > rows["q"][0] + 20e3
    image = matplotlib.image.imread(png)
    assert image.shape[0] > 100 and image.shape[1] > 100


def test_simple_shear_holds_its_normal_stress_and_obeys_stress_dilatancy(tmp_path):
    """Simple shear to gamma = 0.05 at a servo-held sigma_zz of 100 kPa: sigma_zz within
    2 % of it after the first row (measured 0.5 %), and Taylor's stress-dilatancy
    balance: the work tau dgamma goes into friction and into lifting sigma_n, so
    |tau|/sigma_n - d eps_v/d gamma is the friction of steady flow, 0.25-0.45 for these
    grains (mu_s = 0.36 measured in flow, docs/validation.md §3). Measured 0.32-0.41
    over gamma 0.02-0.04, where |tau|/sigma_n alone peaks at 0.61 with d eps_v/d gamma
    ~0.27 (a dense packing dilating). Without dilatancy's share, or with the volume
    sign flipped, the balance misses the band."""
    rows = _run(tmp_path, "shear", "[shear]\nnormal_stress = 100e3\nshear_strain = 0.05\n"
                "strain_rate = 0.5\noutput_interval = 0.005\n")
    gamma, ev = rows["shear_strain"], rows["volumetric_strain"]
    assert gamma[-1] == pytest.approx(0.05, abs=0.005)
    assert np.abs(rows["sigma_zz"][1:] / 100e3 - 1.0).max() < 0.02
    ratio = np.abs(rows["tau_xz"]) / rows["sigma_zz"]
    for k in np.flatnonzero((gamma > 0.0175) & (gamma < 0.0425)):
        dilatancy = (ev[k + 1] - ev[k - 1]) / (gamma[k + 1] - gamma[k - 1])
        assert 0.25 < ratio[k] - dilatancy < 0.45, (gamma[k], ratio[k], dilatancy)


def test_generate_writes_a_packing_at_its_porosity_and_a_snapshot(tmp_path):
    """`rve generate` of a 60-sphere recipe: the packing file read back holds 60 spheres
    at the target porosity within its tolerance, and the VTK snapshot's sphere file
    holds the same 60 centres."""
    params = tmp_path / "params.toml"
    params.write_text("[rve]\nparticles = 60\nradius_min = 2e-3\nradius_max = 2.4e-3\n"
                      "[rve.preparation]\npressure = 10e3\nporosity = 0.42\n"
                      "porosity_tolerance = 0.04\n")
    out = tmp_path / "p.txt"
    assert main(["rve", "generate", str(params), "--out", str(out), "--vtk",
                 str(tmp_path / "snap"), "--quiet"]) == 0
    rp = RVEParams(particles=60, radius_min=2e-3, radius_max=2.4e-3)
    batch = load_packing(out, rp)
    assert batch.n_particles == 60
    assert abs(float(batch.porosity()[0]) - 0.42) <= 0.04
    spheres = [f for f in tmp_path.iterdir() if f.name.startswith("snap") and "sphere" in f.name]
    assert spheres, sorted(f.name for f in tmp_path.iterdir())
    assert len(meshio.read(spheres[0]).points) == 60
