"""How strong are the flowing RVEs of a column collapse, and why? Three diagnostics.

    python studies/column_collapse/flow_friction.py frames OUT
        mobilised friction sin(phi) = (s1 - s3)/(s1 + s3) of flowing (|v| > 5 cm/s) and
        resting (|v| < 5 mm/s) points in every VTK frame of a finished run;
    python studies/column_collapse/flow_friction.py record CASE OUT [--until 2.5]
        runs CASE to `until` tau_c after release, recording every step's dH, dt and
        stress per point and every RVE's state at release (OUT/record.npz, snapshot.npz);
    python studies/column_collapse/flow_friction.py compare OUT TABLE.toml [--window 20]
        compares, point by point and step by step, the friction tau/sigma_n that each
        flowing RVE carried on its shear plane (read from the recorded dH) with the mu(I)
        of TABLE.toml (a `grainscale rve flow` fit) at that RVE's own sigma_n and rate;
    python studies/column_collapse/flow_friction.py replay OUT [--points 8]
        replays the recorded dH of the most sheared points on their RVEs taken at
        release: as run, rebuilt from positions (tangential history restarts, the
        control for supercells), as n x n x n supercells (the same grains n^3 times,
        --tiles 2 3), with retiling, and on packings generated at other sizes
        (--packings P.h5 ...: `fresh N`, each point taking them in turn, and their
        supercells `fresh N nxnxn`; they start from
        their preparation's isotropic state, not the column's geostatic one, so
        `--packings` with the run's own packings, OUT/packings/*.h5, is their control),
        and prints the median mobilised friction of each over 0.5-2.5 tau_c
        (--variants selects).

The replay is the MPM's exact deformation history without the MPM: the RVE's answer
to it depends only on the RVE, so differences between the variants are the cell's.
"""

from __future__ import annotations

import argparse
import glob
import tomllib
from pathlib import Path

import numpy as np

import grainscale as gs
from grainscale import blocks, rve
from grainscale.analysis import read_frame

TAU_C = 0.0782  # s, sqrt(H_i / g) of the seed's column


def mobilised(sig: np.ndarray) -> np.ndarray:
    """sin(phi_mob) = (s1 - s3)/(s1 + s3) of Cauchy stresses (..., 3, 3), tension positive."""
    s = -0.5 * (sig + np.swapaxes(sig, -1, -2))
    ev = np.linalg.eigvalsh(s)
    return (ev[..., 2] - ev[..., 0]) / np.maximum(ev[..., 2] + ev[..., 0], 1e-12)


def degrees(x) -> float:
    return float(np.degrees(np.arcsin(np.clip(x, -1, 1))))


def frames(out: Path) -> None:
    print("frame  flowing: n  phi_mob quartiles [deg]   resting: n  phi_mob quartiles")
    for f in sorted(glob.glob(str(out / "frames" / "frame_*.vtu"))):
        _, d = read_frame(f)
        phi = mobilised(d["stress"].reshape(-1, 3, 3))
        v = np.linalg.norm(d["velocity"], axis=1)
        row = [Path(f).stem[-5:]]
        for sel in ((v > 0.05) & (d["p"] > 30), (v < 0.005) & (d["p"] > 30)):
            q = [degrees(x) for x in np.percentile(phi[sel], [25, 50, 75])] if sel.any() \
                else [np.nan] * 3
            row.append(f"{sel.sum():4d}  " + " ".join(f"{x:5.1f}" for x in q))
        print("   ".join(row))


def record(case: Path, out: Path, until: float) -> None:
    """Run CASE (its one material an RVE material owning every point, released at t = 0
    after a stage at t < 0) to `until` tau_c, recording from the steps gs.run's on_step
    reports: per step that starts at t >= 0 its dH, dt, the points' stress after it and
    its start time; the RVEs as the first such step starts (after the last step before
    release)."""
    cfg = gs.load_case(case)
    if cfg.time.start >= 0:
        raise SystemExit(f"{case}: time.start = {cfg.time.start}: record needs a stage "
                         "before the release at t = 0 (the RVEs are taken as it ends)")
    cfg.time.end = until * TAU_C
    cfg.output.checkpoint_every = 0
    for m in cfg.materials.values():  # out/case.toml stays valid away from CASE's folder
        if m.type == "dem" and m.packings:
            m.packings = [str((case.parent / p).resolve()) for p in m.packings]
    out.mkdir(parents=True, exist_ok=True)
    cfg.save(out / "case.toml")
    rec = {"dH": [], "dt": [], "sig": [], "t": []}
    snap = {}
    now = {"t": cfg.time.start}  # when the coming step starts: the last step's end

    def on_step(s: blocks.MPMState) -> None:
        start, now["t"] = now["t"], s.time
        if s.time >= 0 and not snap:  # the next step is the first after release
            material = s.materials[0]
            if len(material.groups) > 1:
                raise RuntimeError("cells were retiled before release; record with "
                                   "retile_width = 0")
            snap.update(blocks.state_arrays(material.groups[0].copy()),
                        dt_crit=material.dt_crit)
        if start >= 0:  # (the material owns every point: its stresses are the points')
            for key, v in (("dH", s.dH.copy()), ("dt", s.last_dt),
                           ("sig", s.points.stress.copy()), ("t", start)):
                rec[key].append(v)

    try:
        gs.run(cfg, out, checkpoint_every=0, progress=False, on_step=on_step)
    except gs.RunError as err:  # what was recorded up to the error is kept
        print(f"{err}: recorded up to it")
    np.savez(out / "record.npz", **{k: np.array(v) for k, v in rec.items()})
    np.savez(out / "snapshot.npz", **snap)
    print(f"recorded {len(rec['dt'])} steps after release into {out}")


def replay(out: Path, n_points: int, tiles: list[int], skip: int = 0,
           packings: list[Path] = (), only: list[str] | None = None) -> None:
    from grainscale.blocks import (
        STATE_FIELDS,
        RVEMaterial,
        RVEParams,
        SimulationError,
        from_packing,
        from_state_arrays,
        read_rve_state,
    )

    rec = np.load(out / "record.npz")
    snap = dict(np.load(out / "snapshot.npz"))
    params = rve.load(out / "case.toml").rve
    dH, dts, sig_run, t = rec["dH"], rec["dt"], rec["sig"], rec["t"]
    window = t > 0.5 * TAU_C
    sym = 0.5 * (dH + np.swapaxes(dH, 2, 3))
    dev = sym - np.trace(sym, axis1=2, axis2=3)[..., None, None] * np.eye(3) / 3
    shear = np.linalg.norm(dev, axis=(2, 3))[window].sum(0)
    p_mean = (-np.trace(sig_run, axis1=2, axis2=3) / 3)[window].mean(0)
    loaded = np.flatnonzero(p_mean > 100)
    points = loaded[np.argsort(shear[loaded])[::-1][skip:skip + n_points]]
    one = from_state_arrays({k: snap[k][points] for k in STATE_FIELDS})

    def supercell(r, n, cell=None):  # n x n x n copies of RVE r of `cell` (the snapshot)
        src, k = (one, r) if cell is None else (cell, 0)
        h = src.h[k]
        x = src.s[k] @ h.T
        shifts = np.array([[i, j, k] for i in range(n) for j in range(n) for k in range(n)],
                          float)
        big = from_packing(n * h, np.concatenate([x + s @ h.T for s in shifts]),
                           np.tile(src.radius[k], n**3), params.density)
        rng = np.random.default_rng(r)  # break the copies' symmetry, far below the noise
        big.v[0] = np.tile(src.v[k], (n**3, 1)) + 1e-9 * rng.standard_normal(big.v[0].shape)
        big.w[0] = np.tile(src.w[k], (n**3, 1))
        big.h0[0] = n * src.h0[k]
        return big

    def alone(r):  # the same state rebuilt from positions (contact history restarts)
        b = from_packing(one.h[r], one.s[r] @ one.h[r].T, one.radius[r], params.density)
        b.v[0], b.w[0], b.h0[0] = one.v[r], one.w[r], one.h0[r]
        return b

    fresh = {}  # packings generated at their size, one per point in turn: N -> [(batch, params)]
    for f in packings:
        batch, stored = read_rve_state(f)
        if stored is None:
            raise SystemExit(f"{f}: no [rve] parameters stored with the packing")
        fresh.setdefault(batch.radius.shape[1], []).append((batch, RVEParams(**stored)))

    def fresh_of(r, n, tiles=1):  # point r's packing of n spheres, as tiles^3 copies
        batch, rve_params = fresh[n][r % len(fresh[n])]
        return (batch if tiles == 1 else supercell(r, tiles, batch)), rve_params

    def run(batch, p, retile_width=0.0, rve_params=params):
        mat = RVEMaterial("replay", rve_params, [batch], 1, retile_width=retile_width)
        mat.groups, mat.dt_crit = [batch], float(snap["dt_crit"])
        sig = mat.initial_stress()
        out_sig = []
        for k in range(len(dts)):
            try:
                mat.update(dH[k, p][None], dts[k], sig)
            except SimulationError:
                break  # too thin: the rest of this variant is missing
            out_sig.append(sig[0].copy())
        return np.array(out_sig)

    variants = {"as run": lambda r: one.take([r]), "rebuilt": alone,
                **{f"{n}x{n}x{n}": (lambda r, n=n: supercell(r, n)) for n in tiles},
                "retiled": lambda r: one.take([r]),
                **{f"fresh {n}": (lambda r, n=n: fresh_of(r, n)) for n in fresh},
                **{f"fresh {n} {m}x{m}x{m}": (lambda r, n=n, m=m: fresh_of(r, n, m))
                   for n in fresh for m in tiles}}
    if only:
        unknown = sorted(set(only) - set(variants))
        if unknown:
            raise SystemExit(f"--variants {unknown}: not among {list(variants)}")
        variants = {k: v for k, v in variants.items() if k in only}
    print(f"points {points.tolist()}; median phi_mob [deg] and p [Pa] over 0.5-2.5 tau_c")
    print(f"{'point':>5} " + " ".join(f"{v:>16}" for v in variants))
    table = {v: [] for v in variants}
    for r, p in enumerate(points):
        cells = []
        for name, make in variants.items():
            made = make(r)
            batch, rve_params = made if isinstance(made, tuple) else (made, params)
            s = run(batch.take([0]), p, retile_width=4.0 if name == "retiled" else 0.0,
                    rve_params=rve_params)
            w = window[:len(s)]
            mu = float(np.median(mobilised(s[w])))
            table[name].append(mu)
            pres = float(np.median(-np.trace(s[w], axis1=1, axis2=2) / 3))
            cells.append(f"{degrees(mu):7.1f} {pres:6.0f} Pa")
        print(f"{p:5d} " + " ".join(f"{c:>16}" for c in cells), flush=True)
    print("median " + " ".join(f"{degrees(np.median(v)):16.1f}" for v in table.values()))


def compare(out: Path, table: Path, window: int = 20) -> None:
    """Does each flowing RVE carry the steady mu(I) of TABLE at its own pressure and rate?

    TABLE is a `grainscale rve flow` fit, in the shear-cell measure (tau/sigma_n on the
    shear plane). Each point's shear plane is read from its recorded dH summed over
    `window` MPM steps (one step's increment is dominated by the grid's noise): the
    deviatoric part is nearly a simple shear gdot t n^T, whose largest singular triple
    gives the rate gdot, the shear direction t and the plane normal n. The RVE's
    |t . sigma n| / (-n . sigma n) is compared with mu(I) at I = gdot d sqrt(rho_s /
    sigma_n). Medians over the points that flow (gdot > 1/s, sigma_n > 20 Pa), per
    interval of t / tau_c."""
    rec = np.load(out / "record.npz")
    dH, dts, sig, t = rec["dH"], rec["dt"], rec["sig"], rec["t"]
    law = next(iter(tomllib.loads(table.read_text())["materials"].values()))
    dev = dH - np.trace(dH, axis1=2, axis2=3)[..., None, None] * np.eye(3) / 3
    kernel = np.ones(window)
    summed = np.apply_along_axis(lambda x: np.convolve(x, kernel, "same"), 0,
                                 dev.reshape(len(dts), -1)).reshape(dev.shape)
    span = np.convolve(dts, kernel, "same")
    u, sv, vt = np.linalg.svd(summed)
    gdot = sv[..., 0] / span[:, None]
    t_dir, n = u[..., :, 0], vt[..., 0, :]
    sym = 0.5 * (sig + np.swapaxes(sig, 2, 3))
    sn = -np.einsum("...i,...ij,...j->...", n, sym, n)
    mu_rve = np.abs(np.einsum("...i,...ij,...j->...", t_dir, sym, n)) / np.maximum(sn, 1e-12)
    inertial = gdot * law["grain_diameter"] * np.sqrt(law["grain_density"]
                                                      / np.maximum(sn, 1e-12))
    mu_law = law["mu_s"] + (law["mu_2"] - law["mu_s"]) / (law["I_0"] / np.maximum(
        inertial, 1e-12) + 1)
    flowing = (gdot > 1.0) & (sn > 20.0)
    print(f"window {window} MPM steps; medians over flowing samples")
    print("t/tau_c     samples   median I   tau/sigma_n RVE   mu(I) of the fit   RVE / fit")
    rows = [(f"{lo:4.1f}-{lo + 0.5:3.1f}", ((t / TAU_C >= lo) & (t / TAU_C < lo + 0.5))[:, None])
            for lo in np.arange(0.0, t.max() / TAU_C, 0.5)]
    for name, when in [*rows, ("all    ", np.ones((len(t), 1), bool))]:
        w = when & flowing
        if w.sum() < 10:
            continue
        ratio = np.median(mu_rve[w] / mu_law[w])
        print(f"{name}  {w.sum():9d}  {np.median(inertial[w]):9.3f}  "
              f"{np.median(mu_rve[w]):16.3f}  {np.median(mu_law[w]):17.3f}  {ratio:10.3f}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    f = sub.add_parser("frames")
    f.add_argument("out", type=Path)
    r = sub.add_parser("record")
    r.add_argument("case", type=Path)
    r.add_argument("out", type=Path)
    r.add_argument("--until", type=float, default=2.5, help="tau_c after release")
    c = sub.add_parser("compare")
    c.add_argument("out", type=Path)
    c.add_argument("table", type=Path, help="TOML with one [materials.X] type = mu_i table")
    c.add_argument("--window", type=int, default=20, help="MPM steps per rate sample")
    p = sub.add_parser("replay")
    p.add_argument("out", type=Path)
    p.add_argument("--points", type=int, default=8, help="how many of the most sheared")
    p.add_argument("--skip", type=int, default=0, help="skip the most sheared SKIP points")
    p.add_argument("--tiles", type=int, nargs="+", default=[2],
                   help="supercells of n x n x n copies (n >= 2)")
    p.add_argument("--packings", type=Path, nargs="+", default=[],
                   help="packings (.h5 state, `grainscale rve generate`) generated at other "
                        "sizes: a variant `fresh N` per size N, the points taking them in turn")
    p.add_argument("--variants", nargs="+",
                   help="run only these variants (as run, rebuilt, NxNxN, retiled, fresh N, "
                        "fresh N NxNxN)")
    a = ap.parse_args()
    if a.command == "frames":
        frames(a.out)
    elif a.command == "record":
        record(a.case, a.out, a.until)
    elif a.command == "compare":
        compare(a.out, a.table, a.window)
    else:
        replay(a.out, a.points, a.tiles, a.skip, a.packings, a.variants)


if __name__ == "__main__":
    main()
