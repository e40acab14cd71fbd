"""Plots of a sweep's results table: a metric against one swept setting."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from matplotlib.artist import Artist
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from slamkit.viz.plots import new_figure

__all__ = ["metric_against_setting_figure", "plot_metric_against_setting"]


def _numeric(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value) if math.isfinite(value) else None


def plot_metric_against_setting(
    ax: Axes, rows: Sequence[Mapping[str, Any]], setting: str, metric: str
) -> list[Artist]:
    """Every run's ``metric`` against its ``setting`` (one colour per estimator and data
    set), with the mean over the runs at each value joined by a line. A setting with
    non-numeric values is placed at evenly spaced ticks."""
    artists: list[Artist] = []
    values = [r.get(setting) for r in rows]
    numeric = all(_numeric(v) is not None for v in values)
    labels = sorted({str(v) for v in values}) if not numeric else []
    pairs = sorted({(str(r["estimator"]), str(r["dataset"])) for r in rows})
    for est, ds in pairs:
        xs, ys = [], []
        for r in rows:
            y = _numeric(r.get(metric))
            if y is None or (str(r["estimator"]), str(r["dataset"])) != (est, ds):
                continue
            v = r.get(setting)
            x = _numeric(v) if numeric else float(labels.index(str(v)))
            assert x is not None
            xs.append(x)
            ys.append(y)
        if not xs:
            continue
        x_arr, y_arr = np.array(xs), np.array(ys)
        label = est if len(pairs) == 1 else f"{est} on {ds}"
        points = ax.scatter(x_arr, y_arr, s=10, alpha=0.45, label=label)
        at = np.unique(x_arr)
        means = np.array([y_arr[x_arr == x].mean() for x in at])
        colour = tuple(np.asarray(points.get_facecolor())[0][:3])
        (line,) = ax.plot(at, means, "-o", ms=4, color=colour)
        artists += [points, line]
    if not numeric:
        ax.set_xticks(range(len(labels)), labels)
    ax.set_xlabel(setting)
    ax.set_ylabel(metric)
    ax.grid(alpha=0.3)
    if artists:
        ax.legend(fontsize="small")
    return artists


def metric_against_setting_figure(
    rows: Sequence[Mapping[str, Any]], setting: str, metric: str
) -> Figure:
    """A figure of :func:`plot_metric_against_setting`."""
    fig = new_figure(figsize=(6.4, 4.2))
    ax = fig.add_subplot()
    plot_metric_against_setting(ax, rows, setting, metric)
    ax.set_title(f"{metric} against {setting}")
    return fig
