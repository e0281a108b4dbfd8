"""The `roachplan` command line's parser: every command, its arguments and their help. Light:
`roachplan --help` and an argument error answer without importing OMPL, Open3D, trimesh,
matplotlib or Ray; each command names the function that runs it ("module:function", imported
only when that command runs)."""

from __future__ import annotations

import argparse
import re

from roachplan.experiments import list_experiments
from roachplan.perception import DEPTH_UNITS, FRAMES, METHODS, PRESETS
from roachplan.planning import PLANNER_NAMES

from ._choose_cli import add_choose_parser
from ._flags import clip, engine_flag

FORCE_HELP = (
    "replace an existing output file roachplan did not write (never an input of the command)"
)
TERRAIN_HELP = (
    "library scene name, scene .yaml, or a terrain file (capture, mesh, .scad) "
    "as a scene with start and goal picked"
)
REFERENCE_HELP = (
    "the report's raw paths and algorithms 1-2 (default: drivable plans, "
    "arcs no tighter than the robot turns, and the tracking driver)"
)
SCALE_HELP = "scale every terrain model by S (0.001: millimetres)"


def _runs(p: argparse.ArgumentParser, function: str) -> None:
    """p's command runs roachplan.app.MODULE:FUNCTION (function: "MODULE:FUNCTION")."""
    p.set_defaults(run=f"roachplan.app.{function}")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="roachplan",
        description="Plan a small hexapod's path across terrain with OMPL and test it in PyBullet.",
        epilog="Outputs are written atomically and never over an input; -o replaces an existing "
        "file only if roachplan wrote it (or with --force). Exit status: 0 done, 1 a run that "
        "failed, 2 bad input.",
    )
    parser.add_argument(
        "--debug",
        action="store_true",
        help="show the Python traceback of an error (for a bug report)",
    )
    sub = parser.add_subparsers(dest="command", required=True)

    _add_serve_parser(sub)
    _add_planning_parsers(sub)
    _add_experiment_parser(sub)
    add_choose_parser(sub, TERRAIN_HELP)
    _add_replay_parser(sub)
    _add_robot_parsers(sub)
    _add_perception_parsers(sub)

    _add_calibrate_parser(sub)
    _add_scene_parsers(sub)
    # --debug after the command too (`roachplan plan --debug`); SUPPRESS keeps the top level's
    # value when it is not repeated there.
    for command in _all_parsers(parser)[1:]:
        command.add_argument(
            "--debug", action="store_true", default=argparse.SUPPRESS, help=argparse.SUPPRESS
        )
    return parser


def _all_parsers(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    """parser and every (sub)command's parser under it."""
    out = [parser]
    for action in parser._actions:  # argparse has no public walk of its subcommands
        if isinstance(action, argparse._SubParsersAction):
            for child in dict.fromkeys(action.choices.values()):
                out += _all_parsers(child)
    return out


def _add_replay_parser(sub) -> None:
    p = sub.add_parser(
        "replay",
        help="a trial, experiment, choice or robot run as one HTML file that plays offline",
    )
    p.add_argument(
        "folder",
        metavar="DIR|LOG.mcap",
        help="an experiment's results folder (`experiment --out`), a choice's (`choose --out`) "
        "or a robot run's log (`roachplan robot -o`)",
    )
    p.add_argument(
        "--trial",
        type=int,
        default=None,
        metavar="K",
        help="only trial K of the experiment (default: every trial drawn, the best "
        "path's trial walking)",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help=".html (standalone: viser's client and the recording in one file, opens "
        "offline) or .viser (viser's recording), in an existing folder; an "
        "existing file is replaced only if roachplan wrote it (else --force)",
    )
    p.add_argument(
        "--scene",
        default=None,
        help="a robot run's log only: the scene to show it on (default: the scene file the "
        "log names, as it was then)",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    _runs(p, "_experiment_cli:cmd_replay")


def _add_experiment_parser(sub) -> None:
    p = sub.add_parser(
        "experiment", help="a batch of trials in parallel: tables 7.1/7.2, figures, best path"
    )
    p.add_argument(
        "spec", metavar="SPEC", help=f"{', '.join(list_experiments())} or an experiment .yaml"
    )
    p.add_argument(
        "--trials",
        type=int,
        default=None,
        help="total trials, split evenly over the spec's routes (default: the spec's)",
    )
    p.add_argument("--reference", action="store_true", help=REFERENCE_HELP)
    p.add_argument(
        "--workers", type=int, default=None, help="parallel workers (default: all cores)"
    )
    p.add_argument(
        "--out",
        default=None,
        help="results folder, created if new (default: results/SPEC); an existing one "
        "must be empty or hold a roachplan experiment (to --resume)",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the experiment in --out (its --trials and --repeats by default)",
    )
    p.add_argument("--repeats", type=int, default=None, help="re-drives of the best path")
    p.add_argument(
        "--backend",
        choices=("local", "ray"),
        default="local",
        help="local worker processes, or a Ray cluster",
    )
    p.add_argument(
        "--address", default=None, help="Ray cluster address (default: start a local Ray instance)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    engine_flag(p)
    p.add_argument(
        "--cross-check",
        action="store_true",
        help="then drive every trial's path again under the other physics engine, from the "
        "same start: per route, success and energy under each, and whether the engines agree "
        "(cross_check.json)",
    )
    _runs(p, "_experiment_cli:cmd_experiment")


def _add_perception_parsers(sub) -> None:
    def capture_flags(p):
        p.add_argument(
            "--intrinsics",
            default=None,
            help=f"depth images: a calibration file (.json, PCL .xml, OpenCV or ROS "
            f".yaml) or a preset: {', '.join(PRESETS)}",
        )
        for k, what in (
            ("fx", "focal length x"),
            ("fy", "focal length y"),
            ("cx", "principal point x"),
            ("cy", "principal point y"),
        ):
            p.add_argument(
                f"--{k}",
                type=float,
                default=None,
                help=f"depth images: {what} [px] (with the other three of "
                f"--fx --fy --cx --cy, instead of --intrinsics)",
            )
        p.add_argument(
            "--depth-scale",
            type=float,
            default=None,
            help="depth images: units per metre (default: the calibration's or "
            "preset's, e.g. 5000 for tum-*, else 1000, i.e. mm)",
        )
        p.add_argument(
            "--depth-units",
            choices=DEPTH_UNITS,
            default=None,
            help="depth images: kinect-disparity for a Kinect v1's raw 11-bit "
            "disparity (NYU Depth v2's raw dumps), converted to metres with "
            "NYU's model (default: depth in units of --depth-scale; raw "
            "disparity is recognised when plain)",
        )
        p.add_argument("--units", choices=("m", "mm"), default=None, help="point cloud units")
        p.add_argument("--topic", default=None, help="bags: the topic to read")

    p = sub.add_parser("mesh", help="capture (point cloud, depth image, bag) -> terrain mesh")
    p.add_argument(
        "input", metavar="INPUT", help=".pcd .ply .xyz .pts .npy .png .pgm .ppm .bag .db3 .mcap"
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="mesh file: .stl, .ply or .obj, in an existing folder; an existing file "
        "is replaced only if roachplan wrote it (else --force), never the input",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--voxel", default=None, help="voxel size [m]: d or dx,dy,dz (default 0.01)")
    p.add_argument("--method", choices=METHODS, default=None, help="default: grid")
    p.add_argument(
        "--camera-pose",
        default=None,
        help="x,y,z,qx,qy,qz,qw of the camera in the world (default: from the ground)",
    )
    p.add_argument("--crop", default=None, help="world box xmin,ymin,zmin,xmax,ymax,zmax [m]")
    p.add_argument("--seed", type=int, default=None, help="RANSAC seed (default 0)")
    p.add_argument(
        "--frame",
        choices=FRAMES,
        default=None,
        help="camera: optical frame (x right, y down, z forward); world: z up (or "
        "--up), e.g. a lidar or a map; default auto: what the file says",
    )
    p.add_argument(
        "--up",
        default=None,
        metavar="X,Y,Z",
        help="up in the capture's frame (default: a calibration's pose, a bag's "
        "IMU, -y for a camera, +z for a world frame)",
    )
    p.add_argument(
        "--ground-point",
        default=None,
        metavar="X,Y,Z",
        help="a point on the intended ground, capture frame [m]: the plane through "
        "it is the ground",
    )
    p.add_argument(
        "--depth-range",
        default=None,
        metavar="NEAR,FAR",
        help="keep points this near/far [m] (default: 0.3,8 for a camera, all for a world frame)",
    )
    p.add_argument(
        "--recentre",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="put the cloud's centre at x = y = 0 (default: when georeferenced)",
    )
    p.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object: camera pose, ground, triangles, warnings",
    )
    capture_flags(p)
    _runs(p, "_perception_cli:cmd_mesh")

    p = sub.add_parser(
        "voxel-study", help="table 3.1: voxel size vs plane-fit error of a flat capture"
    )
    p.add_argument("capture", metavar="CAPTURE")
    p.add_argument("--sizes", default="1,2,5,10,20", help="voxel sizes [cm]")
    p.add_argument(
        "--square",
        type=float,
        default=None,
        help="use the points within this square around the optical axis [m]",
    )
    p.add_argument(
        "--region",
        default=None,
        metavar="X0,Y0,X1,Y1",
        help="use the points with x0<=x<=x1, y0<=y<=y1 in the camera frame (x right, y down) [m]",
    )
    p.add_argument(
        "--plane",
        action="store_true",
        help="use only the dominant plane's points (RANSAC), e.g. a room's wall",
    )
    p.add_argument("--seed", type=int, default=None, help="RANSAC seed of --plane (default 0)")
    p.add_argument("--json", action="store_true", help="print the study as JSON")
    p.add_argument(
        "--csv",
        default=None,
        help="also write the table to this .csv file (an existing file is replaced "
        "only if it is a voxel-study table, else with --force)",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--voxel", default=None, help=argparse.SUPPRESS)
    capture_flags(p)
    _runs(p, "_perception_cli:cmd_voxel_study")

    p = sub.add_parser("synth-capture", help="render a scene as a noisy Kinect v2 depth capture")
    p.add_argument("scene", metavar="SCENE", help="library scene name or scene .yaml")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help=".png (+ .json sidecar), .pcd, .ply or .npy in an existing folder; an existing "
        "file is replaced only with --force",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--eye", required=True, help="camera position x,y,z [m]")
    p.add_argument("--target", required=True, help="point the camera looks at x,y,z [m]")
    p.add_argument("--intrinsics", default="kinect2-qhd", help=f"{', '.join(PRESETS)} or a file")
    p.add_argument("--seed", type=int, default=0, help="seed of the noise")
    p.add_argument("--no-noise", action="store_true", help="exact depth")
    _runs(p, "_perception_cli:cmd_synth_capture")


class _Parser(argparse.ArgumentParser):
    """argparse, with its error messages bounded (it echoes a refused value whole), and a value
    that starts with a negative number taken as a value: `--crop -1,-1,0,1,1,1`, not "expected
    one argument" (no roachplan option looks like a number)."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = re.compile(r"^-(\d|\.\d)[\d.,eE+\-]*$")

    def error(self, message: str):
        super().error(clip(message, 300))


def _add_serve_parser(sub) -> None:
    p = sub.add_parser("serve", help="start the browser app")
    p.add_argument(
        "--scene",
        default="double_bridge",
        help="library scene name, scene .yaml, or a terrain file (capture, mesh, .scad)",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default: loopback only)")
    p.add_argument("--port", type=int, default=8080)
    engine_flag(p)
    _runs(p, "cli:cmd_serve")


def _add_planning_parsers(sub) -> None:
    """trial, plan and benchmark: planning (and driving) on a scene."""
    p = sub.add_parser("trial", help="one headless plan-and-drive trial")
    p.add_argument("--scene", default=None, help=f"{TERRAIN_HELP} (default: double_bridge)")
    p.add_argument("--scale", type=float, default=None, metavar="S", help=SCALE_HELP)
    p.add_argument("--seed", type=int, default=None, help="trial seed (default: the scene's)")
    p.add_argument("--planner", choices=PLANNER_NAMES, default=None)
    p.add_argument(
        "--time-limit",
        type=float,
        default=None,
        metavar="S",
        help="planning budget [s]: the plan, every route it tries included (default: the "
        "scene's planner time_limit); the drive then has its own 60 s of simulated time",
    )
    p.add_argument(
        "--from",
        dest="from_dir",
        default=None,
        metavar="DIR",
        help="re-run a trial of the experiment in DIR exactly (with --trial K)",
    )
    p.add_argument("--trial", type=int, default=None, metavar="K", help="trial number in DIR")
    p.add_argument("--reference", action="store_true", help=REFERENCE_HELP)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    engine_flag(p)
    _runs(p, "_plan_cli:cmd_trial")

    p = sub.add_parser("plan", help="plan paths with OMPL over a scene's terrain (no driving)")
    p.add_argument("--scene", default="double_bridge", help=TERRAIN_HELP)
    p.add_argument("--scale", type=float, default=None, metavar="S", help=SCALE_HELP)
    p.add_argument("--planner", choices=PLANNER_NAMES, default=None, help="default: the scene's")
    p.add_argument("--seed", type=int, default=None, help="first seed (default: the scene's)")
    p.add_argument("--count", type=int, default=1, help="number of distinct paths, by route")
    p.add_argument("--start", default=None, help="x,y,yaw_deg (default: the scene's)")
    p.add_argument("--goal", default=None, help="x,y,yaw_deg (default: the scene's)")
    p.add_argument(
        "--time-limit",
        type=float,
        default=None,
        metavar="S",
        help="planning budget of the whole command [s]: every seed and try of --count "
        "shares it, and planning stops when it is spent (default: the scene's planner "
        "time_limit)",
    )
    p.add_argument(
        "--try-limit",
        type=float,
        default=None,
        metavar="S",
        help="at most this long for each seed's plan [s], within --time-limit (default: "
        "what is left of --time-limit)",
    )
    for flag, what in (
        ("simplify", "shortcut the path"),
        ("smooth", "B-spline smooth the path"),
        ("optimize", "let optimizing planners refine to their budget"),
    ):
        p.add_argument(f"--{flag}", action=argparse.BooleanOptionalAction, default=None, help=what)
    p.add_argument("--reference", action="store_true", help=REFERENCE_HELP)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _runs(p, "_plan_cli:cmd_plan")

    p = sub.add_parser(
        "benchmark", help="compare planners on a scene: an OMPL benchmark log (Planner Arena)"
    )
    p.add_argument("--scene", default="double_bridge", help=TERRAIN_HELP)
    p.add_argument(
        "--planners",
        required=True,
        metavar="P,Q,...",
        help=f"comma-separated, from {', '.join(PLANNER_NAMES)}",
    )
    p.add_argument("--runs", type=int, required=True, help="plans per planner (run k: seed + k)")
    p.add_argument(
        "--time-limit",
        type=float,
        default=None,
        metavar="S",
        help="planning budget of each run [s]: a run is one plan, as OMPL's Benchmark gives "
        "each run its time (default: the scene's planner time_limit)",
    )
    p.add_argument("--seed", type=int, default=None, help="first seed (default: the scene's)")
    p.add_argument(
        "--simulate",
        action="store_true",
        help="drive every plan in PyBullet: success, energy, drive time, failure mode",
    )
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="the OMPL benchmark log (.log), in an existing folder; an existing file is "
        "replaced only if roachplan wrote it (else --force), never an input",
    )
    p.add_argument(
        "--db",
        default=None,
        help="also the SQLite database Planner Arena opens (.db, .sqlite, .sqlite3)",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    engine_flag(p)
    _runs(p, "_plan_cli:cmd_benchmark")


def _add_calibrate_parser(sub) -> None:
    p = sub.add_parser(
        "calibrate-turning", help="sweep motor-speed ratios on flat ground (appendix A, fig. 3.4)"
    )
    p.add_argument(
        "--out",
        required=True,
        help="folder for turning.csv/.png/_model.json and spin.csv/.png, created if "
        "new; an existing one must be empty or hold only an earlier "
        "calibration",
    )
    p.add_argument(
        "--ratios",
        default=None,
        help="right/left speed ratios (default: every 0.1 from 1 to 3 and 1.25, 1.75)",
    )
    p.add_argument(
        "--duration",
        type=float,
        default=10.0,
        help="simulated seconds per ratio and per steady spin",
    )
    engine_flag(p)
    _runs(p, "_experiment_cli:cmd_calibrate_turning")


def _scad_flags(q) -> None:
    """The OpenSCAD render's time limit and backend, as every command that renders takes."""
    q.add_argument(
        "--scad-timeout",
        type=float,
        default=None,
        metavar="SECONDS",
        help="time limit of each OpenSCAD render (default: the scene's, else 600)",
    )
    q.add_argument(
        "--scad-backend",
        choices=("auto", "cgal", "manifold"),
        default=None,
        help="who renders each OpenSCAD model: auto (manifold unless the model "
        "uses something it renders differently, such as surface(), then "
        "the binary; a note says which and why), cgal (the openscad "
        "binary) or manifold (openscad-evaluator, faster on CSG-heavy "
        "models; refuses surface()) (default: the scene's, else auto)",
    )


def _add_scene_parsers(sub) -> None:
    """scene list, check and build."""
    p = sub.add_parser("scene", help="the scene library")
    scene_sub = p.add_subparsers(dest="scene_command", required=True)
    q = scene_sub.add_parser("list", help="list library scenes")
    _runs(q, "_scene_cli:cmd_scene_list")
    q = scene_sub.add_parser(
        "check", help="validate scene files: load, render, and check start and goal"
    )
    q.add_argument("files", nargs="+", metavar="FILE", help="scene .yaml files or library names")
    _scad_flags(q)
    _runs(q, "_scene_cli:cmd_scene_check")
    q = scene_sub.add_parser("build", help="export a scene's assembled terrain mesh")
    q.add_argument("scene", metavar="NAME", help="library scene name or scene .yaml")
    q.add_argument(
        "-o",
        "--output",
        required=True,
        help="mesh file: .stl, .obj, .ply or .glb, in an existing folder; an existing "
        "file is replaced only if roachplan wrote it (else --force), never an "
        "input",
    )
    q.add_argument(
        "--scale",
        type=float,
        default=None,
        metavar="S",
        help="scale every terrain model by S before placing it (0.001: millimetres)",
    )
    _scad_flags(q)
    q.add_argument("--force", action="store_true", help=FORCE_HELP)
    _runs(q, "_scene_cli:cmd_scene_build")


def _add_robot_parsers(sub) -> None:
    """twin, robot, compare and fit: a real robot (or its stand-in) in the loop."""
    p = sub.add_parser(
        "twin",
        help="a simulated roach that speaks as a real one: pose over NatNet or UDP/JSON, "
        "motor commands over UDP or a serial line",
    )
    p.add_argument("--scene", default="double_bridge", help=TERRAIN_HELP)
    p.add_argument(
        "--start", default=None, help="x,y,yaw_deg where it stands (default: the scene's)"
    )
    hidden = (
        ("friction", "ground friction [-] (default: the scene's)"),
        ("motor-gain", "both motors run at this x their command [-] (default 1)"),
        ("motor-mismatch", "left x (1 + d), right x (1 - d) [-] (default 0)"),
        ("mass-scale", "the body's mass x this [-] (default 1)"),
    )
    for flag, what in hidden:
        p.add_argument(
            f"--{flag}",
            dest=f"twin_{flag.replace('-', '_')}",
            metavar=flag.upper().replace("-", "_"),
            type=float,
            default=None if flag == "friction" else (0.0 if flag == "motor-mismatch" else 1.0),
            help=f"hidden parameter: {what}",
        )
    p.add_argument(
        "--pose", choices=("natnet", "udp-json"), default="natnet", help="how the pose is served"
    )
    p.add_argument(
        "--natnet-port",
        dest="twin_natnet_port",
        metavar="NATNET_PORT",
        type=int,
        default=0,
        help="NatNet command port to serve on (Motive's is 1510; default 0: a free one, announced)",
    )
    p.add_argument(
        "--rigid-body",
        dest="twin_rigid_body",
        metavar="RIGID_BODY",
        type=int,
        default=1,
        help="its streaming id",
    )
    p.add_argument(
        "--pose-target", default=None, metavar="HOST:PORT", help="udp-json: where to send the poses"
    )
    p.add_argument(
        "--pose-rate",
        dest="twin_pose_rate",
        metavar="POSE_RATE",
        type=float,
        default=120.0,
        help="[Hz]",
    )
    p.add_argument(
        "--latency",
        dest="twin_latency",
        metavar="LATENCY",
        type=float,
        default=0.0,
        help="pose latency [s]",
    )
    p.add_argument(
        "--noise",
        dest="twin_noise",
        metavar="NOISE",
        type=float,
        default=0.0,
        help="position noise, sigma [m]",
    )
    p.add_argument(
        "--noise-angle",
        dest="twin_noise_angle",
        metavar="NOISE_ANGLE",
        type=float,
        default=0.0,
        help="orientation noise, sigma about each axis [rad]",
    )
    p.add_argument(
        "--drop",
        dest="twin_drop",
        metavar="DROP",
        type=float,
        default=0.0,
        help="share of poses lost",
    )
    p.add_argument("--seed", type=int, default=None, help="seed of the noise and drops (default 0)")
    p.add_argument(
        "--mocap",
        default=None,
        metavar="X,Y,Z,YAW_DEG",
        help="T_world_mocap: the poses are given in this capture frame (default: the world's)",
    )
    p.add_argument("--command", choices=("udp", "serial"), default="udp", help="how commands come")
    p.add_argument(
        "--command-port",
        dest="twin_command_port",
        metavar="COMMAND_PORT",
        type=int,
        default=0,
        help="udp: the port commands come to (default 0: a free one, announced)",
    )
    p.add_argument(
        "--serial", default="pty", help="serial: pty (a pseudo-terminal, announced) or a device"
    )
    p.add_argument(
        "--command-timeout",
        dest="twin_command_timeout",
        metavar="COMMAND_TIMEOUT",
        type=float,
        default=0.25,
        help="it stops by itself with no valid command for this long [s]",
    )
    p.add_argument(
        "--host",
        dest="twin_host",
        metavar="HOST",
        default="127.0.0.1",
        help="the address its sockets bind to (default: loopback only)",
    )
    _runs(p, "_robot_cli:cmd_twin")
    _add_robot_parser(sub)
    _add_log_parsers(sub)


def _add_robot_parser(sub) -> None:
    p = sub.add_parser(
        "robot",
        help="drive a real robot (or a twin) headless: plan from where it stands, wait for Go, "
        "drive, record the run",
    )
    p.add_argument("--scene", default="double_bridge", help=TERRAIN_HELP)
    p.add_argument("--source", choices=("natnet", "udp-json"), default="natnet", help="pose source")
    p.add_argument("--natnet-server", default="127.0.0.1", metavar="HOST", help="Motive's address")
    p.add_argument(
        "--natnet-local",
        default="127.0.0.1",
        metavar="HOST",
        help="this computer's address on Motive's network",
    )
    p.add_argument(
        "--natnet-port",
        dest="robot_natnet_port",
        metavar="NATNET_PORT",
        type=int,
        default=1510,
        help="Motive's command port (default 1510)",
    )
    p.add_argument(
        "--rigid-body", default="1", metavar="ID|NAME", help="the robot's rigid body in Motive"
    )
    p.add_argument("--up-axis", choices=("z", "y"), default="z", help="Motive's streaming up axis")
    p.add_argument(
        "--pose-host",
        default="127.0.0.1",
        metavar="HOST",
        help="udp-json: the address to receive on",
    )
    p.add_argument(
        "--pose-port",
        dest="robot_pose_port",
        metavar="POSE_PORT",
        type=int,
        default=None,
        help="udp-json: the port to receive on (default 9871)",
    )
    p.add_argument("--link", choices=("udp", "serial"), default="udp", help="command link")
    p.add_argument(
        "--robot",
        dest="robot_address",
        default=None,
        metavar="HOST:PORT",
        help="udp: the robot's (or its bridge's) address (default 127.0.0.1:9870)",
    )
    p.add_argument(
        "--serial", dest="serial_device", default=None, metavar="DEVICE", help="serial: the device"
    )
    p.add_argument(
        "--baudrate",
        dest="robot_baudrate",
        metavar="BAUDRATE",
        type=int,
        default=115200,
        help="serial: [bit/s]",
    )
    p.add_argument(
        "--transform",
        default=None,
        metavar="X,Y,Z,YAW_DEG",
        help="T_world_mocap (default: measured from the first pose, the robot placed at the "
        "scene's start)",
    )
    p.add_argument("--seed", type=int, default=None, help="the plan's seed (default: the scene's)")
    p.add_argument(
        "--rate",
        dest="robot_rate",
        metavar="RATE",
        type=float,
        default=50.0,
        help="control rate [Hz]",
    )
    for flag, what in (
        ("max-pose-age", "a pose older than this stops the robot [s] (default 0.2)"),
        ("max-deviation", "this far off the path stops it [m] (default 0.15)"),
        ("area-margin", "this far outside the planning area stops it [m] (default 0.05)"),
        ("standable-margin", "this far from where it can stand stops it [m] (default 0.05)"),
        ("stop-hold", "zero commands go on this long after a stop [s] (default 0.5)"),
    ):
        p.add_argument(
            f"--{flag}",
            dest=f"robot_{flag.replace('-', '_')}",
            metavar=flag.upper().replace("-", "_"),
            type=float,
            default=None,
            help=what,
        )
    p.add_argument(
        "--first-pose-timeout",
        dest="robot_first_pose_timeout",
        metavar="FIRST_POSE_TIMEOUT",
        type=float,
        default=5.0,
        help="how long to wait for the robot's first pose [s]",
    )
    p.add_argument(
        "--go",
        action="store_true",
        help="drive as soon as the plan is made (default: ask, and wait for Enter)",
    )
    p.add_argument(
        "--no-predict",
        action="store_true",
        help="do not simulate the plan from the robot's start for the log",
    )
    p.add_argument(
        "--look-ahead",
        action="store_true",
        help="while it drives, about once a second simulate short rollouts of the rest of the "
        "plan from its live pose, in their own process: the chance it goes on without a stop "
        "or a fall, recorded in the log (/lookahead)",
    )
    p.add_argument(
        "--look-ahead-draws", type=int, default=None, metavar="N", help="rollouts each (default 8)"
    )
    p.add_argument(
        "--look-ahead-horizon",
        type=float,
        default=None,
        metavar="S",
        help="simulated seconds each rollout walks (default 3)",
    )
    p.add_argument(
        "--guard",
        type=float,
        default=None,
        metavar="P",
        help="with --look-ahead: hold the robot when a look-ahead's chance of going on without "
        "a stop or a fall is below P (or it drifts, or makes no progress: --guard-drift, "
        "--guard-stuck), re-plan from where it stands, and go on at Enter (--go: at once)",
    )
    p.add_argument(
        "--no-trim",
        action="store_true",
        help="with --look-ahead: send the driver's commands as they are (by default the motors' "
        "mismatch the look-ahead estimates from the robot's walk is divided out of them)",
    )
    p.add_argument(
        "--edge-keep",
        default=None,
        metavar="M",
        help="plans from where the robot stands keep M m from the drop-offs: the robot may "
        "drift that far sideways anywhere and still stand; a robot standing nearer one turns "
        "and walks in first (default 0.04; 'none': the planner's first valid plan, from where "
        "it stands)",
    )
    p.add_argument(
        "--guard-drift",
        default=None,
        metavar="F",
        help="with --guard: also hold the robot and re-plan once it is F times --max-deviation "
        "off its path (past that, as --guard-drift-lead says), before the loop stops it there, "
        "or 2 cm off it with 1 cm left before an edge (default 0.5; 'none': not held for "
        "drifting, nor at an edge)",
    )
    p.add_argument(
        "--guard-drift-lead",
        default=None,
        metavar="S",
        help="with --guard: a robot past --guard-drift is held only once its drift, going on S "
        "seconds at its present rate, would come within 1 cm of --max-deviation (default 0.4; "
        "'none': held at --guard-drift)",
    )
    p.add_argument(
        "--guard-stuck",
        default=None,
        metavar="F",
        help="with --guard: also hold the robot and re-plan it with lines and turns on the spot "
        "once it has made no progress along its path for F times the scene's stuck time, before "
        "the loop stops it as stuck (from 0.1 to below 1; default 0.8: 8 s of 10 s; 'none': "
        "the stuck stop ends the run)",
    )
    p.add_argument(
        "--replans",
        type=int,
        default=6,
        metavar="N",
        help="re-plans after the guard held the robot, at most (default 6: after a second "
        "drift hold or a stall hold each re-plan is lines and turns on the spot, and on a "
        "slippery slope such legs reached the goal about 2 times in 5)",
    )
    p.add_argument(
        "--look-ahead-noise",
        type=float,
        default=None,
        metavar="M",
        help="the pose's position error each rollout starts with, standard deviation [m] "
        "(default 0.01)",
    )
    p.add_argument(
        "--look-ahead-latency",
        type=float,
        default=None,
        metavar="S",
        help="how late a pose arrives [s] (the motion capture's latency: Motive shows it); each "
        "rollout starts at a moment drawn from 0 to twice this before the pose arrived, the "
        "legs at the commands' phase then (default 0)",
    )
    p.add_argument(
        "--look-ahead-period",
        type=float,
        default=None,
        metavar="S",
        help="how often a look-ahead starts [s] (default 1)",
    )
    p.add_argument(
        "--look-ahead-engine",
        default=None,
        metavar="ENGINE",
        help="the engine its rollouts run in: pybullet or mujoco (default: the scene's; "
        "mujoco steps them in lockstep, several times as fast)",
    )
    p.add_argument(
        "-o",
        "--output",
        default=None,
        help="the run's log (.mcap, in an existing folder; default SCENE-robot-TIME.mcap "
        "here); an existing file is replaced only if it is a run log roachplan wrote (else "
        "--force)",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument("--json", action="store_true", help="print one JSON object")
    _runs(p, "_robot_cli:cmd_robot")


def _add_log_parsers(sub) -> None:
    """compare and fit: what is made of robot run logs."""

    def log_flags(q) -> None:
        q.add_argument(
            "--scene",
            default=None,
            help="the scene to re-simulate on (default: the scene file the log names, as it "
            "was then)",
        )
        q.add_argument(
            "--latency",
            type=float,
            default=None,
            help="the pose stream's latency [s]: a pose received at t shows the robot at "
            "t - latency (default 0)",
        )
        q.add_argument("--json", action="store_true", help="print one JSON object")

    p = sub.add_parser(
        "compare",
        help="how well the simulation predicted robot runs: open loop, closed loop, windows, "
        "and the look-ahead's chances against what happened",
    )
    p.add_argument(
        "logs",
        nargs="+",
        metavar="LOG.mcap",
        help="run logs (`roachplan robot -o`); with several, the look-ahead is scored over all",
    )
    p.add_argument(
        "--look-ahead-only",
        action="store_true",
        help="only score the logs' look-aheads (no simulation of the runs)",
    )
    p.add_argument(
        "--robot-file",
        default=None,
        metavar="FILE.yaml",
        help="simulate with these parameters (`roachplan fit -o`; default: the scene's)",
    )
    log_flags(p)
    _runs(p, "_robot_cli:cmd_compare")

    p = sub.add_parser(
        "fit", help="fit the simulation's friction and motors to robot runs: a robot file"
    )
    p.add_argument("logs", nargs="+", metavar="LOG.mcap", help="run logs of one robot on one floor")
    p.add_argument(
        "-o",
        "--output",
        required=True,
        help="the robot file (.yaml) a scene names (`robot: {file: ...}`), in an existing "
        "folder; an existing file is replaced only if roachplan wrote it (else --force)",
    )
    p.add_argument("--force", action="store_true", help=FORCE_HELP)
    p.add_argument(
        "--parameters",
        default=None,
        metavar="P,Q,...",
        help="what to fit: friction, motor_gain, motor_mismatch, mass_scale (default: the "
        "first three)",
    )
    p.add_argument(
        "--evaluations",
        type=int,
        default=None,
        help="at most this many re-simulations of the logs (default 80)",
    )
    p.add_argument(
        "--rounds", type=int, default=None, help="passes over the parameters (default 2)"
    )
    p.add_argument(
        "--starts",
        type=int,
        default=None,
        help="friction: points searched across its range before refining (default 5)",
    )
    p.add_argument(
        "--horizon", type=float, default=None, help="the windows' length [s] (default 1)"
    )
    log_flags(p)
    _runs(p, "_robot_cli:cmd_fit")
