"""Screenshots of the console's pages at 1280x800, taken by the done-when browser test.

Runs ``tests/e2e/test_console_operation.py`` (the simulated cell: teach one model from the
Models page, two inspections from the Inspection page, the Reports page with one opened)
with ``VISIONCELL_SCREENSHOTS`` set, then prints the files written.  ``--docs`` writes them
to ``docs/screenshots/`` (the README shows them), else to ``benchmarks/out/screenshots/``.

    .venv/bin/python -m benchmarks.console_screenshots --docs
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

ROOT = Path(__file__).resolve().parent.parent
TEST = "tests/e2e/test_console_operation.py"
PAGES = ("models", "inspection", "reports", "reports-detail")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--docs", action="store_true", help="write to docs/screenshots/")
    ap.add_argument("--json", action="store_true", help="print one JSON line at the end")
    args = ap.parse_args(argv)
    out = ROOT / ("docs/screenshots" if args.docs else "benchmarks/out/screenshots")
    out.mkdir(parents=True, exist_ok=True)
    err = Console(stderr=True)
    err.print(f"running {TEST} (about a minute or two) ...")
    t0 = time.monotonic()
    env = {**os.environ, "VISIONCELL_SCREENSHOTS": str(out)}
    r = subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", TEST],
        cwd=ROOT, env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    took = time.monotonic() - t0
    if r.returncode != 0:
        err.print(r.stdout[-4000:], r.stderr[-2000:])
        err.print(f"[red]the test failed (exit {r.returncode}); no screenshots trusted[/red]")
        return r.returncode
    rows = []
    for name in PAGES:
        path = out / f"{name}.png"
        if not path.is_file():
            err.print(f"[red]missing {path}[/red]")
            return 1
        rows.append(
            {
                "page": name,
                "file": str(path.relative_to(ROOT)),
                "kB": round(path.stat().st_size / 1024, 1),
            }
        )
    table = Table(title=f"Console screenshots (1280x800), test run {took:.0f} s")
    for col in ("page", "file", "kB"):
        table.add_column(col)
    for row in rows:
        table.add_row(row["page"], row["file"], f"{row['kB']:.1f}")
    Console().print(table)
    if args.json:
        print(json.dumps({"screenshots": rows, "test_s": round(took, 1)}))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
