"""Compare the result tables of two campaign directories (or two SIL step logs) column by column.

Used to show that a change left a campaign's numbers unchanged. The comparison itself is
:func:`daa_sil.study.campaign.compare.compare_dirs` (the golden-campaign test uses the same one):
per-encounter and per-decision tables of every group and the shared ``encounters.parquet``,
floats bit for bit, NaN equal to NaN; ``campaign.json`` is metadata and is not compared.

The same for SIL step logs: A and B may be two ``steplog.parquet`` files, two ``daa-sil run``
output directories (each holding ``steplog.parquet``), or two directories of such run directories
(e.g. one run per scenario: every name present in either is compared). Step-log metadata is not
compared.

    python benchmarks/compare_campaigns.py /work/ref/base2k-literal /tmp/after-literal
    python benchmarks/compare_campaigns.py /work/ref/sil runs/sil-after

Prints one line per table and a final ``identical: yes|no`` figure line; exit status 0 when every
data column is identical, 1 otherwise, 2 (one line) when a directory or file cannot be read.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from daa_sil.errors import DaaSilError
from daa_sil.steplog import RENAMED
from daa_sil.study.campaign.compare import compare_dirs

RENAMED_HELP = "; ".join(f"column {col!r}: " + ", ".join(f"{old!r} -> {new!r}" for old, new in m.items())
                         for col, m in RENAMED.items())
EPILOG = f"""values renamed since older runs (applied to both sides when reading, so runs written by
bba2fd8 compare with newer ones): {RENAMED_HELP} (daa_sil.steplog.RENAMED).

examples:
  python benchmarks/compare_campaigns.py /work/ref/base2k-literal /tmp/after-literal
  python benchmarks/compare_campaigns.py /work/ref/sil/head_on/steplog.parquet runs/head_on/steplog.parquet
  python benchmarks/compare_campaigns.py /work/ref/sil runs/sil-after
"""


def main(argv: "list[str] | None" = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], epilog=EPILOG,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir_a", type=Path, metavar="A", help="campaign directory, step log, run directory or directory of runs")
    ap.add_argument("dir_b", type=Path, metavar="B", help="the same kind as A")
    args = ap.parse_args(argv)
    try:
        res = compare_dirs(args.dir_a, args.dir_b, on_table=print)
    except DaaSilError as exc:
        print(f"compare_campaigns: {exc}", file=sys.stderr)
        return 2
    for d in res.differences:
        print("  " + d)
    print(f"identical: {'yes' if res.identical else 'no'} ({res.columns} columns compared, "
          f"{len(res.differences)} differences)")
    return 0 if res.identical else 1


if __name__ == "__main__":
    sys.exit(main())
