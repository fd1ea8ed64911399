"""Season charts drawn on the server as SVG (many teams; a log axis for caps 250x apart).

Every mark carries its numbers as data attributes, the same the figure's CSV holds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from markupsafe import Markup, escape

from cloudsim.competition.plots import COLOURS, short

WIDTH, HEIGHT = 720, 300
LEFT, RIGHT, TOP, BOTTOM = 70, 16, 30, 40


def _colour(index: int, count: int) -> str:
    if count <= len(COLOURS):
        return COLOURS[index]
    return f"hsl({round(index * 360 / count)}, 65%, 42%)"  # 30 teams: 30 distinct hues


def _frame(title: str, x_label: str, y_label: str, height: int) -> list[str]:
    middle = (TOP + HEIGHT - BOTTOM) / 2
    return [
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {WIDTH} {height}" class="chart" '
        f'role="img" aria-label="{escape(title)}">',
        f"<title>{escape(title)}</title>",
        f'<text x="{LEFT}" y="18" class="chart-title">{escape(title)}</text>',
        f'<line x1="{LEFT}" y1="{HEIGHT - BOTTOM}" x2="{WIDTH - RIGHT}" y2="{HEIGHT - BOTTOM}" '
        'stroke="#888"/>',
        f'<line x1="{LEFT}" y1="{TOP}" x2="{LEFT}" y2="{HEIGHT - BOTTOM}" stroke="#888"/>',
        f'<text x="{(LEFT + WIDTH) / 2:.0f}" y="{HEIGHT - 6}" text-anchor="middle" '
        f'font-size="11">{escape(x_label)}</text>',
        f'<text x="14" y="{middle:.0f}" font-size="11" text-anchor="middle" '
        f'transform="rotate(-90 14 {middle:.0f})">{escape(y_label)}</text>',
    ]


def _tick(x: float, y: float, text: str, anchor: str) -> str:
    return (
        f'<text x="{x:.1f}" y="{y:.1f}" text-anchor="{anchor}" font-size="10">{escape(text)}</text>'
    )


def team_lines(
    title: str, series: dict[str, list[tuple[float, float]]], x_label: str, y_label: str
) -> Markup:
    """Return a line per team (x from 1), the legend listed under the plot."""
    xs = [x for points in series.values() for x, _ in points] or [1.0]
    ys = [y for points in series.values() for _, y in points] or [0.0]
    x_max, y_max = max(max(xs), 2.0), (max(ys) * 1.05) or 1.0
    per_row = 4
    height = HEIGHT + 16 * math.ceil(len(series) / per_row)

    def px(x: float) -> float:
        return LEFT + (WIDTH - LEFT - RIGHT) * (x - 1) / (x_max - 1)

    def py(y: float) -> float:
        return HEIGHT - BOTTOM - (HEIGHT - TOP - BOTTOM) * y / y_max

    parts = _frame(title, x_label, y_label, height)
    parts += [
        _tick(LEFT - 4, TOP + 4, short(y_max), "end"),
        _tick(LEFT - 4, HEIGHT - BOTTOM, "0", "end"),
        _tick(LEFT, HEIGHT - BOTTOM + 14, "1", "middle"),
        _tick(WIDTH - RIGHT, HEIGHT - BOTTOM + 14, f"{x_max:g}", "middle"),
    ]
    for index, (name, points) in enumerate(series.items()):
        colour = _colour(index, len(series))
        path = " ".join(f"{px(x):.1f},{py(y):.1f}" for x, y in points)
        values = " ".join(f"{y:.15g}" for _, y in points)
        parts.append(
            f'<polyline fill="none" stroke="{colour}" stroke-width="1.5" points="{path}" '
            f'data-series="{escape(name)}" data-values="{values}"><title>{escape(name)}: '
            f"{escape(short(points[-1][1]) if points else '0')}</title></polyline>"
        )
        parts += [  # a mark per run: a team's first run alone is no line yet
            f'<circle cx="{px(x):.1f}" cy="{py(y):.1f}" r="2.5" fill="{colour}" '
            f'data-series="{escape(name)}"/>'
            for x, y in points
        ]
        column, row = index % per_row, index // per_row
        x = LEFT + column * (WIDTH - LEFT) / per_row
        parts.append(
            f'<text x="{x:.0f}" y="{HEIGHT + 12 + 16 * row}" '
            f'font-size="11" fill="{colour}">■ {escape(name)}</text>'
        )
    parts.append("</svg>")
    return Markup("".join(parts))  # noqa: S704 - every text in it went through escape()


def scatter_with_caps(
    title: str,
    points: Sequence[tuple[str, int, float, float]],
    caps: Sequence[float],
    x_label: str,
    y_label: str,
) -> Markup:
    """Return (label, run id, x, y) points on a log-10 x axis, each cap a dotted vertical line."""
    positive = [x for _, _, x, _ in points if x > 0] + [c for c in caps if c > 0]
    low = 10 ** math.floor(math.log10(min(positive))) if positive else 1.0
    high = 10 ** math.ceil(math.log10(max(positive))) if positive else 10.0
    high = max(high, low * 10)
    y_max = math.floor(max([y for *_, y in points] + [0.0])) + 1.0  # scores are whole

    def px(x: float) -> float:
        share = (math.log10(max(x, low)) - math.log10(low)) / (math.log10(high) - math.log10(low))
        return LEFT + (WIDTH - LEFT - RIGHT) * share

    def py(y: float) -> float:
        return HEIGHT - BOTTOM - (HEIGHT - TOP - BOTTOM) * y / y_max

    parts = _frame(title, x_label, y_label, HEIGHT)
    step = max(1, math.ceil(y_max / 10))
    parts += [_tick(LEFT - 4, py(y) + 4, f"{y}", "end") for y in range(0, int(y_max) + 1, step)]
    decade = low
    while decade <= high:  # the log axis's decades
        parts.append(_tick(px(decade), HEIGHT - BOTTOM + 14, short(decade), "middle"))
        decade *= 10
    for cap in caps:
        parts.append(
            f'<line x1="{px(cap):.1f}" y1="{TOP}" x2="{px(cap):.1f}" y2="{HEIGHT - BOTTOM}" '
            f'stroke="#cf222e" stroke-dasharray="2 3" class="cap" data-cap="{cap:.15g}">'
            f"<title>cap {escape(short(cap))} bits</title></line>"
        )
    teams = sorted({label for label, *_ in points}, key=str.lower)
    for label, run_id, x, y in points:
        colour = _colour(teams.index(label), len(teams))
        parts.append(
            f'<circle cx="{px(x):.1f}" cy="{py(y):.1f}" r="3.5" fill="{colour}" '
            f'data-team="{escape(label)}" data-run="{run_id}" data-x="{x:.15g}" data-y="{y:.15g}">'
            f"<title>{escape(label)}, run {run_id}: {x:,.0f} bits, score {y:g}</title></circle>"
        )
    parts.append("</svg>")
    return Markup("".join(parts))  # noqa: S704 - every text in it went through escape()
