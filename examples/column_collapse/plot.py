"""Plot the column's runout against t / tau_c from a run's history.csv.

    python examples/column_collapse/plot.py OUT_DIR [--png runout.png]

Marks the published final runouts for a = 0.6 (validation.md, case 2): Lube et al. 2005,
1.2 a = 0.72, and Lajeunesse et al. 2005 (the seed's experiment), 1.8 a = 1.08.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

import grainscale as gs  # noqa: E402


def plot(out_dir: Path, png: Path, aspect: float = 0.6) -> Path:
    h = gs.open_result(out_dir).history
    after = h["t_over_tc"] >= 0
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(h["t_over_tc"][after], h["runout_ratio"][after], "k-", label="MPM (this run)")
    ax.axhline(1.2 * aspect, color="tab:blue", ls="--", label=f"Lube et al. 2005: 1.2a = "
               f"{1.2 * aspect:.2f}")
    ax.axhline(1.8 * aspect, color="tab:red", ls=":", label=f"Lajeunesse et al. 2005: 1.8a "
               f"= {1.8 * aspect:.2f}")
    ax.set_xlabel("t / tau_c")
    ax.set_ylabel("(L - L_i) / L_i")
    ax.set_xlim(left=0)
    ax.set_ylim(bottom=0)
    ax.legend(loc="lower right")
    ax.set_title(f"column collapse, a = {aspect}")
    fig.tight_layout()
    fig.savefig(png, dpi=120)
    plt.close(fig)
    return png


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out_dir", type=Path)
    ap.add_argument("--png", type=Path, default=None)
    ap.add_argument("--aspect", type=float, default=0.6)
    args = ap.parse_args()
    png = args.png or args.out_dir / "runout.png"
    print(plot(args.out_dir, png, args.aspect))


if __name__ == "__main__":
    main()
