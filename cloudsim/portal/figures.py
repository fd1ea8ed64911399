"""The VRC's figures as tables: what each chart draws is exactly what its CSV holds.

Fig. 5: uplink bits banked per team over its scoring runs; Fig. 6/7: a run's bandwidth as
2 s and 10 s averages; Fig. 8: uplink bits used per run against its score, with the caps.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

from csrouter.bandwidth_log import DIRECTIONS, Bandwidth

from cloudsim.competition.plots import AVERAGES, cumulative, moving_average
from cloudsim.portal.results import ResultRow

Cell = str | int | float
# A text cell starting so is a formula to a spreadsheet: an end reason a team instance sent
# or a team's name must not run as one on an officer's machine (OWASP "CSV injection").
FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


@dataclass(frozen=True)
class Table:
    """A figure's numbers: a header and rows."""

    header: tuple[str, ...]
    rows: list[tuple[Cell, ...]]

    def csv(self) -> str:
        """Return the table as CSV text."""
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        writer.writerow(self.header)
        writer.writerows(tuple(_inert(cell) for cell in row) for row in self.rows)
        return out.getvalue()


def _inert(cell: Cell) -> Cell:
    """Return a text cell a spreadsheet shows as text (a leading quote), others as they are."""
    return "'" + cell if isinstance(cell, str) and cell.startswith(FORMULA_START) else cell


def bits_banked(rows: Iterable[ResultRow]) -> Table:
    """Return Fig. 5: per team, each scoring run's banked uplink bits and the running total."""
    table: list[tuple[Cell, ...]] = []
    totals: dict[int, int] = {}
    numbers: dict[int, int] = {}
    for row in sorted(rows, key=_run_order):
        if not row.scoring:
            continue
        numbers[row.team_id] = numbers.get(row.team_id, 0) + 1
        totals[row.team_id] = totals.get(row.team_id, 0) + row.uplink_bits_banked
        table.append(
            (
                row.team,
                numbers[row.team_id],
                row.run_id,
                row.uplink_bits_banked,
                totals[row.team_id],
            )
        )
    table.sort(key=lambda r: (str(r[0]).lower(), r[1]))
    return Table(("team", "scoring_run", "run_id", "bits_banked", "cumulative_bits_banked"), table)


def uplink_against_score(rows: Iterable[ResultRow]) -> Table:
    """Return Fig. 8: each scoring run's uplink bits used, its cap and its score."""
    table: list[tuple[Cell, ...]] = [
        (row.team, row.run_id, row.task, row.uplink_bits_used, row.uplink_cap_bits, row.score)
        for row in sorted(rows, key=_run_order)
        if row.scoring
    ]
    return Table(("team", "run_id", "task", "uplink_bits_used", "uplink_cap_bits", "score"), table)


def bandwidth_history(bandwidth: dict[str, Bandwidth]) -> Table:
    """Return Fig. 6/7 of one run: per second and direction the bits, their 2 s and 10 s
    averages (as the run page draws them), the running total and the cap."""
    table: list[tuple[Cell, ...]] = []
    for direction in DIRECTIONS:
        data = bandwidth[direction]
        values = [float(v) for v in data.bits_per_second]
        averages = [moving_average(values, window) for window in AVERAGES]
        totals = cumulative(values)
        cap = data.cap_bits if data.cap_bits is not None else ""
        for index, bits in enumerate(data.bits_per_second):
            table.append(
                (
                    direction,
                    index + 1,
                    bits,
                    *(round(a[index], 3) for a in averages),
                    int(totals[index]),
                    cap,
                )
            )
    header = ("direction", "second", "bits", *(f"average_{w}s" for w in AVERAGES))
    return Table((*header, "cumulative_bits", "cap_bits"), table)


def _run_order(row: ResultRow) -> tuple[object, ...]:
    return (row.team_id, row.finished_at or row.started_at, row.run_id)


def series_of(table: Table, key: int, x: int, y: int) -> dict[str, list[tuple[float, float]]]:
    """Return the table's (x, y) points grouped by the column `key`, in row order."""
    grouped: dict[str, list[tuple[float, float]]] = {}
    for row in table.rows:
        grouped.setdefault(str(row[key]), []).append((float(row[x]), float(row[y])))
    return grouped


def caps_of(table: Sequence[tuple[Cell, ...]], column: int) -> list[float]:
    """Return the distinct caps in a column, smallest first."""
    return sorted({float(row[column]) for row in table})
