"""Terrain-aware motion planning with OMPL over the robot's (x, y, yaw)."""

from ._heightfield import HeightField as HeightField
from ._heightfield import heightfield_from_mesh as heightfield_from_mesh
from ._ompl import PLANNER_NAMES as PLANNER_NAMES
from ._ompl import PlannerConfig as PlannerConfig
from ._ompl import PlannerName as PlannerName
from ._ompl import PlanningError as PlanningError
from ._ompl import PlanResult as PlanResult
from ._ompl import plan_path as plan_path
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
from ._validity import ValidityConfig as ValidityConfig
from ._validity import check_states as check_states
from ._validity import describe_state as describe_state
