"""Plots of a run drawn on the server as SVG: bandwidth (2 s and 10 s averages, cap) and score.

No JavaScript and nothing fetched from elsewhere: the machines that show these pages may
have no internet.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from csrouter.bandwidth_log import DIRECTIONS, Bandwidth
from markupsafe import Markup, escape

AVERAGES = (2, 10)
COLOURS = ("#1f6feb", "#d29922", "#2da44e", "#cf222e")


def moving_average(values: Sequence[float], window: int) -> list[float]:
    """Return the trailing average over `window` samples (fewer at the start)."""
    averages, total = [], 0.0
    for index, value in enumerate(values):
        total += value
        if index >= window:
            total -= values[index - window]
        averages.append(total / min(index + 1, window))
    return averages


def cumulative(values: Sequence[float]) -> list[float]:
    """Return running totals."""
    totals, total = [], 0.0
    for value in values:
        total += value
        totals.append(total)
    return totals


@dataclass(frozen=True)
class Series:
    """A named line of (x, y) points."""

    label: str
    points: list[tuple[float, float]]
    step: bool = False


def line_chart(
    title: str,
    series: Sequence[Series],
    *,
    x_label: str,
    y_label: str,
    limit: tuple[str, float] | None = None,
    limit_scaled: bool = True,
    width: int = 640,
    height: int = 220,
) -> Markup:
    """Return an accessible SVG line chart; `limit` draws a labelled horizontal line (a cap).

    With `limit_scaled` false the scale follows the data alone: a limit above it is marked at
    the top edge with its value, so small use is not flattened against a large cap.
    """
    left, right, top, bottom = 64, 12, 28, 36
    xs = [x for s in series for x, _ in s.points] or [0.0]
    scaled = [limit[1]] if limit and limit_scaled else []
    ys = [y for s in series for _, y in s.points] + scaled + [0.0]
    x_max = max(max(xs), 1.0)
    y_max = max(ys) * 1.05 or 1.0

    def px(x: float) -> float:
        return left + (width - left - right) * x / x_max

    def py(y: float) -> float:
        return height - bottom - (height - top - bottom) * y / y_max

    parts = [
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" '
        f'class="chart" role="img" aria-label="{escape(title)}" '
        # where x = 0 and x = x_max fall, so a page can mark a moment (the 3D replay does)
        f'data-x0="{px(0):.1f}" data-x1="{px(x_max):.1f}" data-x-max="{x_max:g}" '
        f'data-y0="{top}" data-y1="{py(0):.1f}">',
        f"<title>{escape(title)}</title>",
        f'<text x="{left}" y="16" class="chart-title">{escape(title)}</text>',
        f'<line x1="{left}" y1="{py(0):.1f}" x2="{width - right}" y2="{py(0):.1f}" stroke="#888"/>',
        f'<line x1="{left}" y1="{top}" x2="{left}" y2="{py(0):.1f}" stroke="#888"/>',
        f'<text x="{left - 4}" y="{top + 4}" text-anchor="end" font-size="10">'
        f"{escape(short(y_max))}</text>",
        f'<text x="{left - 4}" y="{py(0):.1f}" text-anchor="end" font-size="10">0</text>',
        f'<text x="{width - right}" y="{height - 18}" text-anchor="end" font-size="10">'
        f"{escape(short(x_max))}</text>",
        f'<text x="{(left + width) / 2:.0f}" y="{height - 4}" text-anchor="middle" '
        f'font-size="11">{escape(x_label)}</text>',
        f'<text x="12" y="{(top + height - bottom) / 2:.0f}" font-size="11" '
        f'transform="rotate(-90 12 {(top + height - bottom) / 2:.0f})" text-anchor="middle">'
        f"{escape(y_label)}</text>",
    ]
    if limit is not None and limit[1] > y_max:
        label, value = limit
        parts.append(
            f'<line x1="{left}" y1="{top}" x2="{width - right}" y2="{top}" stroke="#cf222e" '
            'stroke-dasharray="2 6" class="limit" data-off-scale="true"/>'
            f'<text x="{width - right}" y="{top - 2}" text-anchor="end" font-size="10" '
            f'fill="#cf222e">{escape(label)} {escape(short(value))} above the scale '
            f"({escape(f'{100 * max(ys) / value:.1f}' if value else '0')}% used)</text>"
        )
    elif limit is not None:
        label, value = limit
        parts.append(
            f'<line x1="{left}" y1="{py(value):.1f}" x2="{width - right}" y2="{py(value):.1f}" '
            'stroke="#cf222e" stroke-dasharray="6 4" class="limit"/>'
            f'<text x="{width - right}" y="{py(value) - 4:.1f}" text-anchor="end" '
            f'font-size="10" fill="#cf222e">{escape(label)} {escape(short(value))}</text>'
        )
    for index, line in enumerate(series):
        colour = COLOURS[index % len(COLOURS)]
        points = _stepped(line.points) if line.step else line.points
        if points:
            path = " ".join(
                f"{x:.1f},{y:.1f}" for x, y in _per_pixel([(px(x), py(y)) for x, y in points])
            )
            parts.append(
                f'<polyline fill="none" stroke="{colour}" stroke-width="1.5" '
                f'points="{path}" data-series="{escape(line.label)}"/>'
            )
        parts.append(  # the legend, right-aligned on the title's line
            f'<text x="{width - right - 110 * (len(series) - 1 - index)}" y="16" '
            f'text-anchor="end" font-size="11" fill="{colour}">{escape(line.label)}</text>'
        )
    parts.append("</svg>")
    return Markup("".join(parts))  # noqa: S704 - every text in it went through escape()


def _per_pixel(points: list[tuple[float, float]]) -> list[tuple[float, float]]:
    """Keep, of the points falling in one pixel column, the highest and the lowest (in their
    order): the line looks the same, and a 30-minute run's chart stays small."""
    if len(points) <= 2:
        return points
    kept: list[tuple[float, float]] = []
    column: list[tuple[float, float]] = []
    for point in points:
        if column and int(point[0]) != int(column[0][0]):
            kept += _extremes(column)
            column = []
        column.append(point)
    return kept + _extremes(column)


def _extremes(column: list[tuple[float, float]]) -> list[tuple[float, float]]:
    if len(column) <= 2:
        return column
    top, bottom = min(column, key=lambda p: p[1]), max(column, key=lambda p: p[1])
    return sorted({top, bottom}, key=column.index)


def _stepped(points: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    stepped: list[tuple[float, float]] = []
    for x, y in points:
        if stepped:
            stepped.append((x, stepped[-1][1]))
        stepped.append((x, y))
    return stepped


def short(value: float) -> str:
    """Return a number in three significant digits with k, M or G."""
    for size, unit in ((1e9, "G"), (1e6, "M"), (1e3, "k")):
        if abs(value) >= size:
            return f"{value / size:.3g}{unit}"
    return f"{value:.3g}"


def bandwidth_charts(bandwidth: dict[str, Bandwidth]) -> list[Markup]:
    """Return per direction a rate chart (2 s and 10 s averages) and a used-bits chart with
    the cap drawn in."""
    charts = []
    for direction in DIRECTIONS:
        data = bandwidth[direction]
        values = [float(v) for v in data.bits_per_second]
        rates = [
            Series(f"{window} s average", list(enumerate(moving_average(values, window), 1)))
            for window in AVERAGES
        ]
        charts.append(
            line_chart(
                f"{direction.capitalize()} bandwidth",
                rates,
                x_label="seconds since the run started",
                y_label="bits/s",
            )
        )
        used = Series("bits used", list(enumerate(cumulative(values), 1)))
        cap = ("cap", float(data.cap_bits)) if data.cap_bits is not None else None
        charts.append(
            line_chart(
                f"{direction.capitalize()} bits used",
                [used],
                x_label="seconds since the run started",
                y_label="bits",
                limit=cap,
                limit_scaled=False,
            )
        )
    return charts


def score_chart(events: Sequence[tuple[float, str, int]], end: float) -> Markup:
    """Return the score over simulated time from (sim_time, kind, score after) events."""
    score_points = [(0.0, 0.0)]
    falls_points = [(0.0, 0.0)]
    falls = 0
    for sim_time, kind, score in events:
        if kind == "checkpoint":
            score_points.append((sim_time, float(score)))
        elif kind == "fall":
            falls += 1
            falls_points.append((sim_time, float(falls)))
    score_points.append((max(end, score_points[-1][0]), score_points[-1][1]))
    falls_points.append((max(end, falls_points[-1][0]), falls_points[-1][1]))
    return line_chart(
        "Score timeline",
        [Series("checkpoints", score_points, step=True), Series("falls", falls_points, step=True)],
        x_label="simulated seconds",
        y_label="count",
    )
