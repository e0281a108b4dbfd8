"""Terrain-aware motion planning with OMPL over the robot's (x, y, yaw)."""

from typing import TYPE_CHECKING

from roachplan._lazy import lazy_exports

# Public names, imported on first use (roachplan._lazy): the command line answers at once.
_getattr, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "HeightField": "._heightfield",
        "heightfield_from_mesh": "._heightfield",
        "GridCover": "._heightfield",
        "grid_cover": "._heightfield",
        "heightfield_from_cover": "._heightfield",
        "IsolationError": "._isolated",
        "run_isolated": "._isolated",
        "PLANNER_NAMES": "._names",
        "MAX_TIME_LIMIT": "._config",
        "PlannerConfig": "._config",
        "PlannerName": "._names",
        "PlanningError": "._names",
        "PlanResult": "._ompl",
        "plan_path": "._ompl",
        "start_plan": "._ompl",
        "waypoints_on_surface": "._ompl",
        "StandableMap": "._regions",
        "homology_signature": "._regions",
        "signature_label": "._regions",
        "standable_map": "._regions",
        "BODY_HEIGHT": "._validity",
        "COLLISION": "._validity",
        "CONDITION_NAMES": "._validity",
        "FOOT": "._validity",
        "OFF_MAP": "._validity",
        "SLOPE": "._validity",
        "VALID": "._validity",
        "Footprint": "._validity",
        "StateCheck": "._validity",
        "ValidityConfig": "._config",
        "check_states": "._validity",
        "describe_state": "._validity",
    },
)
if not TYPE_CHECKING:  # (a type checker sees the names imported below instead, and so
    # reports an import from here of a name that is not one of them)
    __getattr__ = _getattr
del _getattr

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and editors
    from ._config import MAX_TIME_LIMIT as MAX_TIME_LIMIT
    from ._config import PlannerConfig as PlannerConfig
    from ._config import ValidityConfig as ValidityConfig
    from ._heightfield import GridCover as GridCover
    from ._heightfield import HeightField as HeightField
    from ._heightfield import grid_cover as grid_cover
    from ._heightfield import heightfield_from_cover as heightfield_from_cover
    from ._heightfield import heightfield_from_mesh as heightfield_from_mesh
    from ._isolated import IsolationError as IsolationError
    from ._isolated import run_isolated as run_isolated
    from ._names import PLANNER_NAMES as PLANNER_NAMES
    from ._names import PlannerName as PlannerName
    from ._names import PlanningError as PlanningError
    from ._ompl import PlanResult as PlanResult
    from ._ompl import plan_path as plan_path
    from ._ompl import start_plan as start_plan
    from ._ompl import waypoints_on_surface as waypoints_on_surface
    from ._regions import StandableMap as StandableMap
    from ._regions import homology_signature as homology_signature
    from ._regions import signature_label as signature_label
    from ._regions import standable_map as standable_map
    from ._validity import BODY_HEIGHT as BODY_HEIGHT
    from ._validity import COLLISION as COLLISION
    from ._validity import CONDITION_NAMES as CONDITION_NAMES
    from ._validity import FOOT as FOOT
    from ._validity import OFF_MAP as OFF_MAP
    from ._validity import SLOPE as SLOPE
    from ._validity import VALID as VALID
    from ._validity import Footprint as Footprint
    from ._validity import StateCheck as StateCheck
    from ._validity import check_states as check_states
    from ._validity import describe_state as describe_state
