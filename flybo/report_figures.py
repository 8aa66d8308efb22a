"""The figures of `flybo report`: the paper's Figures 4-6, as PNG and SVG (matplotlib, headless).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from flybo.report_data import ReportData
from server.schemas import Band, Interval, Leaderboard, LeaderboardPlanner

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

# Okabe-Ito, as on the website: distinguishable with the common colour-vision deficiencies.
PALETTE = ("#E69F00", "#56B4E9", "#009E73", "#0072B2", "#D55E00", "#CC79A7", "#F0E442",
           "#000000")


def _figure(width: float, height: float) -> Figure:
    import matplotlib

    matplotlib.use("Agg")  # headless: no display is needed, nor wanted
    from matplotlib.figure import Figure

    return Figure(figsize=(width, height), layout="constrained")


def _colours(board: Leaderboard) -> dict[str, str]:
    names = [p.planner for p in board.overall]
    return {n: PALETTE[i % len(PALETTE)] for i, n in enumerate(sorted(names))}


def _nan(values: list[float | None]) -> list[float]:
    return [float("nan") if v is None else v for v in values]


def _band_plot(ax: Axes, t: list[float], band: Band, colour: str, label: str) -> None:
    ax.fill_between(t, _nan(band.min), _nan(band.max), color=colour, alpha=0.2, linewidth=0)
    ax.plot(t, _nan(band.mean), color=colour, label=label, linewidth=1.4)


def curves_figure(data: ReportData, which: str) -> Figure:
    """Figure 4 (`which="volume"`: explored volume) or 5 (`"recall"`: surface recall) over
    time, one panel per area with results, one line (mean) and band (min-max) per planner."""
    areas = list(data.curves)
    cols = max(1, min(4, len(areas)))
    rows = max(1, -(-len(areas) // cols))
    fig = _figure(3.6 * cols, 2.8 * rows + 0.6)
    colours = _colours(data.board)
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.flat[len(areas):]:
        ax.set_visible(False)
    if not areas:
        axes[0, 0].set_visible(True)
        axes[0, 0].text(0.5, 0.5, "no results yet", ha="center", va="center")
        axes[0, 0].set_axis_off()
    for ax, area in zip(axes.flat, areas, strict=False):
        c = data.curves[area]
        for p in c.planners:
            if which == "volume":
                _band_plot(ax, p.time_s, p.explored_volume_m3, colours[p.planner], p.planner)
            else:
                _band_plot(ax, p.recall_time_s, p.surface_recall, colours[p.planner], p.planner)
        if c.plateau_s:
            ax.axvline(c.plateau_s, color="0.6", linestyle=":", linewidth=1)
        ax.set_title(area)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("explored volume (m³)" if which == "volume" else "surface recall")
        if which == "recall":
            ax.set_ylim(0.0, 1.0)
        ax.grid(alpha=0.3)
    handles, labels = [], []
    for ax in axes.flat:
        for h, lab in zip(*ax.get_legend_handles_labels(), strict=True):
            if lab not in labels:
                handles.append(h)
                labels.append(lab)
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncols=min(len(labels), 4))
    title = ("Figure 4: explored volume over time" if which == "volume" else
             "Figure 5: surface recall over time")
    fig.suptitle(f"{title} (mean, min–max band over runs; preset {data.preset})")
    return fig


def _error(value: float, interval: Interval | None) -> list[list[float]] | None:
    """Matplotlib's error bar lengths below and above `value` for its interval."""
    if interval is None:
        return None
    return [[max(0.0, value - interval.low)], [max(0.0, interval.high - value)]]


def pareto_figure(data: ReportData) -> Figure:
    """Figure 6: mean coverage rank against mean F-score rank (1 is best), each with its 95 %
    interval as error bars, the Pareto set circled and joined."""
    fig = _figure(5.5, 4.6)
    ax = fig.subplots()
    colours = _colours(data.board)
    ranked: list[LeaderboardPlanner] = [p for p in data.board.overall
                                        if p.mean_fscore_rank is not None]
    for p in ranked:
        assert p.mean_fscore_rank is not None
        ax.errorbar([p.mean_coverage_rank], [p.mean_fscore_rank],
                    xerr=_error(p.mean_coverage_rank, p.mean_coverage_rank_ci),
                    yerr=_error(p.mean_fscore_rank, p.mean_fscore_rank_ci),
                    color=colours[p.planner], linewidth=1, capsize=3, zorder=2.5)
        ax.scatter([p.mean_coverage_rank], [p.mean_fscore_rank], color=colours[p.planner],
                   s=50, zorder=3, label=p.planner)
        ax.annotate(p.planner, (p.mean_coverage_rank, p.mean_fscore_rank),
                    textcoords="offset points", xytext=(6, 4), fontsize=8)
    front = sorted((p for p in ranked if p.pareto), key=lambda p: p.mean_coverage_rank)
    if front:
        xs = [p.mean_coverage_rank for p in front]
        ys = [float(p.mean_fscore_rank or 0.0) for p in front]
        ax.plot(xs, ys, color="black", linewidth=1, zorder=2)
        ax.scatter(xs, ys, s=160, facecolors="none", edgecolors="black", zorder=4,
                   label="Pareto set")
    if not ranked:
        ax.text(0.5, 0.5, "no results yet", ha="center", va="center", transform=ax.transAxes)
    ax.set_xlabel("mean coverage rank (1 is best)")
    ax.set_ylabel("mean F-score rank (1 is best)")
    ax.invert_xaxis()
    ax.invert_yaxis()
    ax.grid(alpha=0.3)
    ax.set_title(f"Figure 6: coverage rank vs F-score rank (preset {data.preset})\n"
                 "bars: 95 % intervals of the mean ranks", fontsize=10)
    return fig


def save_figure(fig: Figure, out: Path, stem: str) -> list[Path]:
    paths = []
    for suffix in ("png", "svg"):
        path = out / f"{stem}.{suffix}"
        # No date in the SVG: the same data gives the same file.
        fig.savefig(path, format=suffix, dpi=150,
                    metadata={"Date": None} if suffix == "svg" else None)
        paths.append(path)
    return paths


FIGURES: dict[str, tuple[str, Callable[[ReportData], Figure]]] = {
    "figure4": ("Figure 4: explored volume over time",
                lambda d: curves_figure(d, "volume")),
    "figure5": ("Figure 5: surface recall over time", lambda d: curves_figure(d, "recall")),
    "figure6": ("Figure 6: coverage rank vs F-score rank", pareto_figure),
}
