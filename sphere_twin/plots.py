"""Figures written by the CLI (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Literal, TypeVar

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from sphere_sim.integrate.solve import Trajectory
    from sphere_sim.kicks.characteristics import OffsetSolution

PathT = TypeVar('PathT', bound=str | os.PathLike[str])


def plot_pulse_sweep(trajectories: Sequence[Trajectory], voltages_v: Sequence[float],
                     threshold_v: float, path: PathT, title: str = '') -> PathT:
    """Fig. 4 layout: beam z and phi over time (a) and sphere height change (b)."""
    fig, axes = plt.subplots(3, 1, figsize=(7.5, 8.5), sharex=True)
    cmap = plt.get_cmap('viridis')
    for i, (traj, v) in enumerate(zip(trajectories, voltages_v, strict=True)):
        color = cmap(i / max(1, len(voltages_v) - 1))
        model = traj.model
        t_ms = traj.t * 1e3
        axes[0].plot(t_ms, traj.x[0] * 1e6, color=color, label=f'{v:.0f} V')
        axes[1].plot(t_ms, traj.x[1] * 1e3, color=color)
        if model.has_sphere:
            z = traj.x[model.sphere_offset + 2]
            axes[2].plot(t_ms, (z - z[0]) * 1e6, color=color)
    axes[0].set_ylabel('beam 1 $z_S$ (µm)')
    axes[1].set_ylabel(r'beam 1 $\varphi$ (mrad)')
    axes[2].set_ylabel('sphere height change (µm)')
    axes[2].set_xlabel('time (ms)')
    axes[0].legend(ncol=3, fontsize=8)
    axes[0].set_title(title or f'5 ms pulses on all beams; dynamic pull-in at {threshold_v:.1f} V')
    for ax in axes:
        ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def plot_lines(x: ArrayLike, ys: Sequence[ArrayLike], labels: Sequence[str], xlabel: str,
               ylabel: str, path: str | os.PathLike[str], title: str = '',
               logx: bool = False, logy: bool = False) -> NDArray[Any]:
    """A plain multi-line plot."""
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for y, label in zip(ys, labels, strict=True):
        ax.plot(x, y, marker='o', label=label)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    if logx:
        ax.set_xscale('log')
    if logy:
        ax.set_yscale('log')
    ax.grid(alpha=0.3)
    ax.legend()
    ax.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return np.asarray(x)


def plot_offsets(solutions: Sequence[OffsetSolution], path: PathT) -> PathT:
    """Fig. 8 layout: the offset (V) at each grid state and the remaining direction error."""
    x = np.array([s.x_sn for s in solutions])
    y = np.array([s.y_sn for s in solutions])
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.5))
    panels = ((np.array([s.offset_v for s in solutions]), 'offset (V)', 'coolwarm'),
              (np.degrees([abs(s.direction_error_rad) for s in solutions]),
               '|direction error| after offset (deg)', 'viridis'))
    for ax, (value, label, cmap) in zip(axes, panels, strict=True):
        art = ax.scatter(x, y, c=value, cmap=cmap, s=140, marker='s')
        fig.colorbar(art, ax=ax, label=label)
        ax.set_xlabel('$x_{sn}$')
        ax.set_ylabel('$y_{sn}$')
        ax.set_aspect('equal')
        ax.grid(alpha=0.3)
    axes[0].set_title('voltage offset on the compensating beam')
    axes[1].set_title('residual direction error')
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


# --- kicks on a time axis, the x-y panel, replay errors -----------------------------------------

# Resolution the run figures are saved at (savefig's dpi): the kick marks are sized for it.
SAVE_DPI = 120
# A '|' kick tick is 1 pt wide (1.7 px at SAVE_DPI). With successive ticks closer than this on
# the saved figure, under 2.3 px of white is left between them and they read as one solid bar
# (the demo's 15 kicks/s over 33 s fell 1.1 px apart): closer than this, the kicks are drawn as
# a rate instead. On the report's error panel (about 560 px for the demo's 33 s) the switch
# falls near 4 kicks/s: a setpoint's handful of kicks stays ticks, the trajectory's become a rate.
MIN_KICK_TICK_GAP_PX = 4.0
# The rate is counted per second (it reads as the kicks in that second); a run shorter than
# MIN_KICK_RATE_BINS seconds is cut into that many bins instead.
KICK_RATE_BIN_S = 1.0
MIN_KICK_RATE_BINS = 5
RATE_HEADROOM = 2.0
KICK_TICK_LABEL = 'kicks'
KICK_RATE_LABEL = 'kick rate (kicks/s)'
KickMarks = Literal['ticks', 'rate', 'none']

# The x-y panel shows the normal's x and y components as degrees of tilt, asin(x_sn) and
# asin(y_sn): the unit of the error panel beside it and of every printed figure, so the
# distance from the path to the setpoint reads as the error (for small tilts).
TILT_X_LABEL = 'tilt towards x, asin $x_{sn}$ (deg)'
TILT_Y_LABEL = 'tilt towards y, asin $y_{sn}$ (deg)'

# The replay errors are plotted in the unit replay-check prints them in.
REPLAY_ERROR_LABEL = 'simulated vs recorded normal (rad)'
SORTED_SHARE_LABEL = 'share of samples with a smaller error (%)'
# An exact replay (lockstep, discrete plant) has zero error: kept on the log axis at this floor.
REPLAY_FLOOR_RAD = 1e-15
# The replay starts on the recorded normal, so its first samples' error is zero or rounding:
# the log axis starts a little below this percentile of the errors instead of decades below.
REPLAY_AXIS_PERCENTILE = 1.0


def kick_marks(kick_times_s: ArrayLike, span_s: float, axis_width_px: float) -> KickMarks:
    """How kicks are drawn on a time axis ``axis_width_px`` wide that shows ``span_s``: as
    ticks when the median gap between successive kicks is at least MIN_KICK_TICK_GAP_PX on it,
    else as a rate. The median, not the mean: kicks that come in bursts between long rests
    merge within the bursts even though the mean gap is wide."""
    times = np.sort(np.asarray(kick_times_s, dtype=float))
    if times.size == 0:
        return 'none'
    if times.size == 1:
        return 'ticks'
    gap_px = float(np.median(np.diff(times))) * axis_width_px / max(span_s, 1e-12)
    return 'ticks' if gap_px >= MIN_KICK_TICK_GAP_PX else 'rate'


def axis_width_px(ax: Axes) -> float:
    """The width of ``ax`` on the figure saved at SAVE_DPI."""
    figure = ax.get_figure(root=True)
    assert figure is not None  # an Axes made by plt.subplots belongs to a figure
    return float(ax.get_position().width * figure.get_figwidth() * SAVE_DPI)


def draw_kicks(ax: Axes, kick_times_s: ArrayLike, span: tuple[float, float]) -> Axes:
    """Mark the kicks on time axis ``ax`` showing ``span`` (start_s, end_s): thin ticks along
    its bottom edge when sparse, else the kick rate on a twin axis (:func:`kick_marks`).
    Returns the axes that hold the marks (``ax``, or the twin), for the legend."""
    times = np.asarray(kick_times_s, dtype=float)
    start_s, end_s = span
    marks = kick_marks(times, end_s - start_s, axis_width_px(ax))
    if marks == 'ticks':
        # On the x axis' transform (y in axes fraction): the ticks stay on the bottom edge
        # whatever the error axis' limits become.
        ax.plot(times, np.full(times.size, 0.02), '|', color='tab:red', ms=8,
                transform=ax.get_xaxis_transform(), label=KICK_TICK_LABEL)
        return ax
    if marks == 'none':
        return ax
    bins = max(MIN_KICK_RATE_BINS, math.ceil((end_s - start_s) / KICK_RATE_BIN_S))
    counts, edges = np.histogram(times, bins=bins, range=(start_s, end_s))
    rate_ax = ax.twinx()
    rate_ax.stairs(counts / np.diff(edges), edges, color='tab:red', alpha=0.7,
                   label=KICK_RATE_LABEL)
    rate_ax.set_ylabel(KICK_RATE_LABEL, color='tab:red')
    # Headroom above the highest rate keeps the rate in the lower part of the panel, under
    # the error's peaks and the legend.
    rate_ax.set_ylim(0.0, RATE_HEADROOM * max(float(counts.max() / np.diff(edges).min()), 1.0))
    return rate_ax


def legend_of(*axes: Axes, **kwargs: Any) -> None:
    """One legend holding the labelled artists of all ``axes`` (a twin axis' artists would
    otherwise need a legend of their own), on the last of them: a twin is drawn over its
    parent, and would hide a legend of the parent's."""
    handles: list[Any] = []
    labels: list[str] = []
    for ax in dict.fromkeys(axes):
        more_handles, more_labels = ax.get_legend_handles_labels()
        handles += more_handles
        labels += more_labels
    axes[-1].legend(handles, labels, **kwargs)


def tilt_deg(normals: ArrayLike) -> NDArray[np.float64]:
    """(n, 2): the x and y components of unit normals (n, 3) as degrees of tilt."""
    xy = np.asarray(normals, dtype=float).reshape(-1, 3)[:, :2]
    return np.degrees(np.arcsin(np.clip(xy, -1.0, 1.0)))


def draw_tilt_path(ax: Axes, normals: ArrayLike, setpoints: ArrayLike,
                   trajectory: ArrayLike) -> None:
    """The surface normal's path in degrees of tilt, the reference trajectory (normals along
    it, dashed) where there is one, and each setpoint as a cross."""
    path = tilt_deg(normals)
    ax.plot(path[:, 0], path[:, 1], lw=1, label='surface normal')
    moving = tilt_deg(trajectory)
    if moving.size:
        ax.plot(moving[:, 0], moving[:, 1], 'k--', lw=1, label='reference trajectory')
    held = tilt_deg(setpoints)
    if held.size:
        ax.plot(held[:, 0], held[:, 1], 'X', color='black', ms=10, ls='none',
                label='setpoint')
    ax.set_xlabel(TILT_X_LABEL)
    ax.set_ylabel(TILT_Y_LABEL)
    ax.set_aspect('equal', adjustable='datalim')
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def plot_replay_errors(times_s: ArrayLike, errors_rad: dict[str, ArrayLike], path: PathT,
                       title: str = '') -> PathT:
    """An open-loop replay's error, in rad: (a) against time, one line per replayed set, and
    (b) each set's errors sorted, with its RMS in the legend. Two sets' thousands of noisy
    samples overlap in (a); sorted, one curve lies below the other where a set replays better.
    """
    fig, (ax_time, ax_sorted) = plt.subplots(2, 1, figsize=(8, 7.5))
    for label, errors in errors_rad.items():
        shown = np.maximum(np.asarray(errors, dtype=float), REPLAY_FLOOR_RAD)
        rms = float(np.sqrt(np.mean(np.square(errors)))) if shown.size else 0.0
        ax_time.semilogy(times_s, shown, lw=0.7, alpha=0.8, label=label)
        share = 100.0 * (np.arange(shown.size) + 0.5) / max(shown.size, 1)
        ax_sorted.semilogy(share, np.sort(shown), lw=1.5,
                           label=f'{label}: RMS {rms:.3g} rad')
    bottom_rad = replay_axis_bottom_rad(list(errors_rad.values()))
    ax_time.set_xlabel('time (s)')
    ax_time.set_ylabel(REPLAY_ERROR_LABEL)
    ax_sorted.set_xlabel(SORTED_SHARE_LABEL)
    ax_sorted.set_ylabel(REPLAY_ERROR_LABEL)
    for ax in (ax_time, ax_sorted):
        ax.set_ylim(bottom=bottom_rad)
        ax.grid(alpha=0.3, which='both')
        ax.legend(fontsize=8)
    ax_time.set_title(title)
    fig.tight_layout()
    fig.savefig(path, dpi=SAVE_DPI)
    plt.close(fig)
    return path


def replay_axis_bottom_rad(errors_rad: Sequence[ArrayLike]) -> float:
    """Where the replay plot's log axis starts: a third of the REPLAY_AXIS_PERCENTILE-th
    percentile of all the errors, no lower than REPLAY_FLOOR_RAD."""
    pooled = np.concatenate([np.zeros(0)] + [np.ravel(np.asarray(e, dtype=float))
                                             for e in errors_rad])
    if pooled.size == 0:
        return REPLAY_FLOOR_RAD
    return max(REPLAY_FLOOR_RAD, float(np.percentile(pooled, REPLAY_AXIS_PERCENTILE)) / 3.0)
