"""The page's Robot folder: a real robot (or a twin) in the loop.

Its settings - where the pose comes from (NatNet from Motive, or a UDP/JSON stream), where the
motor commands go (UDP, or a serial line), the mocap-to-world transform (measured with the
robot placed at the start marker, or typed) - and three buttons, each a command on the app's
loop (its callbacks only put them):

- **Route from robot**: connect, take the robot's pose, plan from where it stands to the goal
  marker (drawn black: Drive can simulate it too) and simulate the plan from there (the
  prediction, blue); the robot is then held (stop frames) until Go. Pressed again after a run
  (or before Go), it re-plans from where the robot is now.
- **Go**: drive the robot along the plan (robot/_loop.py RobotLoop, in a thread of its own);
  the page follows it like a drive: the robot drawn at its live pose, where it went in green,
  its deviation from the path over time, and the run recorded (MCAP) beside the app's uploads.
- **Stop**: at once, even while Go runs (as Cancel at the top does): zero commands, repeated.
"""

from __future__ import annotations

import math
import queue
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ._commands import RobotGoCmd, RobotPlanCmd, RobotStopCmd
from ._robot_route import carried_from, held_text, leg_recorder, predict_from, route_from

if TYPE_CHECKING:
    from roachplan.robot import FrameTransform, RobotLoop, RunRecorder

    from ._app import App

SOURCES = ("natnet", "udp-json")
SINKS = ("udp", "serial")
MEASURE = "measure at start"
"""The transform box's value that measures T_world_mocap from the first pose."""
DEVIATION_POINTS = 2000
"""The live track and the deviation plot are drawn with at most about this many points."""


@dataclass(frozen=True, kw_only=True)
class RobotForm:
    """The Robot folder's settings, read and checked (RobotPanel.form)."""

    source: str
    source_settings: dict[str, Any]
    link: str
    link_settings: dict[str, Any]
    transform: FrameTransform | None
    """None: measured from the first pose, the robot placed at the start marker."""
    look_ahead: bool = False
    """Look ahead of the robot while it drives (robot.watch_ahead)."""
    guard: float | None = None
    """Hold the robot when a look-ahead's chance falls under this [0, 1] (None: never)."""
    max_pose_age: float = 0.2
    """The loop stops the robot when its newest pose is older than this [s]
    (SafetyConfig.max_pose_age)."""
    latency: float = 0.0
    """How late a pose arrives [s] (LookAheadConfig.latency: the look-ahead starts its
    rollouts that long before)."""


class RobotPanel:
    """The Robot folder's controls."""

    def __init__(self, gui, put) -> None:
        from roachplan.robot import SafetyConfig

        with gui.add_folder("Robot"):
            self.source = gui.add_dropdown(
                "Pose source",
                SOURCES,
                initial_value="natnet",
                hint="natnet: OptiTrack Motive (unicast); udp-json: one JSON datagram per pose",
            )
            self.source_address = gui.add_text(
                "Source address",
                "127.0.0.1:1510",
                hint="natnet: Motive's address and command port; udp-json: HOST:PORT to receive on",
            )
            self.rigid_body = gui.add_text(
                "Rigid body", "1", hint="natnet: the robot's streaming id or its name in Motive"
            )
            self.sink = gui.add_dropdown(
                "Command sink", SINKS, initial_value="udp", hint="Where the motor commands go"
            )
            self.sink_address = gui.add_text(
                "Sink address",
                "127.0.0.1:9870",
                hint="udp: the robot's HOST:PORT; serial: the device, e.g. /dev/ttyUSB0",
            )
            self.transform = gui.add_text(
                "Frame transform",
                MEASURE,
                hint=f"T_world_mocap as x,y,z,yaw_deg, or '{MEASURE}' (the robot placed at "
                f"the start marker)",
            )
            self.look_ahead = gui.add_checkbox(
                "Look ahead",
                False,
                hint="While it drives, about once a second simulate short rollouts of the rest "
                "of the plan from its live pose: the chance it goes on 3 s without a stop or a "
                "fall, drawn on the path ahead (green to red)",
            )
            self.guard = gui.add_number(
                "Guard",
                0.0,
                min=0.0,
                max=1.0,
                step=0.05,
                hint="With Look ahead: hold the robot when the chance falls under this, or it "
                "drifts off its path, or makes no progress for 8 s (0: never); Route from robot "
                "then re-plans from where it stands",
            )
            self.max_pose_age = gui.add_number(
                "Max pose age [ms]",
                round(SafetyConfig().max_pose_age * 1000),
                min=1,
                max=10_000,
                step=10,
                hint="Stop the robot when the newest pose is older than this: the tracker lost "
                "it or the stream stopped (raise it for a slow or bursty stream)",
            )
            self.latency = gui.add_number(
                "Pose latency [ms]",
                0,
                min=0,
                max=5000,
                step=5,
                hint="How late a pose arrives (the motion capture's latency: Motive shows it): "
                "the look-ahead starts its rollouts from the pose at the moment it was the "
                "robot's, the legs at the commands' phase then",
            )
            self.plan_button = gui.add_button(
                "Route from robot", hint="Plan from where the robot stands; it is held until Go"
            )
            self.go_button = gui.add_button("Go", color="green", disabled=True)
            self.stop_button = gui.add_button(
                "Stop", color="red", hint="Stop the robot now: zero commands, repeated"
            )
            self.report = gui.add_markdown("No robot connected.")
            self.deviation = gui.add_uplot(
                (np.zeros(1), np.zeros(1)),
                (
                    {"label": "t [s]"},
                    {"label": "deviation [cm]", "stroke": "rgb(0, 170, 90)", "width": 2},
                ),
                title="Deviation from the path",
                aspect=1.6,
                visible=False,
            )
        self.plan_button.on_click(lambda ev: put(RobotPlanCmd(ev.client_id)))
        self.go_button.on_click(lambda ev: put(RobotGoCmd(ev.client_id)))
        self.stop_button.on_click(lambda ev: put(RobotStopCmd(ev.client_id)))

    def form(self) -> RobotForm:
        """The settings as typed, checked by the robot's validators; RobotError naming the box
        and what it accepts."""
        from roachplan import SettingError, setting_problem
        from roachplan.robot import (
            FrameTransform,
            LookAheadConfig,
            NatNetSettings,
            RobotError,
            RobotSettings,
            SafetyConfig,
            parse_address,
        )

        def address(box, name: str) -> tuple[str, int]:
            try:
                return parse_address(box.value)
            except ValueError as exc:
                raise RobotError(f"{name} {box.value!r}: {exc}") from None

        source, link = self.source.value, self.sink.value
        if source == "natnet":
            host, port = address(self.source_address, "Source address")
            text = self.rigid_body.value.strip()
            rigid: int | str = int(text) if text.isdigit() else text
            try:
                NatNetSettings(server=host, command_port=port, rigid_body=rigid)
            except SettingError as exc:
                raise RobotError(f"Rigid body {text!r}: {exc.expected}") from None
            source_settings: dict[str, Any] = {
                "server": host,
                "command_port": port,
                "rigid_body": rigid,
            }
        else:
            host, port = address(self.source_address, "Source address")
            source_settings = {"host": host, "port": port}
        if link == "udp":
            host, port = address(self.sink_address, "Sink address")
            link_settings: dict[str, Any] = {"host": host, "port": port}
        else:
            device = self.sink_address.value.strip()
            if not device:
                raise RobotError("Sink address: give the serial device, e.g. /dev/ttyUSB0")
            link_settings = {"port": device}
        transform = None
        text = self.transform.value.strip()
        if text and text != MEASURE:
            try:
                x, y, z, yaw = (float(v) for v in text.split(","))
                transform = FrameTransform.from_xyz_yaw(x, y, z, math.radians(yaw))
            except (ValueError, RobotError):
                raise RobotError(
                    f"Frame transform {text!r}: expected x,y,z,yaw_deg (4 finite numbers) or "
                    f"'{MEASURE}'"
                ) from None
        guard = float(self.guard.value) if self.look_ahead.value else 0.0
        why = setting_problem(RobotSettings, "guard", guard)
        if why is not None:
            raise RobotError(f"Guard {self.guard.value!r}: {why}")
        max_pose_age = float(self.max_pose_age.value) / 1000
        why = setting_problem(SafetyConfig, "max_pose_age", max_pose_age)
        if why is not None:
            raise RobotError(
                f"Max pose age [ms] {self.max_pose_age.value!r} ({max_pose_age:g} s): {why}"
            )
        latency = float(self.latency.value) / 1000
        why = setting_problem(LookAheadConfig, "latency", latency)
        if why is not None:
            raise RobotError(f"Pose latency [ms] {self.latency.value!r} ({latency:g} s): {why}")
        return RobotForm(
            source=source,
            source_settings=source_settings,
            link=link,
            link_settings=link_settings,
            transform=transform,
            look_ahead=bool(self.look_ahead.value),
            guard=guard if guard > 0 else None,
            max_pose_age=max_pose_age,
            latency=latency,
        )

    def show_transform(self, transform: FrameTransform) -> None:
        """The transform in use, in the box (x,y,z,yaw_deg)."""
        from roachplan.robot import yaw_of

        x, y, z = transform.translation
        self.transform.value = f"{x:.4f},{y:.4f},{z:.4f},{math.degrees(yaw_of(transform.quat)):.2f}"

    def plot(self, t: np.ndarray, deviation_m: np.ndarray) -> None:
        self.deviation.data = (np.asarray(t, dtype=float), 100.0 * np.asarray(deviation_m))
        self.deviation.visible = True


@dataclass(frozen=True)
class LookAheadShown:
    """A look-ahead's result for the page (the runner's thread puts it on the session's
    queue; the command loop draws it)."""

    t: float
    """When it looked ahead [s, monotonic]."""
    ahead: Any
    """The LookAhead."""


@dataclass(eq=False)
class RobotSession:
    """A connected robot, its plan and its loop (App.robot)."""

    source: Any
    link: Any
    transform: FrameTransform
    path: np.ndarray
    spins: tuple
    loop: RobotLoop
    recorder: RunRecorder | None
    log: Path
    events: queue.Queue = field(default_factory=queue.Queue)
    """What the loop tells (its listener puts every event here), and the look-ahead's results
    (LookAheadShown)."""
    went: bool = False
    watcher: Any = None
    """The look-ahead beside the loop (robot.watch_ahead; started at Go), or None."""
    source_key: tuple = ()
    """(the pose source, its settings): the robot this session drove."""
    drifts: int = 0
    """The guard's drift holds in a row before this leg (a Route from robot after one widens
    its arcs: robot.replan_radius)."""
    stalled: bool = False
    """The guard held a leg before this one, of those it held in a row, for making no
    progress (a Route from robot after it plans lines and turns on the spot:
    robot.replan_radius)."""
    result: Any = None
    """How the loop ended (a RunResult), once Go's drive has."""
    estimates: tuple = ()
    """The motors' mismatch estimated so far, this leg's and those before it (RobotRun's):
    a Route from robot of the same robot goes on from them."""
    plan: Any = None
    """The PlanResult this leg drives (its seed and arcs: a rejoin after a drift hold keeps
    them)."""
    lookaheads: list = field(default_factory=list)
    """The look-aheads made while it drove, in order (the watcher's own list: it outlives
    the watcher)."""

    def close(self) -> None:
        """Stop the robot (if it moves), end the loop and the look-ahead, close the log, the
        link and the source."""
        self.loop.close()
        if self.watcher is not None:
            self.watcher.close()
            self.watcher = None
        if self.recorder is not None:
            self.recorder.close()
            self.recorder = None
        for closable in (self.link, self.source):
            try:
                closable.close()
            except OSError:
                pass


class _Followed:
    """A RobotLoop as the command loop follows a job: its events, Cancel as a stop."""

    def __init__(self, session: RobotSession) -> None:
        self.session = session
        self.started = time.monotonic()

    def poll(self, timeout: float = 0.0) -> list:
        out, deadline = [], time.monotonic() + timeout
        while True:
            try:
                out.append(self.session.events.get(timeout=max(deadline - time.monotonic(), 0)))
            except queue.Empty:
                return out
            if time.monotonic() >= deadline:
                while not self.session.events.empty():
                    out.append(self.session.events.get_nowait())
                return out

    def cancel(self) -> None:
        self.session.loop.stop("cancel", "Cancel pressed in the page")

    @property
    def elapsed(self) -> float:
        return time.monotonic() - self.started


def _close_session(app: App) -> None:
    if app.robot is not None:
        app.robot.close()
        app.robot = None


def do_robot_plan(app: App, cmd: RobotPlanCmd) -> None:
    """Connect, locate the robot, plan from where it stands, predict, and hold it until Go."""
    from roachplan.robot import (
        LoopConfig,
        RobotLoop,
        SafetyConfig,
        SafetyMap,
        measure_transform,
        open_link,
        open_pose_source,
        start_height,
        wait_first_pose,
        yaw_of,
    )

    panel = app.page.robot_panel
    form = panel.form()
    before = app.robot  # (the last leg: a re-plan of the same robot goes on from it)
    _close_session(app)  # (a robot still held or driven stops first)
    key = (form.source, tuple(sorted(form.source_settings.items())))
    carried = carried_from(before, key)
    app.page.view.remove("/lookahead")  # (the last run's look-ahead)
    start, goal = app.page.markers.valid_poses(app.world)
    app.page.set_status("Robot: connecting to the pose source ...")
    source = open_pose_source(form.source, **form.source_settings)
    try:
        link = open_link(form.link, **form.link_settings)
    except Exception:
        source.close()
        raise
    watcher = None
    try:
        sample = wait_first_pose(source, 5.0)
        transform = form.transform or measure_transform(
            sample.position, sample.quat, start, start_height(app.world, start)
        )
        panel.show_transform(transform)
        p, q = transform.apply(sample.position, sample.quat)
        stands = (p[0], p[1], yaw_of(q))
        route = route_from(app, stands, goal, carried)
        plan, here = route.plan, route.here
        prediction = predict_from(app, plan, here, goal)
        path = np.asarray(plan.path_xyz, dtype=float)
        log, recorder = leg_recorder(
            app,
            form,
            transform=transform,
            plan=plan,
            here=here,
            stands=stands,
            goal=goal,
            prediction=prediction,
            route=route,
        )
        events: queue.Queue = queue.Queue()
        loop = RobotLoop(
            path_xyz=path,
            spins=tuple(plan.spins),
            source=source,
            link=link,
            transform=transform,
            safety_map=SafetyMap.from_world(app.world),
            driver=app.world.scene.driver,
            max_motor_speed=app.world.robot.max_motor_speed,
            cfg=LoopConfig(safety=SafetyConfig(max_pose_age=form.max_pose_age)),
            recorder=recorder,
            listeners=[events.put],
        )
        # The control loop's thread shares this process's GIL with viser and the command loop:
        # a thread waiting for it waits up to the switch interval (5 ms by default, a quarter
        # of a control period); 1 ms keeps its periods on time while the page is drawn.
        sys.setswitchinterval(min(sys.getswitchinterval(), 0.001))
        if form.look_ahead:
            from roachplan.robot import LookAheadConfig, RobotSettings, watch_ahead

            defaults = RobotSettings()  # (the command line's, where the page has no box)

            watcher = watch_ahead(
                app.world,
                path,
                tuple(plan.spins),
                loop,
                cfg=LookAheadConfig(latency=form.latency),
                guard=form.guard,
                drift=defaults.guard_drift,
                lead=defaults.guard_drift_lead,
                stuck=defaults.guard_stuck,
                trim=defaults.trim,
                estimates=carried.estimates,
                period=defaults.look_ahead_period,
                seed=plan.seed,
                safety=loop.cfg.safety,
                recorder=recorder,
                also=lambda t, ahead: events.put(LookAheadShown(t, ahead)),
            )
        loop.start()  # (held: stop frames until Go)
    except BaseException:
        if watcher is not None:
            watcher.close()
        link.close()
        source.close()
        raise
    app.robot = RobotSession(
        source=source,
        link=link,
        transform=transform,
        path=path,
        spins=tuple(plan.spins),
        loop=loop,
        recorder=recorder,
        log=log,
        events=events,
        watcher=watcher,
        source_key=key,
        drifts=carried.drifts,
        stalled=carried.stalled,
        estimates=carried.estimates,
        plan=plan,
        lookaheads=watcher.results if watcher is not None else [],
    )
    panel.go_button.disabled = False
    text = held_text(stands, route, len(path), prediction)
    panel.report.content = text
    app.page.set_status(text)


class _Live:
    """What Go shows as the robot drives: its pose (legs at the phase of the commands sent),
    where it went (green), its deviation from the path over time, the progress."""

    def __init__(self, app: App, session: RobotSession) -> None:
        self.app, self.session = app, session
        self.robot = app.world.robot
        self.path_xy = session.path[:, :2]
        self.track: list[tuple[float, float, float]] = []
        self.t: list[float] = []
        self.deviation: list[float] = []
        self.phase = np.zeros(2)
        self.last_command = None
        self.result = None
        self.t0 = time.monotonic()
        self.shown = self.drawn = 0.0
        self.ahead = None
        """The newest look-ahead (a LookAhead), or None."""

    def step(self, events: list) -> bool:
        """Take the loop's events in; redraw at most 15 (the robot) and 2 (the rest) times a
        second (each redraw holds the GIL the control loop's thread needs on time); True once
        the loop has finished."""
        from roachplan.robot import CommandEvent, FinishedEvent, PoseEvent, distance_to_path

        from ._draw import wxyz_from_xyzw

        latest = None
        for ev in events:
            if isinstance(ev, PoseEvent):
                latest = ev
                self.track.append(ev.position)
                self.t.append(ev.sample.t_receive - self.t0)
                self.deviation.append(distance_to_path(ev.position, self.path_xy))
            elif isinstance(ev, CommandEvent):
                if self.last_command is not None:
                    f, dt = self.last_command.frame, ev.t - self.last_command.t
                    self.phase += dt * np.array([f.left, f.right]) * self.robot.motor_gain
                self.last_command = ev
            elif isinstance(ev, FinishedEvent):
                self.result = ev.result
            elif isinstance(ev, LookAheadShown):
                self.ahead = ev.ahead
                self.show_ahead(ev.ahead)
        now = time.monotonic()
        if latest is not None and now - self.shown > 1 / 15:
            self.shown = now
            sides = self.phase[np.asarray(self.robot.leg_sides)]
            legs, _ = self.robot.leg_angle(sides + np.asarray(self.robot.leg_phase_offsets))
            self.app.page.show_robot_pose(latest.position, wxyz_from_xyzw(latest.quat), legs)
        if now - self.drawn > 0.5 and self.track:
            self.drawn = now
            self.draw()
            from ._draw import path_fraction

            done = path_fraction(self.path_xy, self.track[-1])
            ahead = (
                ""
                if self.ahead is None
                else f"; look-ahead: {self.ahead.p_hold:.2f} chance of going on "
                f"{self.ahead.horizon:g} s"
            )
            text = (
                f"Robot: {100 * done:.0f} % of the path, {now - self.t0:.1f} s; deviation "
                f"{100 * self.deviation[-1]:.1f} cm (max {100 * max(self.deviation):.1f} cm)"
                f"{ahead}"
            )
            self.app.page.robot_panel.report.content = text
            self.app.loop.progress(done, text)
        return self.result is not None

    def show_ahead(self, ahead) -> None:
        """The newest look-ahead on the path ahead (its risk colour, its failures: red
        squares), in place of the one before."""
        from ._draw import look_ahead_lines

        view = self.app.page.view
        view.remove("/lookahead")
        for suffix, points, colour in look_ahead_lines(ahead.to_json(), self.session.path):
            view.draw("/lookahead" + (f"/{suffix}" if suffix else "/ahead"), points, colour)

    def draw(self) -> None:
        from ._draw import LIVE

        if self.track:
            every = max(1, len(self.track) // DEVIATION_POINTS)  # (at most ~2000 points each)
            self.app.page.view.draw("/live/track", self.track[::every] + self.track[-1:], LIVE)
            self.app.page.robot_panel.plot(
                np.asarray(self.t[::every]), np.asarray(self.deviation[::every])
            )


def do_robot_go(app: App, cmd: RobotGoCmd) -> None:
    """Drive the robot along the plan; followed until it stops (goal, safety, Stop, Cancel)."""
    session = app.robot
    panel = app.page.robot_panel
    if session is None or session.went or not session.loop.running:
        app.page.notify(
            cmd.client_id, "Nothing to drive", "Press Route from robot first.", error=True
        )
        return
    session.went = True
    panel.go_button.disabled = True
    live = _Live(app, session)
    session.loop.go()
    if session.watcher is not None:  # (looks ahead of a robot that drives)
        session.watcher.start()
    try:
        app.loop.follow(_Followed(session), "Robot", live.step)
    except BaseException as exc:  # (the page failed to follow: the robot stops)
        session.loop.stop("error", f"the page failed to follow the robot: {exc}")
        session.loop.wait(5.0)
        session.close()
        raise
    result = session.loop.wait(5.0)
    session.result = result
    if session.watcher is not None:  # (the estimates a re-plan of this robot goes on from)
        session.estimates = session.watcher.estimates
    live.draw()
    if session.recorder is not None and result is not None:
        session.recorder.write("/result", time.monotonic(), result.to_json())
    session.close()
    if result is None:
        text = "Robot: the loop did not end in time; it was told to stop"
    else:
        late = f"{result.late} of {result.periods} control periods late"
        worst = f", max deviation {100 * max(live.deviation):.1f} cm" if live.deviation else ""
        text = (
            f"Robot stopped: **{result.reason}** ({result.detail}); {late}{worst}. "
            f"Log: {session.log.name}. **Route from robot** re-plans from where it is."
        )
    panel.report.content = text
    app.page.set_status(text)


def do_robot_stop(app: App, cmd: RobotStopCmd) -> None:
    """Stop the robot now (while Go runs too): zero commands, repeated."""
    session = app.robot
    if session is None or not session.loop.running:
        app.page.notify(cmd.client_id, "Nothing to stop", "No robot is held or driven.")
        return
    session.loop.stop("stop", "Stop pressed in the page")
    if not session.went:  # held before Go: the session ends here
        session.loop.wait(2.0)
        _close_session(app)
        app.page.robot_panel.go_button.disabled = True
        app.page.robot_panel.report.content = "Robot stopped before Go."
        app.page.set_status("Robot stopped before Go.")
