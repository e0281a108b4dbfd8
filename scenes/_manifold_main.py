"""Run openscad-evaluator (backend manifold) as OpenSCAD 2021.01 would render the model.

Run as `python -I -S -B _manifold_main.py SITE_PATHS_JSON MODEL -o OUT ...` by
scenes/_openscad.py, inside the render jail: it imports nothing of roachplan, puts only the
evaluator's site-packages folder on sys.path, and hands the rest of its arguments to the
evaluator's command line.

One change to the evaluator: seeded `rands(min, max, n, seed)` draws the numbers OpenSCAD
2021.01 draws, so a model's seeded bumps (double_bridge_rough) land where the reference binary
puts them. The evaluator draws from Python's `random` seeded with int(seed), a different
sequence (measured: rands(0, 1, 4, 0) gives 0.844, 0.758, ... against OpenSCAD's 0.593, 0.844,
...). OpenSCAD 2021.01 seeds a std::mt19937 with the seed converted to a 32-bit unsigned integer
and draws each number with std::uniform_real_distribution, which takes two 32-bit outputs per
number (libstdc++'s generate_canonical<double, 53>); checked against Debian's binary for seeds
0, 1, 42, -3 and 12345, and min > max. A non-integer seed is seeded otherwise there (not found
out), so it is refused with a message that names backend cgal. Unseeded rands() is random in
OpenSCAD too and is left as the evaluator has it.
"""

from __future__ import annotations

import json
import math
import os
import random
import sys


def mt19937(seed: int) -> random.Random:
    """A generator whose getrandbits(32) are std::mt19937(seed)'s outputs (init_genrand, not
    Python's own init_by_array seeding)."""
    state = [seed & 0xFFFFFFFF]
    for i in range(1, 624):
        state.append((1812433253 * (state[-1] ^ (state[-1] >> 30)) + i) & 0xFFFFFFFF)
    rng = random.Random()
    rng.setstate((3, (*state, 624), None))
    return rng


REFUSED = 3
"""Exit status of a render stopped for a construct it would not draw as OpenSCAD does."""
SEEDS = (-(1 << 31), 1 << 32)
"""Seeds whose draws are OpenSCAD's [min, max): integers that convert to a 32-bit seed alike."""


def openscad_rands(lo: float, hi: float, n: int, seed: int) -> list[float]:
    """rands(lo, hi, n, seed) as OpenSCAD 2021.01 computes it, for an integer seed in SEEDS."""
    rng = mt19937(seed & 0xFFFFFFFF)
    a, b = min(lo, hi), max(lo, hi)
    out = []
    for _ in range(max(0, int(n))):
        low = rng.getrandbits(32)
        high = rng.getrandbits(32)
        u = (float(low) + float(high) * 4294967296.0) / 18446744073709551616.0
        if u >= 1.0:
            u = math.nextafter(1.0, 0.0)
        out.append(u * (b - a) + a)
    return out


def _patch_rands() -> None:
    from openscad_evaluator.evaluator import Evaluator

    unseeded = Evaluator._builtin_rands

    def _builtin_rands(self, minval, maxval, n, seed=None):
        if seed is None:
            return unseeded(self, minval, maxval, n)
        seed = float(seed)
        if not (seed.is_integer() and SEEDS[0] <= seed < SEEDS[1]):
            # Not an EvalError: the evaluator turns one inside an expression into undef and
            # goes on, and the render would "succeed" with other numbers than OpenSCAD's.
            sys.stderr.write(
                f"ERROR: rands() with the seed {seed:g}: backend manifold draws OpenSCAD's "
                f"numbers for integer seeds only; render this model with `backend: cgal`\n"
            )
            sys.stderr.flush()
            os._exit(REFUSED)
        self._rands_call_count += 1  # the evaluator's cache taint, as in its own rands
        return openscad_rands(float(minval), float(maxval), int(n), int(seed))

    Evaluator._builtin_rands = _builtin_rands


def main() -> int:
    # Everything on the error stream, as OpenSCAD writes it (echo(), the parser's syntax
    # errors): the renderer keeps that stream's ends for its messages and drops the output one.
    os.dup2(2, 1)
    sys.path[:0] = json.loads(sys.argv[1])
    _patch_rands()
    from openscad_evaluator.cli import main as evaluate

    return evaluate(sys.argv[2:])


if __name__ == "__main__":
    sys.exit(main())
