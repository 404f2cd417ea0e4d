"""Fig. 3-style plots of a run's traces."""

from __future__ import annotations

import textwrap
from pathlib import Path

import numpy as np

from nsdrake.experiment.traces import Traces
from nsdrake.reporting.metrics import torque_steps

MODE_NAMES = {0: "none", 1: "obstacle", 2: "joint torque", 3: "manipulability", 4: "joint limits"}


def _pyplot():
    """matplotlib's pyplot on the Agg backend (files only; never needs a display), imported
    when a figure is drawn, as compare's and sweep's plots do: importing this module (and
    so the command line, which every variant and sweep process started from the
    ``nsdrake`` script imports again) does not load matplotlib, 0.4 CPU-s of imports."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _mode_axis(ax, traces: Traces, fontsize: int) -> None:
    """The mode over time as a step plot, its ticks named after Fig. 1's branches."""
    ax.step(traces["t"], traces["mode"], where="post", color="k", lw=1.2, label="mode")
    ax.set_yticks(list(MODE_NAMES), [f"{k} {v}" for k, v in MODE_NAMES.items()], fontsize=fontsize)
    ax.set_ylim(-0.3, max(MODE_NAMES) + 0.3)
    ax.set_ylabel("level-2 criterion")


def _mode_panel(ax, traces: Traces, selector=None) -> None:
    """Mode (step plot, left axis) with d_min and w (right axes) and their limits."""
    t = traces["t"]
    _mode_axis(ax, traces, fontsize=7)
    right = ax.twinx()
    right.plot(t, traces["d_min"], color="C1", label=r"$d_{min}$ [m]")
    right.plot(t, traces["w"], color="C2", label="w [m$^2$]")
    if selector is not None:
        right.axhline(selector.d_lim, color="C1", ls=":", lw=0.8, label=r"$d_{lim}$")
        right.axhline(selector.w_lim, color="C2", ls=":", lw=0.8, label=r"$w_{lim}$")
    right.set_ylabel(r"$d_{min}$ [m], w [m$^2$]")
    right.legend(loc="upper right", fontsize=7)


def plot_fig3(
    traces: Traces,
    path: Path,
    *,
    task_axes: tuple[str, ...],
    title: str = "",
    baseline: Traces | None = None,
    contact_time: float | None = None,
    selector=None,
) -> None:
    """Writes the Fig. 3 panels (force; each task coordinate against its reference),
    the null-space velocity error, the mode with d_min and w, and the
    joint-torque criterion to ``path``.

    ``baseline`` (the same run with q̇_dⁿ = 0), when given, is overlaid on the
    criterion panel; ``selector`` (the scenario's limits) draws d_lim and w_lim.
    """
    plt = _pyplot()
    t = traces["t"]
    rows = 2 + len(task_axes) + 2
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
    _mode_panel(axes[2 + len(task_axes)], traces, selector)
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
        fig.suptitle(textwrap.fill(title, 90), fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_priority(traces: Traces, path: Path, *, title: str = "", selector=None) -> None:
    """The mode timeline and each criterion over time (d_min, w, p_tau), with the
    limits of Fig. 1's tree, and the largest torque step per control period."""
    plt = _pyplot()
    t = traces["t"]
    fig, axes = plt.subplots(5, 1, figsize=(9, 11), sharex=True, constrained_layout=True)
    mode = traces["mode"]
    _mode_axis(axes[0], traces, fontsize=8)
    colors = {1: "C1", 2: "C0", 3: "C2"}
    panels = [
        ("d_min", 1, r"$d_{min}$ [m]"),
        ("w", 3, "manipulability w [m$^2$]"),
        ("p_tau", 2, r"$p_\tau$ [N$^2$m$^2$]"),
    ]
    for ax, (column, m, label) in zip(axes[1:4], panels, strict=True):
        ax.plot(t, traces[column], color="0.4", lw=1)
        shown = np.where(mode == m, traces[column], np.nan)
        ax.plot(t, shown, color=colors[m], lw=2.2, label=f"while mode {m} ({MODE_NAMES[m]}) is active")
        ax.set_ylabel(label)
        ax.legend(loc="best", fontsize=8)
    if selector is not None:
        axes[1].axhline(selector.d_lim, color="C1", ls=":", label=r"$d_{lim}$")
        axes[1].axhline(
            selector.d_lim + selector.d_band, color="C1", ls="--", lw=0.7, label=r"$d_{lim}+d_{band}$"
        )
        axes[2].axhline(selector.w_lim, color="C2", ls=":", label=r"$w_{lim}$")
        axes[2].axhline(
            selector.w_lim + selector.w_band, color="C2", ls="--", lw=0.7, label=r"$w_{lim}+w_{band}$"
        )
        axes[1].legend(loc="best", fontsize=8)
        axes[2].legend(loc="best", fontsize=8)
    ax = axes[4]
    steps = torque_steps(traces)
    ax.semilogy(t[1:], np.maximum(steps, 1e-9), color="C3", lw=0.8)
    for k in np.flatnonzero(np.diff(mode) != 0) + 1:
        for a in axes:
            a.axvline(t[k], color="k", lw=0.5, alpha=0.3)
    ax.set_ylabel(r"max$_i |\Delta\tau_i|$ per period [N m]")
    ax.set_xlabel("time [s]")
    if title:
        fig.suptitle(textwrap.fill(title, 90), fontsize=10)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_pose(
    traces: Traces,
    path: Path,
    *,
    normal: np.ndarray,
    task_axes: tuple[str, ...],
    title: str = "",
    baseline: Traces | None = None,
    contact_time: float | None = None,
    d_lim: float | None = None,
) -> None:
    """A pose task on a surface (panda_wipe, panda_self_motion): the normal force; the
    tool's path on the surface against its reference; the in-plane position error and
    the orientation error; the distances of the arm's links to each obstacle (and, from
    ``baseline``, the same run with q̇_dⁿ = 0); every joint's margin to its position,
    speed and torque limits as a fraction of the limit's scale; the elbow's swivel and
    the mode."""
    plt = _pyplot()
    fig = plt.figure(figsize=(11, 13), constrained_layout=True)
    grid = fig.add_gridspec(5, 2)
    _force_axis(fig.add_subplot(grid[0, 0]), traces)
    path_axis = fig.add_subplot(grid[0, 1])
    _surface_path_axis(path_axis, traces, normal, task_axes)
    _pose_error_axis(fig.add_subplot(grid[1, :]), traces, normal, task_axes)
    _obstacle_distance_axis(fig.add_subplot(grid[2, :]), traces, baseline, d_lim)
    for cell, kind in zip((grid[3, 0], grid[3, 1], grid[4, 0]), ("q", "v", "tau"), strict=True):
        _margin_axis(fig.add_subplot(cell), traces, kind)
    _swivel_and_mode_axis(fig.add_subplot(grid[4, 1]), traces, baseline)
    if contact_time is not None:
        for a in fig.axes:
            if a is not path_axis:
                a.axvline(contact_time, color="k", lw=0.6, alpha=0.4)
    if title:
        fig.suptitle(textwrap.fill(title, 100), fontsize=10)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _force_axis(ax, traces: Traces) -> None:
    ax.plot(traces["t"], traces["f_n"], color="C0", label="measured $f_n$")
    ax.plot(traces["t"], traces["f_d"], "--", color="C3", label="desired $f_d$")
    ax.set_ylabel("normal force [N]")
    ax.legend(loc="lower right", fontsize=8)


def _surface_path_axis(ax, traces: Traces, normal: np.ndarray, task_axes: tuple[str, ...]) -> None:
    """The path on the surface: the two task axes the normal is not along (empty if fewer)."""
    plane = [a for a, c in zip(task_axes, normal, strict=True) if abs(c) < 0.5][:2]
    if len(plane) != 2:
        return
    ax.plot(traces[f"{plane[0]}_d"], traces[f"{plane[1]}_d"], "--", color="C3", lw=2, label="reference")
    ax.plot(traces[plane[0]], traces[plane[1]], color="C0", lw=0.8, label="tool")
    ax.set_xlabel(f"{plane[0]} [m]")
    ax.set_ylabel(f"{plane[1]} [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.ticklabel_format(useOffset=True, style="sci", scilimits=(-3, 3))
    ax.legend(loc="best", fontsize=8)


def _pose_error_axis(ax, traces: Traces, normal: np.ndarray, task_axes: tuple[str, ...]) -> None:
    """The position error along the surface and, on a right axis, the orientation error."""
    from nsdrake.reporting.metrics import in_plane_errors

    t = traces["t"]
    error = 1e3 * in_plane_errors(traces, normal, task_axes)
    ax.plot(t, error, color="C0", label="position error along the surface")
    ax.set_ylabel("position error [mm]")
    if "rot_err" in traces:
        right = ax.twinx()
        right.plot(t, np.degrees(traces["rot_err"]), color="C2", lw=0.8, label="orientation error")
        right.set_ylabel("orientation error [deg]")
        right.legend(loc="upper right", fontsize=8)
    ax.legend(loc="upper left", fontsize=8)


def _obstacle_distance_axis(ax, traces: Traces, baseline: Traces | None, d_lim: float | None) -> None:
    """Every d_<obstacle> column, dotted from ``baseline``, with the selector's d_lim."""
    for k, name in enumerate(n for n in traces.names if n.startswith("d_") and n != "d_min"):
        ax.plot(traces["t"], traces[name], color=f"C{k}", label=f"{name} (with null-space task)")
        if baseline is not None and name in baseline:
            ax.plot(baseline["t"], baseline[name], ":", color=f"C{k}", label=f"{name} without")
    if d_lim is not None:
        ax.axhline(d_lim, color="k", ls="--", lw=0.8, label=r"$d_{lim}$")
    ax.set_ylabel("link–obstacle distance [m]")
    ax.legend(loc="best", fontsize=8, ncol=2)


_MARGIN_LABELS = {"q": "position margin [rad]", "v": "speed margin [rad/s]", "tau": "torque margin [N m]"}


def _margin_axis(ax, traces: Traces, kind: str) -> None:
    """Each joint's ``<kind>_margin`` column (kind q, v or tau) against zero, the limit;
    an arm without joint position limits has no margin columns (the panel says so)."""
    ax.set_ylabel(_MARGIN_LABELS[kind])
    ax.set_xlabel("time [s]")
    if f"{kind}_margin1" not in traces:
        ax.text(0.5, 0.5, "the arm has no joint limits", ha="center", va="center", transform=ax.transAxes)
        return
    block = traces.block(f"{kind}_margin")
    for i in range(block.shape[1]):
        ax.plot(traces["t"], block[:, i], lw=0.9, label=f"joint {i + 1}")
    ax.axhline(0.0, color="k", lw=0.8)
    if kind == "q":
        ax.legend(loc="best", fontsize=7, ncol=4)


def _swivel_and_mode_axis(ax, traces: Traces, baseline: Traces | None) -> None:
    _mode_axis(ax, traces, fontsize=7)
    if "swivel" in traces:
        right = ax.twinx()
        right.plot(traces["t"], traces["swivel"], color="C4", label="elbow swivel")
        if baseline is not None and "swivel" in baseline:
            right.plot(baseline["t"], baseline["swivel"], ":", color="C4", label="without null-space task")
        right.set_ylabel("elbow swivel [rad]")
        right.legend(loc="upper right", fontsize=8)
    ax.set_xlabel("time [s]")
