"""A table of named fields shown two ways from the same rows: a rich table in the terminal
(related fields share a column, e.g. 'median (IQR)') and CSV with one column per field."""

from __future__ import annotations

import csv
from dataclasses import dataclass
from typing import Any, TextIO

from rich.table import Table

from metaopt.reporting.plain import plain, table_title

Row = dict[str, Any]
#: significant digits of numbers in the terminal (the CSV has them all)
TERMINAL_DIGITS = 4


@dataclass(frozen=True)
class Column:
    """A terminal column: its header and the row fields it shows through ``template``."""

    header: str
    fields: tuple[str, ...]
    template: str = "{}"
    #: fractions shown as percentages
    percent: bool = False
    #: False: in the CSV only (detail that would crowd the terminal)
    in_terminal: bool = True

    def render(self, row: Row) -> str:
        """The text of this column for ``row``."""
        return self.template.format(*(self.format(row.get(name)) for name in self.fields))

    def format(self, value: Any) -> str:
        """One field's text: '-' for missing, a percentage, or 4 significant digits."""
        if value is None:
            return "-"
        if isinstance(value, str | int):
            return str(value)
        return f"{value:.0%}" if self.percent else f"{value:.{TERMINAL_DIGITS}g}"


@dataclass
class ResultTable:
    """Rows of named fields with the columns that show them."""

    title: str
    columns: list[Column]
    rows: list[Row]

    @property
    def fields(self) -> list[str]:
        """Every field, in column order (the CSV header)."""
        return [name for column in self.columns for name in column.fields]

    def to_rich(self) -> Table:
        """The terminal table (the columns ``in_terminal``); its text is shown as it is, never
        read as rich markup (a label or setting may hold brackets)."""
        shown = [column for column in self.columns if column.in_terminal]
        table = Table(title=table_title(self.title), title_justify="left")
        for index, column in enumerate(shown):
            justify = "left" if index < 2 else "right"
            table.add_column(plain(column.header), justify=justify, overflow="fold")
        for row in self.rows:
            table.add_row(*(plain(column.render(row)) for column in shown))
        return table

    def to_markdown(self) -> str:
        """The terminal table as GitHub markdown (title in bold above it), to paste into a doc."""
        shown = [column for column in self.columns if column.in_terminal]

        def cells(texts: list[str]) -> str:
            return "| " + " | ".join(t.replace("\n", " ").replace("|", "\\|") for t in texts) + " |"

        lines = [f"**{self.title}**", "", cells([column.header for column in shown])]
        lines.append("|" + "|".join("---" if i < 2 else "--:" for i in range(len(shown))) + "|")
        lines += [cells([column.render(row) for column in shown]) for row in self.rows]
        return "\n".join(lines) + "\n"

    def to_records(self) -> list[Row]:
        """Every field of every row (None where missing), for JSON."""
        return [{name: row.get(name) for name in self.fields} for row in self.rows]

    def write_csv(self, handle: TextIO) -> None:
        """Every field of every row at full precision (empty where missing)."""
        writer = csv.DictWriter(handle, fieldnames=self.fields, lineterminator="\n")
        writer.writeheader()
        writer.writerows(self.to_records())
