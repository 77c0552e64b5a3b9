"""The optional-fields battery at size: every optional field of every version of every event
schema, null and absent, through ``objsearch lake add`` → read back → ``replay`` and ``where``.

    python benchmarks/lake_fields.py

See :mod:`devtools.lake_fields_battery` for the variants and what each verdict means. Prints,
per event type and kind (null / absent) and in total: tried / clear error / unchanged /
traceback / silent change / loss, lists every variant in the last three columns, and exits 1 if
there is any.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import time
from pathlib import Path

# devtools/ (the harnesses, not installed) is a folder of the checkout, beside this one's.
sys.path.insert(1, str(Path(__file__).resolve().parents[1]))

from devtools.lake_fields_battery import COLUMNS, run_battery


def main() -> int:
    work = Path(tempfile.mkdtemp(prefix="objsearch-bench-lake-fields-"))
    started = time.perf_counter()
    try:
        report = run_battery(work)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    seconds = time.perf_counter() - started
    print("optional-fields battery: every optional field of every schema, null and absent")
    print(f"  command: python benchmarks/lake_fields.py {' '.join(sys.argv[1:])}".rstrip())
    print(f"  {'event type (how)':34} {'tried':>6} " + " ".join(f"{c:>13}" for c in COLUMNS))
    total = {c: report.counts[c] for c in COLUMNS}
    for name, row in [*sorted(report.by_type.items()), ("total", {"tried": report.tried, **total})]:
        print(f"  {name:34} {row['tried']:6} " + " ".join(f"{row[c]:13}" for c in COLUMNS))
    print(f"  ({seconds:.0f} s, {1000 * seconds / max(1, report.tried):.0f} ms a variant)")
    for line in report.flagged:
        print(f"  FLAGGED {line}")
    return 0 if report.ok else 1


if __name__ == "__main__":
    sys.exit(main())
