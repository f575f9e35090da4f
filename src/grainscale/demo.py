"""`grainscale demo`: a drained triaxial test of the seed's unit-element RVE, end to end.

Generates the 800-sphere RVE of seed §4.1 (radii 3-7 mm, E = 100 MPa, kt/kn = 0.8,
mu = 0.5, porosity 0.373 at p = 100 kPa), compresses it axially to 30 % strain with the
lateral stresses held at 100 kPa, and writes into the output folder:
`triaxial.csv` (stress path), `triaxial.png` (q/p and eps_v against axial strain),
`packing.txt` (the prepared packing), and ParaView snapshots of the RVE before and after
(`rve_initial_*.vtu`, `rve_final_*.vtu`: spheres, contact force network, cell).
The strain rate (0.5 /s, inertial number ~1e-3) is faster than the 0.1 /s of
`grainscale rve triaxial` so that the demo finishes in about a minute.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from tqdm import tqdm

from grainscale.config.rve import RVEParams, TriaxialTest
from grainscale.dem import element_tests, engine
from grainscale.dem.commands import write_rows
from grainscale.dem.generate import contact_params, generate
from grainscale.io.packing import write_packing
from grainscale.io.plots import plot_stress_path
from grainscale.io.rve_vtk import write_rve_vtk


def run_demo(out: Path) -> int:
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    params = RVEParams(preparation={"pressure": 100e3, "porosity": 0.373})
    test = TriaxialTest(confining_pressure=100e3, axial_strain=0.3, strain_rate=0.5,
                        output_interval=0.002)
    print(f"grainscale demo -> {out}/ (first run compiles the kernels, ~30 s)")
    print("1/2 preparing the RVE: 800 spheres, target porosity 0.373 at p = 100 kPa")
    batch = generate(params, progress=lambda text: print(f"    {text}"))
    engine.refresh(batch, contact_params(params))
    write_packing(out / "packing.txt", batch.h[0], batch.s[0] @ batch.h[0].T, batch.radius[0])
    write_rve_vtk(out / "rve_initial", batch, params.young_modulus)
    print("2/2 drained triaxial compression to 30 % axial strain, lateral stress 100 kPa")
    with tqdm(total=test.axial_strain, file=sys.stderr, unit="",
              bar_format="    {l_bar}{bar}| {n:.3f}/{total:.2f} strain "
                         "[{elapsed}<{remaining}] {postfix}") as bar:
        def on_row(row):
            bar.update(min(row["axial_strain"], test.axial_strain) - bar.n)
            bar.set_postfix_str(f"q/p={row['q_over_p']:.3f} eps_v={row['volumetric_strain']:+.4f}")

        rows = element_tests.triaxial(batch, params, test, on_row=on_row)
    write_rows(out / "triaxial.csv", rows, "grainscale demo: drained triaxial, unit-element RVE")
    cols = {c: [r[c] for r in rows] for c in rows[0]}
    plot_stress_path(out / "triaxial.png", {"DEM RVE (800 spheres)": cols},
                     title="Drained triaxial test, seed §4.1 RVE")
    write_rve_vtk(out / "rve_final", batch, params.young_modulus)
    peak = max(rows, key=lambda r: r["q_over_p"])
    emin = min(r["volumetric_strain"] for r in rows)
    print(f"peak q/p = {peak['q_over_p']:.3f} at axial strain {peak['axial_strain']:.3f}; "
          f"final q/p = {rows[-1]['q_over_p']:.3f}; eps_v: min {emin:+.4f}, "
          f"final {rows[-1]['volumetric_strain']:+.4f}")
    print(f"wrote {out}/triaxial.csv, triaxial.png, packing.txt, rve_initial_*.vtu, "
          f"rve_final_*.vtu in {time.perf_counter() - t0:.0f} s")
    return 0
