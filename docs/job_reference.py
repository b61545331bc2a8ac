"""Write docs/job-reference.md and docs/job.schema.json from the job schema.

    .venv/bin/python docs/job_reference.py [--check]

Both come from the one declaration of the job file's keys, :mod:`relray.core.scene.schema`
(``python -m relray.core.scene.schema --markdown | --json`` prints them).
``tests/test_schema.py`` fails when a committed file differs from what would be written;
``--check`` exits 1 then.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from relray.core.scene import schema

ROOT = Path(__file__).resolve().parents[1]
OUTPUTS = {ROOT / "docs" / "job-reference.md": schema.markdown,
           ROOT / "docs" / "job.schema.json": schema.json_text}


def stale() -> list[Path]:
    """The generated files that differ from what the schema gives now."""
    return [p for p, make in OUTPUTS.items()
            if not p.is_file() or p.read_text(encoding="utf-8") != make()]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if out of date")
    args = parser.parse_args()
    if args.check:
        for p in stale():
            print(f"{p} is out of date", file=sys.stderr)
        return 1 if stale() else 0
    for p, make in OUTPUTS.items():
        p.write_text(make(), encoding="utf-8")
        print(p)
    return 0


if __name__ == "__main__":
    sys.exit(main())
