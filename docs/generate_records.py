"""The docs' measured figures and tables, from the benchmarks' records (``<!-- figure:RECORD MEASURE -->``,
``<!-- table:RECORD KEY -->``, docs/generate.py).

A figure is the median of a measure in the newest record of a benchmark's command taken on a quiet machine
(``record.newest``), its range over the rounds and the machine, linked to the record ("9.31× (8.92–9.60), AMD
EPYC, 2 cores"); a measure of fewer than 5 rounds is refused (docs/development.md, "Benchmark discipline"). A
table is one a benchmark wrote into its record (``Record.table``), each estimate with its interval, then the
machine and the link to the record.
"""

from __future__ import annotations

import os
from pathlib import Path

import record as records  # benchmarks/record.py, on the path docs/generate.py sets
from generate_flags import cell

UNITS = {"x": "×", "": "", "us": " µs"}  # any other unit is written after a space as it is ("ms", "h", "steps/s")


class FigureError(ValueError):
    """A figure that cannot be published: no such record or measure, a loaded record, too few rounds."""


def number(value: float) -> str:
    """Three significant digits or so: 1,005 / 17.6 / 9.31 / 0.862."""
    size = abs(value)
    return f"{value:,.0f}" if size >= 100 else f"{value:.1f}" if size >= 10 else f"{value:.2f}" if size >= 1 \
        else f"{value:.3f}"


def published(name: str, results: Path, holds=lambda record: True) -> tuple[Path, dict] | None:
    """The newest record of the command ``name`` not taken on a loaded machine that ``holds`` what is asked, and its
    path (``record.newest``); None where quiet records exist but none holds it; FigureError where there is none."""
    try:
        return records.newest(name, results, holds)
    except LookupError:
        return None
    except ValueError as error:  # none, every one loaded, a file that is not a record
        raise FigureError(str(error)) from None


def figure(name: str, measure: str, page: Path, results: Path = records.RESULTS) -> str:
    """The text of one figure: median, range and machine, linked (from ``page``) to its record (the newest that
    has the measure)."""
    found = published(name, results, lambda record: measure in record["measures"])
    if found is None:
        measures = records.newest(name, results)[1]["measures"]
        raise FigureError(f"{name}: no measure {measure!r} (it has {', '.join(measures)})")
    path, record = found
    values = record["measures"][measure]
    if values["rounds"] < records.MIN_ROUNDS:
        raise FigureError(f"{name} {measure}: {values['rounds']} rounds; a figure is the median of at least "
                          f"{records.MIN_ROUNDS}")
    unit = UNITS.get(values["unit"], " " + values["unit"])
    text = (f"{number(values['median'])}{unit} ({number(values['min'])}–{number(values['max'])}), {record['cpu']}, "
            f"{record['cores']} cores")
    return f"[{text}]({Path(os.path.relpath(path, page.parent)).as_posix()})"


def table_cell(value) -> str:
    """Text as it is; a count (an int) as it is, with thousands separators; any other number as ``number``
    writes it; an estimate as "value [low, high]" (with ``digits`` decimals where it gives them: a
    probability)."""
    if isinstance(value, dict):
        digits = value.get("digits")
        shown = number if digits is None else (lambda x: f"{x:.{digits}f}")
        return f"{shown(value['value'])} [{shown(value['low'])}, {shown(value['high'])}]"
    if isinstance(value, int) and not isinstance(value, bool):
        return f"{value:,}"
    if isinstance(value, float):
        return number(value)
    return cell(value)


def recorded_table(name: str, key: str, results: Path) -> tuple[Path, dict]:
    """The newest quiet record of the command ``name`` whose notes hold the table ``key``, and its path."""
    def holds(record: dict) -> bool:
        table = record.get("notes", {}).get(key)
        return isinstance(table, dict) and {"columns", "rows"} <= set(table)

    found = published(name, results, holds)
    if found is None:
        raise FigureError(f"{name}: no table {key!r} in its notes")
    return found


def record_table(name: str, key: str, page: Path, results: Path = records.RESULTS) -> str:
    """A record's table (``Record.table``) in markdown, then its machine and date, linked to the record."""
    path, record = recorded_table(name, key, results)
    table = record["notes"][key]
    lines = ["| " + " | ".join(map(cell, table["columns"])) + " |", "|" + "---|" * len(table["columns"])]
    lines += ["| " + " | ".join(table_cell(value) for value in row) + " |" for row in table["rows"]]
    link = Path(os.path.relpath(path, page.parent)).as_posix()
    return "\n".join(lines) + f"\n\n[{record['cpu']}, {record['cores']} cores, {record['date'][:10]}]({link})\n"


def listed(names: list[str]) -> str:
    """"a", "a and b", "a, b and c"."""
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def half_intervals(name: str, key: str, page: Path, results: Path = records.RESULTS) -> str:
    """What the table KEY of the command's newest record says of each of its probabilities, the columns headed
    "P(X > Y)": the rows whose 95 % interval lies above a half, holds a half, lies below it. An interval that holds
    a half ranks nothing; one wholly above (below) a half says X is likelier to score higher (lower) than Y."""
    table = recorded_table(name, key, results)[1]["notes"][key]
    sentences = []
    for index, column in enumerate(table["columns"]):
        if not column.startswith("P("):
            continue
        estimates = [(row[0], row[index]) for row in table["rows"] if isinstance(row[index], dict)]
        groups: dict[str, list[str]] = {"lies above a half": [], "holds a half": [], "lies below a half": []}
        for row, value in estimates:
            try:
                where = ("lies above a half" if value["low"] > 0.5 else "lies below a half" if value["high"] < 0.5
                         else "holds a half")
            except (KeyError, TypeError) as error:
                raise FigureError(f"{name}: the table {key!r} has an estimate of {column} without its interval "
                                  f"({type(error).__name__}: {error})") from None
            groups[where].append(str(row))
        whole = len(estimates) == len(table["rows"]) > 1  # every row has an estimate: "every strategy"
        parts = [f"{where} for " + (f"every {table['columns'][0]}" if whole and len(rows) == len(estimates)
                                    else listed(rows)) for where, rows in groups.items() if rows]
        sentences.append(f"The interval of {column.split(' [')[0]} " + "; ".join(parts) + ".")
    if not sentences:
        raise FigureError(f"{name}: the table {key!r} has no column P(X > Y)")
    return " ".join(sentences)
