"""Bearing pressure against settlement of the multiscale footing, its Mohr-Coulomb twins
and Prandtl's limit load at the RVE's steady and peak angles (README.md).

    python examples/footing/plot.py footing --twins footing_mc/phi_19.48 footing_mc/phi_26
        [--png footing.png]

Reads each run's history.csv: `bearing_pressure` (force over the footing's section in
the slice) over the surcharge q_0 against `depth` over B, from t = 0 (the push). Marks
N_q(phi) = exp(pi tan phi) tan^2(pi/4 + phi/2) (Prandtl 1921, Reissner 1924: a weightless
Mohr-Coulomb bed, c = 0, associated) at the RVE's angles, and prints, per run, the mean
q / q_0 over the second half of the settlement, the plateau the weightless bed reaches.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import grainscale as gs  # noqa: E402

B = 1.0  # m, the footing's width (footing.toml: its half, 0.5 m, on the symmetry plane)
SURCHARGE = 10e3  # Pa, footing.toml's traction
ANGLES = {"steady": 19.48, "peak": 26.0}  # deg, the RVE at 10 kPa (footing.toml)


def prandtl_nq(phi: float) -> float:
    """N_q = exp(pi tan phi) tan^2(pi/4 + phi/2), phi in degrees."""
    p = math.radians(phi)
    return math.exp(math.pi * math.tan(p)) * math.tan(math.pi / 4 + p / 2) ** 2


def curve(run: Path) -> tuple[np.ndarray, np.ndarray, str]:
    """(settlement / B, q / q_0, the run's title) from t >= 0."""
    r = gs.open_result(run)
    h = r.history
    push = h["time"] >= 0
    return h["depth"][push] / B, h["bearing_pressure"][push] / SURCHARGE, r.case.title


def plateau(s: np.ndarray, nq: np.ndarray) -> float:
    """Mean q / q_0 over the second half of the settlement reached."""
    return float(nq[s >= 0.5 * s.max()].mean())


def plot(multiscale: Path, twins: list[Path], png: Path) -> Path:
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for run, style in [(multiscale, "k-"), *((t, "--") for t in twins)]:
        s, nq, title = curve(run)
        label = "multiscale (RVEs)" if run == multiscale else title.split(", ", 1)[-1]
        ax.plot(s, nq, style, lw=1.2, label=f"{label}: {plateau(s, nq):.2f}")
        print(f"{run}: q/q_0 over the second half {plateau(s, nq):.3f} ({title})")
    for (name, phi), ls in zip(ANGLES.items(), (":", "-."), strict=True):
        ax.axhline(prandtl_nq(phi), color="tab:red", ls=ls, lw=1,
                   label=f"Prandtl N_q, RVE's {name} angle {phi:g} deg: "
                         f"{prandtl_nq(phi):.2f}")
    ax.set(xlabel="settlement / B", ylabel="bearing pressure / q_0", xlim=(0, None),
           ylim=(0, None), title="strip footing on a weightless bed, q_0 = 10 kPa")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("multiscale", type=Path, help="run folder of footing.toml")
    ap.add_argument("--twins", type=Path, nargs="*", default=[],
                    help="run folders of twin.py")
    ap.add_argument("--png", type=Path, default=None)
    args = ap.parse_args()
    print(plot(args.multiscale, args.twins, args.png or args.multiscale / "footing.png"))


if __name__ == "__main__":
    main()
