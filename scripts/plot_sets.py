#!/usr/bin/env python3
"""Plot the optimiser benchmark's per-problem rows: solve time against rank.

    DPMP_BENCH_PER_PROBLEM=/tmp/sets.csv cargo bench --bench optim_sets
    scripts/plot_sets.py /tmp/sets.csv docs/img/optim_sets.svg

One panel per set (typical, hard): every problem's `Problem::solve` time
(log scale) in increasing order, a dot per problem, filled when the problem
was solved (`optimal`, verified, labelled feasible) and a red cross when
not, with the issue's median and p99 targets as dashed lines. Plain SVG,
no plotting library needed. Exit code 2 on a missing or malformed CSV.
"""
import csv
import math
import os
import sys

TARGETS = {"typical": (5.0, 25.0), "hard": (10.0, 50.0)}
W, H = 420, 300
LEFT, RIGHT, TOP, BOTTOM = 56, 12, 28, 40


def load(path):
    sets = {}
    try:
        with open(path, newline="") as f:
            for row in csv.DictReader(f):
                ms = float(row["ms"])
                if not math.isfinite(ms) or ms <= 0:
                    raise ValueError(f"ms must be a positive number, got {row['ms']}")
                solved = row["solved"] == "true"
                sets.setdefault(row["set"], []).append((ms, solved))
    except (OSError, KeyError, ValueError) as e:
        print(f"error: {path}: {e}", file=sys.stderr)
        sys.exit(2)
    if not sets:
        print(f"error: {path}: no rows", file=sys.stderr)
        sys.exit(2)
    return sets


def panel(name, rows, x0, lo, hi):
    rows = sorted(rows)
    n = len(rows)
    pw, ph = W - LEFT - RIGHT, H - TOP - BOTTOM

    def px(i):
        return x0 + LEFT + pw * (i + 0.5) / n

    def py(ms):
        return TOP + ph * (1 - (math.log10(ms) - lo) / (hi - lo))

    out = [f'<rect x="{x0 + LEFT}" y="{TOP}" width="{pw}" height="{ph}" fill="none" stroke="#888"/>']
    for e in range(int(math.floor(lo)), int(math.ceil(hi)) + 1):
        for m in (1, 2, 5):
            v = m * 10**e
            if lo <= math.log10(v) <= hi:
                y = py(v)
                out.append(f'<line x1="{x0 + LEFT}" x2="{x0 + W - RIGHT}" y1="{y:.1f}" y2="{y:.1f}" stroke="#eee"/>')
                out.append(f'<text x="{x0 + LEFT - 4}" y="{y + 4:.1f}" font-size="10" text-anchor="end">{v:g}</text>')
    for t, label in zip(TARGETS.get(name, ()), ("median target", "p99 target")):
        y = py(t)
        out.append(f'<line x1="{x0 + LEFT}" x2="{x0 + W - RIGHT}" y1="{y:.1f}" y2="{y:.1f}" stroke="#36c" stroke-dasharray="4 3"/>')
        out.append(f'<text x="{x0 + W - RIGHT - 2}" y="{y - 3:.1f}" font-size="9" fill="#36c" text-anchor="end">{label} {t:g} ms</text>')
    for i, (ms, solved) in enumerate(rows):
        x, y = px(i), py(ms)
        if solved:
            out.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="2" fill="#2a2"/>')
        else:
            out.append(f'<path d="M{x - 3:.1f} {y - 3:.1f}l6 6m0 -6l-6 6" stroke="#d22" stroke-width="1.5"/>')
    solved = sum(1 for _, s in rows if s)
    median = rows[n // 2][0]
    p99 = rows[min(n - 1, round(0.99 * (n - 1)))][0]
    out.append(
        f'<text x="{x0 + LEFT}" y="16" font-size="12">{name}: {solved}/{n} solved, '
        f"median {median:.1f} ms, p99 {p99:.1f} ms</text>"
    )
    out.append(f'<text x="{x0 + LEFT + pw / 2}" y="{H - 10}" font-size="10" text-anchor="middle">problems, by solve time</text>')
    out.append(f'<text x="{x0 + 12}" y="{TOP + ph / 2}" font-size="10" transform="rotate(-90 {x0 + 12} {TOP + ph / 2})" text-anchor="middle">ms (log)</text>')
    return out


def main():
    if len(sys.argv) != 3:
        print(__doc__, file=sys.stderr)
        sys.exit(2)
    sets = load(sys.argv[1])
    names = [s for s in ("typical", "hard") if s in sets] + sorted(set(sets) - {"typical", "hard"})
    times = [ms for rows in sets.values() for ms, _ in rows]
    targets = [t for n in names for t in TARGETS.get(n, ())]
    lo = math.floor(math.log10(min(times + targets)) * 2) / 2
    hi = math.ceil(math.log10(max(times + targets)) * 2) / 2
    body = []
    for k, name in enumerate(names):
        body += panel(name, sets[name], k * W, lo, hi)
    svg = (
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{W * len(names)}" height="{H}" '
        f'font-family="sans-serif"><rect width="100%" height="100%" fill="white"/>'
        + "".join(body)
        + "</svg>\n"
    )
    tmp = sys.argv[2] + ".tmp"
    try:
        with open(tmp, "w") as f:
            f.write(svg)
        os.replace(tmp, sys.argv[2])
    except OSError as e:
        print(f"error: {sys.argv[2]}: {e}", file=sys.stderr)
        sys.exit(2)


if __name__ == "__main__":
    main()
