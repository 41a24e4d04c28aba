"""Read a campaign report's CSV back into the rows ``analysis.analyse`` takes, whichever
version wrote it.

Reports written before "truth" came to mean only the pose a simulator rendered named the
lab's reference ``lab_truth_*`` and the calibrated one ``calibrated_truth_*``; this reader
gives their rows the current names (``LEGACY_COLUMNS``), so an old CSV analyses as a new
one does. Empty cells read as None, every other cell as the text the CSV holds (the
statistics convert what they use).
"""

from __future__ import annotations

import csv
import io

from backend.services.reports.analysis import AXES

LEGACY_COLUMNS = {
    **{f"lab_truth_{a}": f"reference_{a}" for a in AXES},
    **{f"calibrated_truth_{a}": f"calibrated_reference_{a}" for a in AXES},
}
"""Older column name -> current name."""


class ReportCsvError(ValueError):
    """A CSV that is not a campaign report: names what is missing."""


def read_csv(text: str) -> list[dict[str, str | None]]:
    """The rows of a report CSV (``reports.CSV_COLUMNS``, or the older names of
    ``LEGACY_COLUMNS``) as dicts under the current column names.

    A file holding a column under both names keeps the current one. ``ReportCsvError``
    when the header lacks ``setpoint_index`` or ``ok``.
    """
    reader = csv.DictReader(io.StringIO(text))
    header = reader.fieldnames or []
    missing = [c for c in ("setpoint_index", "ok") if c not in header]
    if missing:
        raise ReportCsvError(
            f"not a campaign report CSV: no {', '.join(missing)} column (header: {header[:8]})"
        )
    rename = {old: new for old, new in LEGACY_COLUMNS.items() if old in header}
    rename = {old: new for old, new in rename.items() if new not in header}
    rows = []
    for raw in reader:
        row = {rename.get(k, k): (None if v == "" else v) for k, v in raw.items()}
        rows.append(row)
    return rows
