"""What the side panel shows about the trials: rows, per-route summary, energy plot, CSV."""

from __future__ import annotations

import csv
import io
import math

import numpy as np

from roachplan.experiments import format_markdown, summarize

COLUMNS = ("#", "seed", "route", "outcome", "drive time [s]", "energy [J]", "rel. energy", "label")
CSV_FIELDS = (
    "trial",
    "label",
    "scene",
    "seed",
    "planner",
    "route",
    "outcome",
    "reason",
    "drive_time",
    "energy",
    "relative_energy",
    "plan_time",
    "drive_wall_time",
)
DRIVE_LABEL = "drive"
"""The label of a trial from the Drive button (its record may carry ""); the others are "batch"
and "best (trial K)": table and CSV use the same words."""


def significant(x: float, digits: int) -> str:
    """x to `digits` significant digits, in plain notation (1.092, 0.01234, 1235)."""
    x = float(x)
    if not math.isfinite(x) or x == 0.0:
        return f"{x:g}"
    decimals = max(digits - 1 - math.floor(math.log10(abs(x))), 0)
    return f"{round(x, decimals):.{decimals}f}"


FORMATS = {
    "drive_time": lambda v: f"{v:.2f}",  # simulated [s]: the 20 ms control period's precision
    "energy": lambda v: significant(v, 4),  # [J]: the sum of its steps' work, to 4 digits
    "relative_energy": lambda v: significant(v, 3),  # a ratio of two such energies
    "plan_time": lambda v: f"{v:.3f}",  # wall clock [s], to the millisecond
    "drive_wall_time": lambda v: f"{v:.3f}",
}
"""How each measured number is written, in the table and the CSV alike."""


def label_of(trial: dict) -> str:
    return trial.get("label") or DRIVE_LABEL


def cell(trial: dict, field: str) -> str:
    """A trial's field as the page and the CSV write it (numbers rounded to their precision)."""
    if field == "label":
        return label_of(trial)
    value = trial.get(field, "")
    if field in FORMATS and isinstance(value, (int, float)) and not isinstance(value, bool):
        return FORMATS[field](value)
    return "" if value is None else str(value)


TABLE_STYLE = "overflow-x: auto; max-width: 100%; font-size: 0.8em"
"""The trials table scrolls sideways inside the panel rather than being clipped by it."""


def trials_markdown(trials: list[dict]) -> str:
    """A row per trial (trial dicts as TrialResult.to_json(), plus "label"), in a box that
    scrolls sideways when the panel is narrower than the table."""
    head = "| " + " | ".join(COLUMNS) + " |\n|" + "---|" * len(COLUMNS) + "\n"
    rows = "".join(
        f"| {k + 1} | {t['seed']} | {t['route'] or '-'} | {t['outcome']} "
        f"| {cell(t, 'drive_time')} | {cell(t, 'energy')} | {cell(t, 'relative_energy')} "
        f"| {label_of(t)} |\n"
        for k, t in enumerate(trials)
    )
    table = head + (rows or "|" + " |" * len(COLUMNS) + "\n")
    return (
        f'**Trials**\n\n<div class="roachplan-trials" style="{TABLE_STYLE}">\n\n{table}\n</div>\n'
    )


def summary_markdown(trials: list[dict]) -> str:
    """Tables 7.1-7.3 layout: a column per route (trials with a path)."""
    driven = [t for t in trials if t["outcome"] != "no_path" or t["route"]]
    if not driven:
        return ""
    table = format_markdown(summarize(driven))
    return (
        f"**Summary per route** (relative energy, successes only)\n\n"
        f'<div class="roachplan-summary" style="{TABLE_STYLE}">\n\n{table}\n\n</div>\n'
    )


def energy_plot(
    trials: list[dict], width: int = 320, height: int = 240, scale: int = 2
) -> np.ndarray:
    """(H, W, 3) uint8 image: relative energy per trial, successes filled, failures hollow.
    width, height: its size on the page [CSS px] (the panel shows it at most as wide as
    itself, ~300 px); drawn at `scale` times that, so that it stays sharp when shown larger
    (the image's expand button). The legend sits above the axes, never over a point."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.ticker import MaxNLocator

    # figsize in inches at 72 dpi x scale: a font of N pt is N CSS px on the page.
    fig, ax = plt.subplots(figsize=(width / 72, height / 72), dpi=72 * scale)
    k = np.arange(1, len(trials) + 1)
    e = np.array([t["relative_energy"] for t in trials], dtype=float)
    ok = np.array([t["outcome"] == "success" for t in trials], dtype=bool)
    if len(trials):
        ax.plot(k[ok], e[ok], "o", color="tab:blue", label="success")
        ax.plot(k[~ok], e[~ok], "o", mfc="none", color="tab:red", label="failed")
        ax.legend(
            fontsize=11,
            loc="lower left",
            bbox_to_anchor=(0.0, 1.0),
            ncol=2,
            frameon=False,
            borderaxespad=0.2,
            handletextpad=0.2,
        )
        locator = ax.xaxis.get_major_locator()
        assert isinstance(locator, MaxNLocator)  # (a linear axis's AutoLocator)
        locator.set_params(integer=True)
    ax.set_xlabel("trial", fontsize=12)
    ax.set_ylabel("relative energy", fontsize=12)
    ax.tick_params(labelsize=11)
    ax.grid(alpha=0.3)
    fig.tight_layout(pad=0.4)
    canvas = fig.canvas
    assert isinstance(canvas, FigureCanvasAgg)  # (the Agg backend's)
    canvas.draw()
    img = np.asarray(canvas.buffer_rgba())[..., :3].copy()
    plt.close(fig)
    return img


def trials_csv(trials: list[dict]) -> str:
    """The trials as CSV, written as the table writes them (same rounding, same labels)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_FIELDS)
    for k, t in enumerate(trials):
        w.writerow([k + 1, *(cell(t, f) for f in CSV_FIELDS[1:])])
    return buf.getvalue()
