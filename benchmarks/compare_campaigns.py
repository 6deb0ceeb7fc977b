"""Compare the result tables of two campaign directories column by column.

Used to show that a change left a campaign's numbers unchanged. The comparison itself is
:func:`daa_sil.study.campaign_compare.compare_dirs` (the golden-campaign test uses the same one):
per-encounter and per-decision tables of every group and the shared ``encounters.parquet``,
floats bit for bit, NaN equal to NaN; ``campaign.json`` is metadata and is not compared.

    python benchmarks/compare_campaigns.py /work/ref/base2k-literal /tmp/after-literal

Prints one line per table and a final ``identical: yes|no`` figure line; exit status 0 when every
data column is identical, 1 otherwise, 2 (one line) when a directory or file cannot be read.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from daa_sil.errors import DaaSilError
from daa_sil.study.campaign_compare import compare_dirs


def main(argv: "list[str] | None" = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0],
                                 epilog="example: python benchmarks/compare_campaigns.py /work/ref/base2k-literal "
                                        "/tmp/after-literal", formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir_a", type=Path)
    ap.add_argument("dir_b", type=Path)
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
