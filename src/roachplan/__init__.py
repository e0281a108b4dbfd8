"""roachplan: decide, by physics simulation, which path a small legged robot should take.

Subpackages: `roachplan.scenes`, `roachplan.perception`, `roachplan.planning`,
`roachplan.sim`, `roachplan.experiments` and `roachplan.app` (the CLI and the browser app); in
the repository they are src/roachplan/*, linked from its top level.
"""

from typing import TYPE_CHECKING

from roachplan._lazy import lazy_exports

__version__ = "0.1.0"

# The Python API (roachplan/_api.py), imported on first use: `import roachplan` stays quick.
__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {name: "._api" for name in ("load", "plan", "drive", "trial", "choose", "experiment", "mesh")},
)

if TYPE_CHECKING:
    from ._api import choose as choose
    from ._api import drive as drive
    from ._api import experiment as experiment
    from ._api import load as load
    from ._api import mesh as mesh
    from ._api import plan as plan
    from ._api import trial as trial
