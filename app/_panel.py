"""What the side panel shows about the trials: rows, per-route summary, energy plot, CSV."""

from __future__ import annotations

import csv
import io

import numpy as np

from roachplan.experiments import summarize
from roachplan.experiments._summary import format_markdown

COLUMNS = ("#", "seed", "route", "outcome", "drive time [s]", "energy [J]", "rel. energy", "from")
CSV_FIELDS = ("trial", "label", "scene", "seed", "planner", "route", "outcome", "reason",
              "drive_time", "energy", "relative_energy", "plan_time", "drive_wall_time")  # fmt: skip


def trials_markdown(trials: list[dict]) -> str:
    """A row per trial (trial dicts as TrialResult.to_json(), plus "label")."""
    head = "| " + " | ".join(COLUMNS) + " |\n|" + "---|" * len(COLUMNS) + "\n"
    rows = "".join(
        f"| {k + 1} | {t['seed']} | {t['route'] or '-'} | {t['outcome']} "
        f"| {t['drive_time']:.2f} | {t['energy']:.3f} | {t['relative_energy']:.2f} "
        f"| {t.get('label') or 'drive'} |\n"
        for k, t in enumerate(trials)
    )
    return "**Trials**\n\n" + head + (rows or "|" + " |" * len(COLUMNS) + "\n")


def summary_markdown(trials: list[dict]) -> str:
    """Tables 7.1-7.3 layout: a column per route (trials with a path)."""
    driven = [t for t in trials if t["outcome"] != "no_path" or t["route"]]
    if not driven:
        return ""
    return "**Summary per route** (relative energy, successes only)\n\n" + format_markdown(
        summarize(driven)
    )


def energy_plot(trials: list[dict], width: int = 420, height: int = 220) -> np.ndarray:
    """(H, W, 3) uint8 image: relative energy per trial, successes filled, failures hollow."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(width / 100, height / 100), dpi=100)
    k = np.arange(1, len(trials) + 1)
    e = np.array([t["relative_energy"] for t in trials], dtype=float)
    ok = np.array([t["outcome"] == "success" for t in trials], dtype=bool)
    if len(trials):
        ax.plot(k[ok], e[ok], "o", color="tab:blue", label="success")
        ax.plot(k[~ok], e[~ok], "o", mfc="none", color="tab:red", label="failed")
        ax.legend(fontsize=7, loc="upper left")
    ax.set_xlabel("trial", fontsize=8)
    ax.set_ylabel("relative energy", fontsize=8)
    ax.tick_params(labelsize=7)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.canvas.draw()
    img = np.asarray(fig.canvas.buffer_rgba())[..., :3].copy()
    plt.close(fig)
    return img


def trials_csv(trials: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_FIELDS)
    for k, t in enumerate(trials):
        w.writerow([k + 1, *(t.get(f, "") for f in CSV_FIELDS[1:])])
    return buf.getvalue()
