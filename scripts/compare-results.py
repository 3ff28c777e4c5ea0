#!/usr/bin/env python3
"""Compare two sweep results.csv files in every deterministic column.

The wall-clock `seconds`, the `backend` label and the `data_path` are left out: they
depend on the machine and the run, not on the fit. With `--rel TOL`, numbers (also inside
the JSON `params`/`param_std` cells) may differ by TOL relative (or TOL absolute near
zero); every other cell must match exactly. The per-data-set rankings (models sorted by
best χ²_red) are compared too. Exit status 1 on any difference.
Usage: scripts/compare-results.py A/results.csv B/results.csv [--rel TOL]
"""
import csv
import json
import sys

SKIP = {"seconds", "backend", "data_path"}


def load(path):
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    key = lambda r: (r["data"], r["model"], r["loss"], r["weights"], r["optimizer"])
    return {key(r): {k: v for k, v in r.items() if k not in SKIP} for r in rows}


def close(x, y, tol):
    """Whether cells x and y agree: numbers within tol, JSON structures element-wise."""
    if x == y:
        return True, 0.0
    if tol is None:
        return False, float("inf")
    try:
        a, b = json.loads(x), json.loads(y)
    except ValueError:
        return False, float("inf")
    worst = 0.0

    def walk(a, b):
        nonlocal worst
        if isinstance(a, dict) and isinstance(b, dict) and a.keys() == b.keys():
            return all(walk(a[k], b[k]) for k in a)
        if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
            return all(walk(p, q) for p, q in zip(a, b))
        if isinstance(a, (int, float)) and isinstance(b, (int, float)):
            d = abs(a - b) / max(abs(a), abs(b), 1.0)
            worst = max(worst, d)
            return d <= tol
        return a == b

    return walk(a, b), worst


def rankings(rows):
    by = {}
    for (data, model, loss, w, opt), r in rows.items():
        by.setdefault((data, loss, w, opt), []).append((float(r["chi2_red"] or "inf"), model))
    return {k: [m for _, m in sorted(v)] for k, v in by.items()}


args = sys.argv[1:]
tol = None
if "--rel" in args:
    i = args.index("--rel")
    tol = float(args[i + 1])
    del args[i : i + 2]
a, b = load(args[0]), load(args[1])
only_a, only_b = sorted(set(a) - set(b)), sorted(set(b) - set(a))
diff, worst = [], 0.0
for k in sorted(set(a) & set(b)):
    for c in a[k]:
        ok, d = close(a[k][c], b[k].get(c), tol)
        worst = max(worst, d if ok else worst)
        if not ok:
            diff.append((k, c, a[k][c], b[k].get(c)))
ra, rb = rankings(a), rankings(b)
rank_diff = [k for k in ra if ra[k] != rb.get(k)]
print(f"{len(a)} vs {len(b)} rows; {len(only_a)} only in A, {len(only_b)} only in B; "
      f"{len(diff)} differing cells" + (f" beyond {tol:g} relative" if tol else "")
      + (f" (largest accepted difference {worst:.2e})" if tol else "")
      + f"; {len(rank_diff)} of {len(ra)} rankings differ")
for k in only_a[:5]:
    print("only in A:", k)
for k in only_b[:5]:
    print("only in B:", k)
for k, c, x, y in diff[:10]:
    print(f"{k} {c}: {x!r} vs {y!r}")
for k in rank_diff[:5]:
    print("ranking", k, ra[k], "vs", rb.get(k))
sys.exit(1 if only_a or only_b or diff or rank_diff else 0)
