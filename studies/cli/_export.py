"""``flexvib export FILE.h5 --csv DIR``: every study of a result file as CSV tables, for users without
Python: ``DIR/<study>.csv`` is ``StudyResult.to_dataframe()`` (one row per grid point or time
sample), ``DIR/<study>_info.csv`` two columns ``key, value``: the study's kind, status, message, run
time and scalar fields, then ``unit:<column>`` for each column."""

from __future__ import annotations

import csv
import json
import logging
from pathlib import Path
from typing import Any, Mapping

from .._errors import StudiesError
from .._identity import plain
from .._tables import require

logger = logging.getLogger("flexvib")


def write_csv(results: Mapping[str, Any], folder: Path) -> list[Path]:
    """Write the two files of each result in ``results`` ({study: result}) into ``folder``; returns
    the paths written. Needs pandas (``flexvib[tables]``)."""
    require("pandas")
    written = []
    for name, result in results.items():
        try:
            frame = result.to_dataframe()
        except StudiesError as error:   # a kind that declares no rows (written outside the package)
            logger.warning("flexvib export: %s not written: %s", name, error)
            continue
        table = folder / f"{_file_name(name)}.csv"
        frame.to_csv(table, index=False)
        info = folder / f"{_file_name(name)}_info.csv"
        with info.open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(["key", "value"])
            for key, value in frame.attrs.items():
                if key == "units":
                    continue
                writer.writerow([key, value if isinstance(value, str) else json.dumps(plain(value))])
            for column, unit in frame.attrs.get("units", {}).items():
                writer.writerow([f"unit:{column}", unit])
        written += [table, info]
    return written


def _file_name(study: str) -> str:
    """A study's group name as a file name ("nonlinear_check@60" stays; a slash would not)."""
    return study.replace("/", "_")
