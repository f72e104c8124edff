"""Figures written by the CLI (matplotlib, Agg backend: no display needed)."""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, TypeVar

import matplotlib

matplotlib.use('Agg')
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:
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
