#!/usr/bin/env python3
"""Compare two sweep results.csv files in every deterministic column.

The wall-clock `seconds`, the `backend` label and the `data_path` are left out: they
depend on the machine and the run, not on the fit. Exit status 1 on any difference.
Usage: scripts/compare-results.py A/results.csv B/results.csv
"""
import csv
import sys

SKIP = {"seconds", "backend", "data_path"}


def load(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    key = lambda r: (r["data"], r["model"], r["loss"], r["weights"], r["optimizer"])
    return {key(r): {k: v for k, v in r.items() if k not in SKIP} for r in rows}


a, b = load(sys.argv[1]), load(sys.argv[2])
only_a, only_b = sorted(set(a) - set(b)), sorted(set(b) - set(a))
diff = [(k, c, a[k][c], b[k].get(c)) for k in sorted(set(a) & set(b)) for c in a[k] if a[k][c] != b[k].get(c)]
print(f"{len(a)} vs {len(b)} rows; {len(only_a)} only in A, {len(only_b)} only in B; "
      f"{len(diff)} differing cells")
for k in only_a[:5]:
    print("only in A:", k)
for k in only_b[:5]:
    print("only in B:", k)
for k, c, x, y in diff[:10]:
    print(f"{k} {c}: {x!r} vs {y!r}")
sys.exit(1 if only_a or only_b or diff else 0)
