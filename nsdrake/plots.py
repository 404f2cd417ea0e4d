"""Fig. 3-style plots of a run's traces."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never needs a display
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .traces import Traces  # noqa: E402


def plot_fig3(
    traces: Traces,
    path: Path,
    *,
    task_axes: tuple[str, ...],
    title: str = "",
    baseline: Traces | None = None,
    contact_time: float | None = None,
) -> None:
    """Writes the Fig. 3 panels (force; each task coordinate against its reference),
    the null-space velocity error and the joint-torque criterion to ``path``.

    ``baseline`` (the same run with q̇_dⁿ = 0), when given, is overlaid on the
    criterion panel.
    """
    t = traces["t"]
    rows = 2 + len(task_axes) + 1
    fig, axes = plt.subplots(rows, 1, figsize=(9, 2.3 * rows), sharex=True, constrained_layout=True)
    ax = axes[0]
    ax.plot(t, traces["f_n"], label="measured $f_n$", color="C0")
    ax.plot(t, traces["f_d"], "--", label="desired $f_d$", color="C3")
    ax.set_ylabel("normal force [N]")
    ax.legend(loc="lower right")
    for i, a in enumerate(task_axes):
        ax = axes[1 + i]
        ax.plot(t, traces[a], label=f"${a}$", color="C0")
        ax.plot(t, traces[f"{a}_d"], "--", label=f"${a}_d$", color="C3")
        ax.set_ylabel(f"{a} [m]")
        ax.legend(loc="best")
    ax = axes[1 + len(task_axes)]
    en = traces.block("en")
    qns = traces.block("qns")
    ax.plot(t, np.linalg.norm(en, axis=1), label=r"$\|e^n\|$ (error)", color="C0")
    ax.plot(t, np.linalg.norm(qns, axis=1), ":", label=r"$\|\dot q_d^{ns}\|$ (command)", color="C2")
    ax.set_yscale("symlog", linthresh=1e-4)
    ax.set_ylabel("null-space velocity [rad/s]")
    ax.legend(loc="best")
    ax = axes[-1]
    ax.plot(t, traces["p_tau"], label=r"$\|J^T F_d\|^2$ with null-space task", color="C0")
    if baseline is not None:
        ax.plot(baseline["t"], baseline["p_tau"], "--", label="without null-space task", color="C7")
    ax.set_ylabel(r"$p_\tau$ [N$^2$m$^2$]")
    ax.set_xlabel("time [s]")
    ax.legend(loc="best")
    if contact_time is not None:
        for ax in axes:
            ax.axvline(contact_time, color="k", lw=0.6, alpha=0.4)
    if title:
        fig.suptitle(title)
    fig.savefig(path, dpi=110)
    plt.close(fig)
