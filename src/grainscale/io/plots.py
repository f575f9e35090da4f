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


def plot_flow(path: str | Path, col: dict, fits: dict, title: str = "") -> None:
    """Steady mu against I (both measures, 95 % bands, fitted mu(I)) and porosity."""
    import numpy as np

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 4), constrained_layout=True)
    for m, i, label, fmt in (("mu", "I", "tau/sigma_n vs I(sigma_n)", "o"),
                             ("mu_p", "I_p", "sqrt(J2)/p vs I(p)", "s")):
        bars = ax1.errorbar(col[i], col[m], xerr=col[f"{i}_err"], yerr=col[f"{m}_err"],
                            fmt=fmt, capsize=3, label=label)
        if m in fits:
            f = fits[m]
            x = np.geomspace(col[i].min() / 2, col[i].max() * 2, 100)
            ax1.plot(x, f["mu_s"] + (f["mu_2"] - f["mu_s"]) / (f["I_0"] / x + 1), "--",
                     color=bars[0].get_color(),
                     label=f"fit: mu_s {f['mu_s']:.3f}, mu_2 {f['mu_2']:.3f}, "
                           f"I_0 {f['I_0']:.3g}")
    ax2.errorbar(col["I"], col["porosity"], xerr=col["I_err"], yerr=col["porosity_err"],
                 fmt="o", capsize=3)
    ax1.set(xscale="log", xlabel="inertial number I", ylabel="effective friction mu")
    ax2.set(xscale="log", xlabel="inertial number I", ylabel="porosity")
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3, which="both")
    ax1.legend(fontsize=8)
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=120)
    plt.close(fig)
