"""The report: datasets (a model, a motion, its loads) × the registered methods, as Markdown, CSV
or JSON. ``paper``: the paper's comparison on one model (PD control, its Tables 2 and 3, "Beyond the
paper", the paper's figures beside ours on the forearm); ``paper_methods``: the paper's table of
methods (its cells and published figures), their execution and statistics; ``methods``: the
registered one-run methods and the datasets they apply to; ``comparison``: a model compared with
the forearm (indicators per kind of coordinate and per coordinate, a floating base's residuals, the
paper's claim tested). ``fdbench.report.X`` is ``fdbench.report.paper.X`` for the paper report's
names."""

from __future__ import annotations

from . import paper
from .paper import CSV_COLUMNS, Row, build_rows, csv_rows, json_report, markdown, settings_table

__all__ = ["CSV_COLUMNS", "Row", "build_rows", "csv_rows", "json_report", "markdown", "settings_table"]


def __getattr__(name: str):
    return getattr(paper, name)
