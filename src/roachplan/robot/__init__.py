"""The robot in the loop: drive a real robot with the same planner and driver as the
simulation, record every run, and measure how well the simulation predicted it.

Pose in (NatNet from OptiTrack Motive, unicast; a UDP/JSON stream; or a registered source),
motor commands out (a documented binary frame over UDP or a serial line; or a registered
link), safety stops as values, a page-independent loop with events, MCAP run logs, a twin
that stands in for the robot on the same protocols (`python -m roachplan.robot.twin`), and
compare/fit of the simulation against logged runs.
"""

from typing import TYPE_CHECKING

from roachplan._lazy import lazy_exports

# Public names, imported on first use (roachplan._lazy): the command line answers at once.
__getattr__, __dir__, __all__ = lazy_exports(
    __name__,
    {
        "RobotError": "._errors",
        "CommandFrame": "._frames",
        "FRAME_SIZE": "._frames",
        "FrameReader": "._frames",
        "decode_command": "._frames",
        "encode_command": "._frames",
        "CommandLink": "._links",
        "LINKS": "._links",
        "SerialCommandLink": "._links",
        "SerialLinkSettings": "._links",
        "UdpCommandLink": "._links",
        "UdpLinkSettings": "._links",
        "UdpCommandReceiver": "._links",
        "FdCommandReceiver": "._links",
        "open_link": "._links",
        "register_link": "._links",
        "PoseSample": "._pose",
        "PoseSource": "._pose",
        "POSE_SOURCES": "._pose",
        "UdpJsonPoseSource": "._pose",
        "UdpJsonSettings": "._pose",
        "open_pose_source": "._pose",
        "register_pose_source": "._pose",
        "parse_pose_json": "._pose",
        "pose_json": "._pose",
        "NatNetPoseSource": "._natnet",
        "NatNetServer": "._natnet",
        "NatNetSettings": "._natnet",
        "RigidBodyFrame": "._natnet",
        "RigidBodyModel": "._natnet",
        "frame_packet": "._natnet",
        "model_def_packet": "._natnet",
        "server_info_packet": "._natnet",
        "NATNET_VERSION": "._natnet",
        "FrameTransform": "._transform",
        "measure_transform": "._transform",
        "SafetyConfig": "._safety",
        "SafetyMap": "._safety",
        "Stop": "._safety",
        "StopReason": "._safety",
        "check_pose": "._safety",
        "distance_to_path": "._safety",
        "LoopConfig": "._config",
        "RobotLoop": "._loop",
        "RunResult": "._loop",
        "LoopEvent": "._loop",
        "PoseEvent": "._loop",
        "CommandEvent": "._loop",
        "StopEvent": "._loop",
        "FinishedEvent": "._loop",
        "RunRecorder": "._record",
        "RunLog": "._record",
        "read_run": "._record",
        "RobotSettings": "._config",
        "RobotRun": "._run",
        "scene_record": "._record",
        "wait_first_pose": "._run",
        "start_height": "._run",
        "yaw_of": "._transform",
        "parse_address": "._checks",
        "drive_robot": "._run",
        "plan_clear_of": "._run",
        "plan_start": "._run",
        "rejoin_path": "._run",
        "rejoin_plan": "._run",
        "REJOIN_MIN": "._run",
        "replan_radius": "._run",
        "drift_allowance": "._run",
        "drift_hold_at": "._run",
        "drift_rate": "._run",
        "DRIFT_MARGIN": "._run",
        "RETURN_SLACK": "._run",
        "GUARD_HOLDS": "._run",
        "MAX_WIDENING": "._run",
        "SPIN_ONLY_RADIUS": "._run",
        "EDGE_OFF": "._edges",
        "EDGE_ROOM": "._edges",
        "STEP_REACH": "._edges",
        "at_edge": "._edges",
        "step_in": "._edges",
        "lead_in": "._run",
        "stepped_plan": "._run",
        "nearest_on_path": "._safety",
        "START_REACH": "._run",
        "MIN_TRY": "._run",
        "clearance": "._run",
        "watch_ahead": "._run",
        "AVOID_RADIUS": "._run",
        "AVOID_TRIES": "._run",
        "EDGE_TRIES": "._run",
        "edge_margin": "._edges",
        "plan_keeps": "._run",
        "predict": "._run",
        "LookAhead": "._lookahead",
        "LookAheadConfig": "._lookahead",
        "LookAheadRunner": "._lookahead",
        "look_ahead_reliability": "._lookahead",
        "observed_hold": "._lookahead",
        "look_ahead": "._lookahead",
        "estimate_mismatch": "._estimate",
        "pooled_mismatch": "._estimate",
        "trim_commands": "._estimate",
        "straight_mismatches": "._estimate",
        "PRIOR_WALK": "._estimate",
        "remaining_path": "._lookahead",
        "phase_at": "._lookahead",
        "PHASE_KEPT": "._lookahead",
        "Comparison": "._compare",
        "FitConfig": "._compare",
        "FitResult": "._compare",
        "SimParams": "._compare",
        "Windows": "._compare",
        "compare": "._compare",
        "fit": "._compare",
        "log_world": "._compare",
        "motor_phase": "._compare",
        "nominal_params": "._compare",
        "params_of_robot_file": "._compare",
        "replay_windows": "._compare",
        "TwinConfig": "._twin",
        "run_twin": "._twin",
    },
)

if TYPE_CHECKING:  # the same names, eagerly, for type checkers and editors
    from ._checks import parse_address as parse_address
    from ._compare import Comparison as Comparison
    from ._compare import FitConfig as FitConfig
    from ._compare import FitResult as FitResult
    from ._compare import SimParams as SimParams
    from ._compare import Windows as Windows
    from ._compare import compare as compare
    from ._compare import fit as fit
    from ._compare import log_world as log_world
    from ._compare import motor_phase as motor_phase
    from ._compare import nominal_params as nominal_params
    from ._compare import params_of_robot_file as params_of_robot_file
    from ._compare import replay_windows as replay_windows
    from ._config import LoopConfig as LoopConfig
    from ._config import RobotSettings as RobotSettings
    from ._edges import EDGE_OFF as EDGE_OFF
    from ._edges import EDGE_ROOM as EDGE_ROOM
    from ._edges import STEP_REACH as STEP_REACH
    from ._edges import at_edge as at_edge
    from ._edges import edge_margin as edge_margin
    from ._edges import step_in as step_in
    from ._errors import RobotError as RobotError
    from ._estimate import PRIOR_WALK as PRIOR_WALK
    from ._estimate import estimate_mismatch as estimate_mismatch
    from ._estimate import pooled_mismatch as pooled_mismatch
    from ._estimate import straight_mismatches as straight_mismatches
    from ._estimate import trim_commands as trim_commands
    from ._frames import FRAME_SIZE as FRAME_SIZE
    from ._frames import CommandFrame as CommandFrame
    from ._frames import FrameReader as FrameReader
    from ._frames import decode_command as decode_command
    from ._frames import encode_command as encode_command
    from ._links import LINKS as LINKS
    from ._links import CommandLink as CommandLink
    from ._links import FdCommandReceiver as FdCommandReceiver
    from ._links import SerialCommandLink as SerialCommandLink
    from ._links import SerialLinkSettings as SerialLinkSettings
    from ._links import UdpCommandLink as UdpCommandLink
    from ._links import UdpCommandReceiver as UdpCommandReceiver
    from ._links import UdpLinkSettings as UdpLinkSettings
    from ._links import open_link as open_link
    from ._links import register_link as register_link
    from ._lookahead import PHASE_KEPT as PHASE_KEPT
    from ._lookahead import LookAhead as LookAhead
    from ._lookahead import LookAheadConfig as LookAheadConfig
    from ._lookahead import LookAheadRunner as LookAheadRunner
    from ._lookahead import look_ahead as look_ahead
    from ._lookahead import look_ahead_reliability as look_ahead_reliability
    from ._lookahead import observed_hold as observed_hold
    from ._lookahead import phase_at as phase_at
    from ._lookahead import remaining_path as remaining_path
    from ._loop import CommandEvent as CommandEvent
    from ._loop import FinishedEvent as FinishedEvent
    from ._loop import LoopEvent as LoopEvent
    from ._loop import PoseEvent as PoseEvent
    from ._loop import RobotLoop as RobotLoop
    from ._loop import RunResult as RunResult
    from ._loop import StopEvent as StopEvent
    from ._natnet import NATNET_VERSION as NATNET_VERSION
    from ._natnet import NatNetPoseSource as NatNetPoseSource
    from ._natnet import NatNetServer as NatNetServer
    from ._natnet import NatNetSettings as NatNetSettings
    from ._natnet import RigidBodyFrame as RigidBodyFrame
    from ._natnet import RigidBodyModel as RigidBodyModel
    from ._natnet import frame_packet as frame_packet
    from ._natnet import model_def_packet as model_def_packet
    from ._natnet import server_info_packet as server_info_packet
    from ._pose import POSE_SOURCES as POSE_SOURCES
    from ._pose import PoseSample as PoseSample
    from ._pose import PoseSource as PoseSource
    from ._pose import UdpJsonPoseSource as UdpJsonPoseSource
    from ._pose import UdpJsonSettings as UdpJsonSettings
    from ._pose import open_pose_source as open_pose_source
    from ._pose import parse_pose_json as parse_pose_json
    from ._pose import pose_json as pose_json
    from ._pose import register_pose_source as register_pose_source
    from ._record import RunLog as RunLog
    from ._record import RunRecorder as RunRecorder
    from ._record import read_run as read_run
    from ._record import scene_record as scene_record
    from ._run import AVOID_RADIUS as AVOID_RADIUS
    from ._run import AVOID_TRIES as AVOID_TRIES
    from ._run import DRIFT_MARGIN as DRIFT_MARGIN
    from ._run import EDGE_TRIES as EDGE_TRIES
    from ._run import GUARD_HOLDS as GUARD_HOLDS
    from ._run import MAX_WIDENING as MAX_WIDENING
    from ._run import MIN_TRY as MIN_TRY
    from ._run import REJOIN_MIN as REJOIN_MIN
    from ._run import RETURN_SLACK as RETURN_SLACK
    from ._run import SPIN_ONLY_RADIUS as SPIN_ONLY_RADIUS
    from ._run import START_REACH as START_REACH
    from ._run import RobotRun as RobotRun
    from ._run import clearance as clearance
    from ._run import drift_allowance as drift_allowance
    from ._run import drift_hold_at as drift_hold_at
    from ._run import drift_rate as drift_rate
    from ._run import drive_robot as drive_robot
    from ._run import lead_in as lead_in
    from ._run import plan_clear_of as plan_clear_of
    from ._run import plan_keeps as plan_keeps
    from ._run import plan_start as plan_start
    from ._run import predict as predict
    from ._run import rejoin_path as rejoin_path
    from ._run import rejoin_plan as rejoin_plan
    from ._run import replan_radius as replan_radius
    from ._run import start_height as start_height
    from ._run import stepped_plan as stepped_plan
    from ._run import wait_first_pose as wait_first_pose
    from ._run import watch_ahead as watch_ahead
    from ._safety import SafetyConfig as SafetyConfig
    from ._safety import SafetyMap as SafetyMap
    from ._safety import Stop as Stop
    from ._safety import StopReason as StopReason
    from ._safety import check_pose as check_pose
    from ._safety import distance_to_path as distance_to_path
    from ._safety import nearest_on_path as nearest_on_path
    from ._transform import FrameTransform as FrameTransform
    from ._transform import measure_transform as measure_transform
    from ._transform import yaw_of as yaw_of
    from ._twin import TwinConfig as TwinConfig
    from ._twin import run_twin as run_twin
