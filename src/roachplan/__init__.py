"""roachplan: decide, by physics simulation, which path a small legged robot should take.

Subpackages: `roachplan.scenes`, `roachplan.perception`, `roachplan.planning`,
`roachplan.sim`, `roachplan.experiments` and `roachplan.app` (the CLI and the browser app); in
the repository they are src/roachplan/*, linked from its top level.
"""

from typing import TYPE_CHECKING

from roachplan._lazy import lazy_exports

__version__ = "0.1.0"

# The Python API (roachplan/_api.py), imported on first use: `import roachplan` stays quick; and
# the errors of bad input and the settings' validators, which every package shares.
__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        **{n: "._api" for n in ("load", "plan", "drive", "trial", "choose", "experiment", "mesh")},
        "InputError": "._errors",
        "SettingError": "._settings",
        "setting_problem": "._settings",
    },
)

if TYPE_CHECKING:
    from ._api import choose as choose
    from ._api import drive as drive
    from ._api import experiment as experiment
    from ._api import load as load
    from ._api import mesh as mesh
    from ._api import plan as plan
    from ._api import trial as trial
    from ._errors import InputError as InputError
    from ._settings import SettingError as SettingError
    from ._settings import setting_problem as setting_problem
