"""Per-run plots in the style of the papers' figures (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import numpy.typing as npt


def plot_run(table: dict[str, npt.NDArray[np.float64]], out_dir: Path, *, title: str) -> Path:
    """Angle and estimate, position error, speed, phase-A current: one PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = table["t"]
    fig, ax = plt.subplots(4, 1, figsize=(9, 10), sharex=True)
    ax[0].plot(t, table["theta_e"], lw=0.8, label=r"$\theta_e$ (true)")
    ax[0].plot(t, table["theta_hat"], lw=0.8, ls="--", label=r"$\hat\theta_e$ (estimated)")
    ax[0].set_ylabel("electrical angle (rad)")
    ax[0].legend(loc="upper right", fontsize=8)
    ax[1].plot(t, table["theta_err_deg"], lw=0.6, color="tab:red")
    ax[1].set_ylabel(r"$\Delta\theta$ (deg, electrical)")
    ax[1].axhline(0.0, color="k", lw=0.5)
    ax[2].plot(t, table["w_m_rpm"], lw=0.8, label="true")
    ax[2].plot(t, table["w_hat_rpm"], lw=0.8, ls="--", label="estimated")
    ax[2].plot(t, table["w_ref_rpm"], lw=0.8, color="k", alpha=0.5, label="reference")
    ax[2].set_ylabel("speed (rpm)")
    ax[2].legend(loc="upper right", fontsize=8)
    ax[3].plot(t, table["i_a"], lw=0.5)
    ax[3].set_ylabel(r"$i_a$ (A)")
    ax[3].set_xlabel("time (s)")
    for a in ax:
        a.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    path = out_dir / "run.png"
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
