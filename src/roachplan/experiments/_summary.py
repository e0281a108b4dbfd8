"""Per-route summary of trial records, in the layout of Tong 2018, tables 7.1 and 7.2.

Energy statistics are over successful trials only, as in the report; energies are the report's
relative unit (energy over that of a straight walk on a flat floor between start and goal).
The standard deviation is the sample one (n - 1).
"""

from __future__ import annotations

import csv
import io
import math
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

FAILURES = ("fell", "flipped", "stuck", "timeout", "missed", "no_path")
NO_PATH_ROUTE = "(no path)"


@dataclass(frozen=True, kw_only=True)
class RouteSummary:
    route: str
    trials: int
    successes: int
    energy_mean: float
    """Relative energy, successful trials only [-] (nan without a success)."""
    energy_std: float
    """Sample standard deviation [-] (nan with fewer than two successes)."""
    energy_min: float
    energy_max: float
    energy_joules_mean: float
    """Mean energy of the successful trials [J]."""
    drive_time_mean: float
    """Mean simulated drive time of the successful trials [s]."""
    failures: dict[str, int] = field(default_factory=dict)
    """Failed trials by outcome."""


def route_key(record: dict) -> str:
    """The route a trial counts for: the one it was picked for, else the one its path took."""
    return record.get("target_route") or record.get("route") or NO_PATH_ROUTE


def summarize(records: list[dict], route_order: tuple[str, ...] = ()) -> list[RouteSummary]:
    """One summary per route of the trial records ({"route"/"target_route", "outcome",
    "relative_energy", "energy", "drive_time"}); routes in route_order first, then by name."""
    groups: dict[str, list[dict]] = {r: [] for r in route_order}
    for rec in records:
        groups.setdefault(route_key(rec), []).append(rec)
    out = []
    for route in [*route_order, *sorted(set(groups) - set(route_order))]:
        recs = groups[route]
        ok = [r for r in recs if r["outcome"] == "success"]
        rel = np.array([r["relative_energy"] for r in ok], dtype=np.float64)
        nan = math.nan
        out.append(
            RouteSummary(
                route=route,
                trials=len(recs),
                successes=len(ok),
                energy_mean=float(rel.mean()) if len(rel) else nan,
                energy_std=float(rel.std(ddof=1)) if len(rel) > 1 else nan,
                energy_min=float(rel.min()) if len(rel) else nan,
                energy_max=float(rel.max()) if len(rel) else nan,
                energy_joules_mean=float(np.mean([r["energy"] for r in ok])) if ok else nan,
                drive_time_mean=float(np.mean([r["drive_time"] for r in ok])) if ok else nan,
                failures=dict(Counter(r["outcome"] for r in recs if r["outcome"] != "success")),
            )
        )
    return out


# Rows of the table: (label, attribute, format).
ROWS = (
    ("number of trials", "trials", "{:d}"),
    ("successful traversals", "successes", "{:d}"),
    ("average energy expended", "energy_mean", "{:.3f}"),
    ("std. dev. energy expended", "energy_std", "{:.4f}"),
    ("minimum energy expended", "energy_min", "{:.3f}"),
    ("maximum energy expended", "energy_max", "{:.3f}"),
    ("average energy [J]", "energy_joules_mean", "{:.3f}"),
    ("average drive time [s]", "drive_time_mean", "{:.2f}"),
)


def _cell(value, fmt: str) -> str:
    if _is_nan(value):
        return "-"
    return fmt.format(value)


def _is_nan(v) -> bool:
    return isinstance(v, float) and math.isnan(v)


def _failures(s: RouteSummary) -> str:
    return ", ".join(f"{k} {v}" for k, v in sorted(s.failures.items())) or "none"


def table_rows(summaries: list[RouteSummary]) -> list[list[str]]:
    """[header, *rows]: a metric per row, a route per column (the report's layout)."""
    rows = [["", *(s.route for s in summaries)]]
    for label, attr, fmt in ROWS:
        rows.append([label, *(_cell(getattr(s, attr), fmt) for s in summaries)])
    rows.append(["failures", *(_failures(s) for s in summaries)])
    return rows


def format_table(summaries: list[RouteSummary]) -> str:
    """Plain text: columns separated by at least two spaces (numbers never contain two)."""
    rows = table_rows(summaries)
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = []
    for r in rows:
        cells = [r[0].ljust(widths[0])] + [c.rjust(w) for c, w in zip(r[1:], widths[1:])]
        lines.append("  ".join(cells).rstrip())
    return "\n".join(lines)


def format_markdown(summaries: list[RouteSummary]) -> str:
    rows = table_rows(summaries)
    lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
    lines += ["| " + " | ".join(r) + " |" for r in rows[1:]]
    return "\n".join(lines)


def format_csv(summaries: list[RouteSummary]) -> str:
    """A route per row (tidy), failures as one column per outcome."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    attrs = [a for _, a, _ in ROWS]
    w.writerow(["route", *attrs, *(f"failed_{f}" for f in FAILURES)])
    for s in summaries:
        values = [getattr(s, a) for a in attrs]
        w.writerow(
            [
                s.route,
                *("" if _is_nan(v) else v for v in values),
                *(s.failures.get(f, 0) for f in FAILURES),
            ]
        )
    return buf.getvalue()


def compare_routes(a: RouteSummary, b: RouteSummary, records: list[dict]) -> str:
    """Are two routes distinguishable? Fisher's exact test on the success counts and the
    Mann-Whitney U test on the successful trials' relative energies (both two-sided)."""
    from scipy.stats import fisher_exact, mannwhitneyu

    table = [[a.successes, a.trials - a.successes], [b.successes, b.trials - b.successes]]
    # (scipy's xp_capabilities decorator hides fisher_exact's SignificanceResult from pyright)
    p_success = (
        fisher_exact(table).pvalue  # pyright: ignore[reportAttributeAccessIssue]
        if a.trials and b.trials
        else math.nan
    )
    ea, eb = (
        [
            r["relative_energy"]
            for r in records
            if route_key(r) == s.route and r["outcome"] == "success"
        ]
        for s in (a, b)
    )
    p_energy = mannwhitneyu(ea, eb).pvalue if ea and eb else math.nan
    return (
        f"{a.route} vs {b.route}: successes {a.successes}/{a.trials} vs {b.successes}/{b.trials} "
        f"(Fisher exact p = {p_success:.2f}); energy {_cell(a.energy_mean, '{:.3f}')} vs "
        f"{_cell(b.energy_mean, '{:.3f}')} (Mann-Whitney U p = {p_energy:.3g})"
    )
