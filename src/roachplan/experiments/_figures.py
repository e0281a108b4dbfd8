"""Figures of an experiment (Tong 2018, figures 7.1-7.4): planned paths in black, driven
trajectories in blue, over a top view of the terrain; and energy per route."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # files only; never a window
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from roachplan.planning import HeightField  # noqa: E402

from ._summary import route_key  # noqa: E402


def _terrain(ax, hf: HeightField) -> None:
    x0, x1, y0, y1 = hf.extent
    ax.imshow(
        np.ma.masked_invalid(hf.heights),
        origin="lower",
        extent=(x0, x1, y0, y1),
        cmap="Greys",
        alpha=0.55,
        interpolation="nearest",
    )
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")


def paths_figure(
    path: Path, hf: HeightField, trials: list[dict], best: dict | None, title: str
) -> None:
    """Two top views side by side: successful trials, failed trials. Each shows every trial's
    planned path (black) and driven trajectory (blue); a failure's trajectory ends in a red x.
    The best path (lowest-energy success) is drawn thicker, in green."""
    ok = [t for t in trials if t["outcome"] == "success"]
    bad = [t for t in trials if t["outcome"] != "success"]
    x0, x1, y0, y1 = hf.extent
    if (x1 - x0) > (y1 - y0):  # a wide terrain: one panel above the other
        fig, axes = plt.subplots(
            2, 1, figsize=(10, 2 * 9 * (y1 - y0) / (x1 - x0) + 2.2), sharex=True
        )
    else:
        fig, axes = plt.subplots(1, 2, figsize=(11, 8.5), sharey=True)
    for ax, group, label in ((axes[0], ok, "successful"), (axes[1], bad, "failed")):
        _terrain(ax, hf)
        for t in group:  # trajectories first and wider, so the planned path shows on top
            if t["trajectory"]:
                q = np.asarray(t["trajectory"])
                ax.plot(
                    q[:, 1],
                    q[:, 2],
                    color="tab:blue",
                    lw=1.8,
                    alpha=0.8,
                    ls="-" if t["outcome"] == "success" else "--",
                )
                if t["outcome"] != "success":
                    ax.plot(q[-1, 1], q[-1, 2], "x", color="red", ms=9, mew=2, zorder=5)
            if t["path"]:
                p = np.asarray(t["path"])
                ax.plot(p[:, 0], p[:, 1], color="black", lw=0.7)
        if best is not None and label == "successful":
            p = np.asarray(best["path"])
            ax.plot(
                p[:, 0], p[:, 1], color="tab:green", lw=2.5, label=f"best (trial {best['index']})"
            )
            ax.legend(loc="upper right", fontsize=8)
        ax.set_title(f"{label}: {len(group)} of {len(trials)} trials")
    fig.suptitle(f"{title}\nplanned path black, driven trajectory blue; failures end in a red x")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def energy_figure(path: Path, trials: list[dict], routes: list[str], title: str) -> None:
    """Relative energy of every successful trial per route (points over a box plot), with
    each route's success count in its label."""
    fig, ax = plt.subplots(figsize=(1.8 + 1.8 * max(len(routes), 1), 5))
    data, labels = [], []
    rng = np.random.default_rng(0)  # horizontal scatter of the points only
    for i, route in enumerate(routes):
        recs = [t for t in trials if route_key(t) == route]
        e = np.array([t["relative_energy"] for t in recs if t["outcome"] == "success"])
        data.append(e)
        labels.append(f"{route}\n{len(e)}/{len(recs)} succeeded")
        ax.plot(i + 1 + rng.uniform(-0.12, 0.12, len(e)), e, "o", color="tab:blue", ms=4, alpha=0.7)
    ax.boxplot([d if len(d) else [np.nan] for d in data], showfliers=False)
    ax.set_xticks(range(1, len(routes) + 1), labels)
    ax.set_ylabel("energy [relative to a straight floor walk]")
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
