"""Plots of stress paths (matplotlib, no display needed)."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def plot_stress_path(path: str | Path, curves: dict[str, dict[str, list[float]]],
                     x: str = "axial_strain", title: str = "") -> None:
    """q/p and eps_v against `x` for one or more labelled curves, side by side.

    `curves` maps a label to columns {x, "q_over_p", "volumetric_strain"}.
    """
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    styles = ["-", "--", ":", "-."]
    for k, (label, c) in enumerate(curves.items()):
        ax1.plot(c[x], c["q_over_p"], styles[k % 4], label=label)
        ax2.plot(c[x], c["volumetric_strain"], styles[k % 4], label=label)
    xlabel = {"axial_strain": "axial strain (L0 - L)/L0",
              "shear_strain": "shear strain gamma"}.get(x, x)
    ax1.set(xlabel=xlabel, ylabel="q / p")
    ax2.set(xlabel=xlabel, ylabel="volumetric strain ln(V/V0) (+ dilation)")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
        ax.legend()
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)
