"""The sweep's plots: heatmaps over the two ``[report]`` axes (one panel per controller, one
figure per metric and per combination of the other grid axes), or a line plot for one axis.

A ``[[frontier]]`` along a report axis is marked on every heatmap: its critical cells
(benchmarks/sweep/frontier.py) outlined, one colour per frontier; on a line plot, a dashed
vertical line at each controller's critical value on the carried-rate panel."""

from __future__ import annotations

import itertools
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402

from benchmarks.sweep.frontier import cell_key  # noqa: E402
from benchmarks.sweep.spec import SweepSpec  # noqa: E402

PLOT_METRICS = {
    "carried_rate": ("carried rate", (0.0, 1.0), "RdYlGn"),
    "success_rate": ("success rate", (0.0, 1.0), "RdYlGn"),
    "max_cup_friction_use": ("mean peak friction use", (0.0, 1.0), "viridis_r"),
    # the 99th percentile over an episode's steps: a one-step spike does not decide it
    "cup_friction_use_p99": ("mean p99 friction use", (0.0, 1.0), "viridis_r"),
}


FRONTIER_COLOURS = ("black", "magenta", "cyan", "orange")


def _metric(controller: Mapping[str, Any], metric: str) -> float:
    if metric in ("success_rate", "carried_rate"):
        value = controller[metric]
    else:
        stat = controller["stats"][metric]
        value = None if stat is None else stat["mean"]
    return np.nan if value is None else float(value)


def _text_colour(image: Any, value: float) -> str:
    """Black on light cells, white on dark ones."""
    red, green, blue, _ = image.cmap(image.norm(value))
    return "black" if 0.299 * red + 0.587 * green + 0.114 * blue > 0.5 else "white"


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.=-]+", "_", text).strip("_")


def _cell_lookup(summary: Mapping[str, Any]) -> dict[str, Mapping[str, Any]]:
    return {cell_key(c["parameters"]): c for c in summary["cells"]}


def _frontier_label(row: Mapping[str, Any]) -> str:
    return f"critical {row['axis']} (carried >= {row['rate']:g}, harder toward {row['toward']})"


def frontier_marks(
    spec: SweepSpec,
    summary: Mapping[str, Any],
    fixed: Mapping[str, Any],
    controller: str,
) -> list[tuple[int, int, int]]:
    """The heatmap cells ``(row, column, frontier index)`` to outline for ``controller`` on
    the heatmap of the other grid axes at ``fixed``: each frontier along a report axis, at its
    critical value, in each row (or column) of the other report axis. A critical value of None
    marks nothing."""
    x_axis, y_axis = spec.report_axes
    marks = []
    for row in summary["frontier"]:
        if row["controller"] != controller or row["axis"] not in (x_axis, y_axis):
            continue
        if any(row["fixed"][k] != v for k, v in fixed.items()):
            continue  # another figure's
        if row["critical"] is None:
            continue
        index = next(
            i
            for i, f in enumerate(spec.frontiers)
            if (f.axis, f.toward, f.rate) == (row["axis"], row["toward"], row["rate"])
        )
        if row["axis"] == x_axis:
            i = spec.grid[y_axis].index(row["fixed"][y_axis])
            j = spec.grid[x_axis].index(row["critical"])
        else:
            i = spec.grid[y_axis].index(row["critical"])
            j = spec.grid[x_axis].index(row["fixed"][x_axis])
        marks.append((i, j, index))
    return marks


def _heatmaps(spec: SweepSpec, summary: Mapping[str, Any], directory: Path) -> list[str]:
    x_axis, y_axis = spec.report_axes
    others = [k for k in spec.grid if k not in spec.report_axes]
    cells = _cell_lookup(summary)
    names = []
    for fixed in itertools.product(*(spec.grid[k] for k in others)):
        fixed_params = dict(zip(others, fixed, strict=True))
        suffix = "".join(f"_{k.split('.')[-1]}={v}" for k, v in fixed_params.items())
        for metric, (label, limits, cmap) in PLOT_METRICS.items():
            xs, ys = spec.grid[x_axis], spec.grid[y_axis]
            fig, axes = plt.subplots(
                1,
                len(spec.controllers),
                squeeze=False,
                sharey=True,
                figsize=(3.2 * len(spec.controllers) + 1.0, 3.2),
            )
            image = None
            for ax, controller in zip(axes[0], spec.controllers, strict=True):
                grid = np.full((len(ys), len(xs)), np.nan)
                for i, y in enumerate(ys):
                    for j, x in enumerate(xs):
                        key = cell_key({**fixed_params, x_axis: x, y_axis: y})
                        grid[i, j] = _metric(cells[key]["controllers"][controller], metric)
                image = ax.imshow(
                    grid, origin="lower", vmin=limits[0], vmax=limits[1], cmap=cmap, aspect="auto"
                )
                for i, j in itertools.product(range(len(ys)), range(len(xs))):
                    if np.isfinite(grid[i, j]):
                        colour = _text_colour(image, grid[i, j])
                        ax.text(
                            j,
                            i,
                            f"{grid[i, j]:.2f}",
                            ha="center",
                            va="center",
                            fontsize=8,
                            color=colour,
                        )
                for i, j, k in frontier_marks(spec, summary, fixed_params, controller):
                    inset = 0.06 * (k + 1)  # several frontiers on one cell stay apart
                    ax.add_patch(
                        Rectangle(
                            (j - 0.5 + inset, i - 0.5 + inset),
                            1 - 2 * inset,
                            1 - 2 * inset,
                            fill=False,
                            edgecolor=FRONTIER_COLOURS[k % len(FRONTIER_COLOURS)],
                            linewidth=2.0,
                        )
                    )
                ax.set_xticks(range(len(xs)), [str(x) for x in xs])
                ax.set_yticks(range(len(ys)), [str(y) for y in ys])
                ax.set_xlabel(x_axis)
                ax.set_title(controller, fontsize=10)
            axes[0][0].set_ylabel(y_axis)
            fig.colorbar(image, ax=axes[0].tolist(), label=label, shrink=0.9)
            legend = [
                Rectangle(
                    (0, 0),
                    1,
                    1,
                    fill=False,
                    edgecolor=FRONTIER_COLOURS[k % len(FRONTIER_COLOURS)],
                    linewidth=2.0,
                    label=_frontier_label(f.as_json()),
                )
                for k, f in enumerate(spec.frontiers)
                if f.axis in spec.report_axes
            ]
            if legend:
                fig.legend(
                    handles=legend,
                    loc="lower center",
                    bbox_to_anchor=(0.5, -0.1 - 0.06 * len(legend)),
                    fontsize=8,
                    frameon=False,
                )
            title = f"{spec.env}: {label}"
            if fixed_params:
                title += " (" + ", ".join(f"{k}={v}" for k, v in fixed_params.items()) + ")"
            fig.suptitle(title, fontsize=10, y=1.03)
            name = f"heatmap_{metric}" + (f"_{_slug(suffix)}" if suffix else "") + ".png"
            fig.savefig(directory / name, dpi=110, bbox_inches="tight")
            plt.close(fig)
            names.append(name)
    return names


def _rate_bars(ax: Any, xs: Any, chosen: list[Any], metric: str, controller: str) -> Any:
    """A rate with its Wilson interval as error bars; the line drawn."""
    rate = np.array([_metric(c, metric) for c in chosen])
    ci = np.array(
        [c[metric.replace("_rate", "_ci95")] or [np.nan, np.nan] for c in chosen], dtype=float
    )
    return ax.errorbar(
        xs,
        rate,
        yerr=np.clip([rate - ci[:, 0], ci[:, 1] - rate], 0.0, None),  # round-off at 0 and 1
        marker="o",
        capsize=3,
        label=controller,
    )


def _line_plots(spec: SweepSpec, summary: Mapping[str, Any], directory: Path) -> list[str]:
    (axis,) = spec.report_axes
    others = [k for k in spec.grid if k != axis]
    cells = _cell_lookup(summary)
    names = []
    for fixed in itertools.product(*(spec.grid[k] for k in others)):
        fixed_params = dict(zip(others, fixed, strict=True))
        values = spec.grid[axis]
        numeric = all(isinstance(v, int | float) and not isinstance(v, bool) for v in values)
        xs = np.asarray(values, dtype=float) if numeric else np.arange(len(values))
        fig, axes = plt.subplots(1, 3, figsize=(13.0, 3.4))
        for controller in spec.controllers:
            chosen = [
                cells[cell_key({**fixed_params, axis: v})]["controllers"][controller]
                for v in values
            ]
            line = _rate_bars(axes[0], xs, chosen, "carried_rate", controller)
            _rate_bars(axes[1], xs, chosen, "success_rate", controller)
            friction = [_metric(c, "max_cup_friction_use") for c in chosen]
            axes[2].plot(xs, friction, marker="o", label=controller)
            colour = line.lines[0].get_color()
            for row in summary["frontier"]:
                if (
                    row["controller"] == controller
                    and row["axis"] == axis
                    and row["fixed"] == fixed_params
                    and row["critical"] is not None
                ):
                    axes[0].axvline(
                        xs[list(values).index(row["critical"])],
                        color=colour,
                        linestyle="--",
                        linewidth=1.0,
                    )
        axes[0].set_ylabel("carried rate (95 % Wilson)")
        axes[1].set_ylabel("success rate (95 % Wilson)")
        for ax in axes[:2]:
            ax.set_ylim(-0.05, 1.05)
        axes[2].set_ylabel("mean peak friction use")
        for ax in axes:
            ax.set_xlabel(axis)
            if not numeric:
                ax.set_xticks(xs, [str(v) for v in values])
        axes[0].legend(fontsize=8)
        frontiers = [f for f in spec.frontiers if f.axis == axis]
        if frontiers:
            axes[0].set_title(
                "dashed: " + "; ".join(_frontier_label(f.as_json()) for f in frontiers),
                fontsize=7,
            )
        suffix = "".join(f"_{k.split('.')[-1]}={v}" for k, v in fixed_params.items())
        fig.suptitle(f"{spec.env}" + (f" ({suffix.strip('_')})" if suffix else ""), fontsize=10)
        name = f"line_{_slug(axis)}{_slug(suffix)}.png"
        fig.savefig(directory / name, dpi=110, bbox_inches="tight")
        plt.close(fig)
        names.append(name)
    return names


def write_plots(spec: SweepSpec, summary: Mapping[str, Any], directory: str | Path) -> list[str]:
    """The plots' file names (in ``directory``)."""
    directory = Path(directory)
    if len(spec.report_axes) == 2:
        return _heatmaps(spec, summary, directory)
    if len(spec.report_axes) == 1:
        return _line_plots(spec, summary, directory)
    return []
