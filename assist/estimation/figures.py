"""Figures and truth of the estimation family: the estimate's figure (like the paper's Figs. 3-4) and the
stiffness truth a simulated log's sidecar holds. Library code (``ptw-assist estimate`` calls it).

May import: ``ptw_env``, numpy, matplotlib (lazily).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def truth_scales(meta: dict) -> tuple[float, float] | None:
    """``(front_scale, rear_scale)`` of a ``tire_stiffness`` truth in a sidecar (logs.md ``truth.causes``), if any;
    ``(1, 1)`` for a sidecar whose truth lists causes but no ``tire_stiffness``; None without truth."""
    causes = (meta or {}).get("truth", {}).get("causes") if isinstance(meta, dict) else None
    if not isinstance(causes, list):
        return None
    for c in causes:
        if isinstance(c, dict) and c.get("cause") == "tire_stiffness":
            p = c.get("params", {})
            return float(p.get("front_scale", 1.0)), float(p.get("rear_scale", 1.0))
    # a log whose truth lists causes but no tire_stiffness has the nominal tires
    return (1.0, 1.0)


def plot_estimate(res, log, path: str | Path, nominal: np.ndarray, truth: np.ndarray | None = None,
                  mass: float | None = None) -> None:
    """Figure like the paper's Figs. 3-4: stiffness ratios over time (with truth) and estimated vs measured outputs.

    ``mass`` [kg] is the vehicle's (estimated ``ay = (Fyf + Fyr) / M``); default the reference scooter's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ptw_env.vehicle import REFERENCE_SCOOTER

    from assist.estimation.lpv_model import THETA_NAMES

    mass = REFERENCE_SCOOTER.mass if mass is None else float(mass)

    fig, axs = plt.subplots(2, 2, figsize=(11, 6.5), constrained_layout=True)
    ax = axs[0, 0]
    for j, name in enumerate(THETA_NAMES):
        ax.plot(res.t, res.stiffness[:, j] / nominal[j], color=f"C{j}", label=name)
        if truth is not None:
            ax.axhline(truth[j] / nominal[j], color=f"C{j}", ls="--", lw=0.8)
    ax.set(xlabel="t [s]", ylabel="C / C_0 [-]", title=f"{res.method}: stiffness (dashed: truth)")
    ax.legend(fontsize=8, loc="best")
    c = log.columns
    panels = [("roll_rate", 4, "roll rate [rad/s]"), ("yaw_rate", 3, "yaw rate [rad/s]"), ("ay", None, "ay [m/s^2]")]
    for ax, (col, idx, lab) in zip((axs[0, 1], axs[1, 0], axs[1, 1]), panels):
        ax.plot(log.t, c[col], color="0.6", lw=0.6, label="measured")
        if res.x_hat is not None:
            est = res.x_hat[:, idx] if idx is not None else (res.x_hat[:, 6] + res.x_hat[:, 7]) / mass
            ax.plot(res.t, est, color="C0", lw=1.0, ls="--", label="estimate")
        if col == "ay" and res.x_hat is not None:
            ax2 = ax.twinx()
            ax2.plot(res.t, np.degrees(res.x_hat[:, 0]), color="C3", lw=0.8)
            ax2.set_ylabel("estimated roll [deg]", color="C3")
        ax.set(xlabel="t [s]", ylabel=lab)
        ax.legend(fontsize=8, loc="upper left")
    fig.savefig(path, dpi=110)
    plt.close(fig)


__all__ = ["plot_estimate", "truth_scales"]
