"""Write scenes/library/heightmap.dat: rolling ground with a ramped plateau, for OpenSCAD surface().

The terrain is a closed-form function (no randomness), so this script always writes the same
file; it is kept to show, and to change, how the height map was made.

    python scripts/make_heightmap.py

Grid: 61 columns (x from -1.5 to 1.5 m) by 81 rows (y from -2 to 2 m), 5 cm apart; values in
centimetres. OpenSCAD's surface() puts row 0 at the lowest y, so the file's first line is y = -2.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

SPACING = 0.05  # [m]
X = np.linspace(-1.5, 1.5, 61)
Y = np.linspace(-2.0, 2.0, 81)


def height_cm(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Surface height [cm] at x, y [m]."""
    rolling = 2.5 + 2.5 * np.sin(2 * np.pi * x / 1.5 + 0.3) * np.sin(2 * np.pi * y / 2.0)
    # A 10 cm plateau for |x| <= 0.6 m, y in [-0.3, 0.3], reached by 0.6 m ramps (9.5 deg)
    # from either side; its long sides are cliffs, so a path goes over the ramps or around.
    rise = np.clip((0.9 - np.abs(y)) / 0.6, 0.0, 1.0) * 10.0
    plateau = np.where(np.abs(x) <= 0.6, rise, 0.0)
    return rolling + plateau


def main() -> None:
    xx, yy = np.meshgrid(X, Y)
    z = height_cm(xx, yy)
    out = Path(__file__).resolve().parent.parent / "scenes" / "library" / "heightmap.dat"
    header = "# Rolling ground with a ramped plateau; written by scripts/make_heightmap.py.\n"
    header += (
        "# 81 rows (y = -2 .. 2 m) x 61 columns (x = -1.5 .. 1.5 m), 5 cm apart, heights in cm.\n"
    )
    rows = "\n".join(" ".join(f"{v:.3f}" for v in row) for row in z)
    out.write_text(header + rows + "\n")
    print(f"wrote {out} ({z.shape[0]} x {z.shape[1]}, {z.min():.2f} .. {z.max():.2f} cm)")


if __name__ == "__main__":
    main()
