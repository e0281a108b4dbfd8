"""Scene loading in the background: a load (meshing a capture, rendering OpenSCAD, picking start
and goal) runs in a child while the current scene stays in use; its world replaces the current
one when it is ready and nothing else is running. One load at a time: a new one replaces it.
The Scene folder shows what is loading and for how long, with Cancel load. `follow_load` runs
on the command loop between commands (and while one runs), the handlers when their command runs.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from roachplan.processes import Running
from roachplan.scenes import World, list_scenes

from ._app import App
from ._commands import CancelLoadCmd, Cmd, LoadSceneCmd
from ._jobs import Job, _load_job, load_outcome, with_page_engine
from ._load_panel import needs_millimetre_scale
from ._placement import model_view
from ._relevel import CaptureView
from ._uploads import public_message


@dataclass(eq=False)
class Loading:
    """A scene load running in the background."""

    job: Job
    client_id: int | None
    """Who asked for it (its notifications)."""
    ref: str
    """Library name or scene file."""
    label: str
    """The scene picker's name of it."""
    from_upload: bool
    """ref is a scene file the app wrote (and may write back into)."""
    what: str
    """What the panel says while it runs ("Loading ...", "Rendering ... with OpenSCAD")."""
    result: tuple[World, CaptureView | None] | None = None
    """(World, CaptureView | None) once it arrived."""
    error: str | None = None
    rendering: tuple[str, float] = ("", 0.0)
    """What the last OpenSCAD render said of itself (Running.what: the model's name, and for
    the binary why it renders and how long it is expected to take), and when [s of the job]."""


class BackgroundLoad:
    """The load lane: its status line and Cancel load button in the Scene folder."""

    def __init__(self, gui, put) -> None:
        self.current: Loading | None = None
        self.status = gui.add_markdown("")
        self.cancel_button = gui.add_button("Cancel load", visible=False, color="red")
        self.cancel_button.on_click(lambda ev: put(CancelLoadCmd(ev.client_id)))

    def start(
        self, cmd: Cmd, ref: str, *, from_upload: bool, label: str, what: str
    ) -> Loading | None:
        """Start loading; returns the load it replaced (stopped), if any."""
        replaced = self.stop()
        self.current = Loading(
            job=Job(_load_job, ref, from_upload),
            client_id=cmd.client_id,
            ref=ref,
            label=label,
            from_upload=from_upload,
            what=what,
        )
        self.cancel_button.visible = True
        self.show()
        return replaced

    def stop(self) -> Loading | None:
        """Kill the running load, if any (returns it)."""
        ld, self.current = self.current, None
        if ld is not None:
            ld.job.cancel()
        self.cancel_button.visible = False
        return ld

    def poll(self) -> Loading | None:
        """The load, once it has a result or an error (it stays current until taken)."""
        ld = self.current
        if ld is None or ld.result is not None or ld.error is not None:
            return ld
        for event in ld.job.poll():  # (an OpenSCAD render's Running; the status counts seconds)
            if isinstance(event, Running):
                ld.rendering = (event.what, ld.job.elapsed)
        if ld.job.done:
            ld.result, ld.error = load_outcome(ld.job)
        if ld.result is None and ld.error is None:
            self.show()
        return ld if (ld.result is not None or ld.error is not None) else None

    def take(self) -> Loading:
        """The finished load, which is no longer current."""
        ld, self.current = self.current, None
        self.cancel_button.visible = False
        assert ld is not None, "no load to take (poll returns it first)"
        return ld

    def show(self, text: str | None = None) -> None:
        ld = self.current
        if text is None:
            text = f"{ld.what} ... {ld.job.elapsed:.0f} s{_rendering(ld)}" if ld is not None else ""
        if self.status.content != text:
            self.status.content = text


def _rendering(ld: Loading) -> str:
    """What the OpenSCAD render running says of itself, when it says more than the model's
    name (the binary: why it renders, how long it is expected to take), else ""."""
    said, when = ld.rendering
    # (none yet, a name, or it ended)
    if not said or said.lower().endswith(".scad") or ld.job.elapsed - when > 2:
        return ""
    return f"; OpenSCAD {said}"


def do_load_scene(app: App, cmd: LoadSceneCmd) -> None:
    """Load the scene the picker names, in the background."""
    if cmd.name != app.picker_label():  # (setting the picker also calls back)
        ref, owned = app.files.get(cmd.name, (cmd.name, False))
        app.start_load(cmd, ref, from_upload=owned, label=cmd.name)


def do_cancel_load(app: App, cmd: CancelLoadCmd) -> None:
    """Stop the load running (its child, and an OpenSCAD it started, killed); the scene stays."""
    ld = app.page.loading.stop()
    if ld is not None:
        app.page.loading.show(
            f"Loading {ld.label} cancelled after {ld.job.elapsed:.1f} s; "
            f"the scene `{app.world.scene.name}` stays."
        )
        app.page.set_scene_picker(app.picker_label())


def follow_load(app: App, *, idle: bool) -> None:
    """Follow the load: a failure is said at once; a loaded world replaces the current one
    only when idle (no command running or queued: those were clicked on the current scene) and
    no batch runs."""
    ld = app.page.loading.poll()
    if ld is None:
        return
    batch = app.page.batch_panel.batch
    if ld.error is not None:
        report_failure(app, app.page.loading.take())
    elif idle and app.loop.running is None and batch is None:
        swap_in(app, app.page.loading.take())
    else:
        after = "the batch of trials" if batch is not None else "the running command"
        app.page.loading.show(f"{ld.label} is ready: it replaces this scene when {after} ends.")


def report_failure(app: App, ld: Loading) -> None:
    """A load failed: the current scene stays; say why (a model in millimetres is offered
    Scale x0.001)."""
    message = public_message(ld.error or "", app.upload_dir)
    uploaded = ld.label.removeprefix("upload: ")
    if ld.label.startswith("upload: ") and Path(uploaded).suffix.lower() not in (".yaml", ".yml"):
        # The scene file around an uploaded model is the app's: the message names the file.
        message = re.sub(r"^[\w.-]+\.ya?ml: terrain\[\d+\](?:\.\w+)?: ", f"{uploaded}: ", message)
    app.page.loading.show("")
    app.page.set_status(f"Could not load {ld.label}; the scene `{app.world.scene.name}` stays.")
    app.page.set_scene_picker(app.picker_label())
    mm = ld.from_upload and needs_millimetre_scale(ld.error or "")  # (as scenes words it)
    app.page.load_panel.offer_scale((Path(ld.ref), ld.label) if mm else None)
    # A model that did not load (under the ground plane, ...) can be placed again from here.
    failed = model_view(ld.ref, loaded=False)
    if failed is not None:
        app.page.load_panel.show_model(failed)
    if mm and "Scale x0.001" not in message:  # (public_message words it so, as a rule)
        message += " Press Scale x0.001 (Scene folder) to load it in metres."
    app.page.notify(ld.client_id, f"Could not load {ld.label}", message, error=True)


def next_seed(app: App, world: World) -> int:
    """The seed the next plan or batch on world's scene starts from: where that scene's seeds
    stopped when it was switched away from (its plans' tries included), and past every seed
    recorded in its trials, so that switching back never repeats a trial; the scene file's own
    seed on a first visit."""
    key = str(world.scene.path)
    recorded = [int(t["seed"]) + 1 for t in app.trials.get(key, ())]
    return max(app.next_seeds.get(key, world.scene.seed), *recorded, world.scene.seed)


def swap_in(app: App, ld: Loading) -> None:
    """The loaded world replaces the current one."""
    assert ld.result is not None
    world, view = ld.result
    world = with_page_engine(world, app.engine)
    app.page.load_panel.offer_scale(None)
    app.next_seeds[str(app.world.scene.path)] = app.next_seed
    app.world = world
    app.host_world()
    labels = None
    if ld.from_upload or ld.label in app.files:
        app.files[ld.label] = (ld.ref, ld.from_upload)
        labels = (*list_scenes(), *app.files)
    app.page.set_scene_picker(app.picker_label(), labels)
    app.page.show_engine(world.scene.sim.engine)
    app.next_seed = next_seed(app, world)
    app.show_world()
    app.page.load_panel.show_loaded(world, view)
    took = ld.job.elapsed
    app.page.loading.show("")
    # Who rendered an OpenSCAD terrain stays in the status; the notification closes itself.
    renders = "".join(  # markdown: a file name's underscores are no emphasis
        "\n\n" + public_message(r, app.upload_dir).replace("_", "\\_") for r in world.renders
    )
    status = (
        f"Loaded `{world.scene.name}` ({len(world.mesh.faces)} triangles) in {took:.1f} s.{renders}"
    )
    failure = app.page.markers.failure
    if failure is not None:  # (the markers are red, on one point: say why and what to do)
        app.page.set_status(f"{status} Start and goal were not picked: see Start and goal.")
        others = public_message(" ".join(world.notes[:-1]), app.upload_dir)
        app.page.notify(
            ld.client_id,
            f"Loaded {ld.label}: start and goal not picked",
            f"{failure} {others}".strip(),
            error=True,
        )
        return
    app.page.set_status(status)
    if world.notes:
        notes = " ".join(n if n.endswith(".") else f"{n}." for n in world.notes)
        app.page.notify(ld.client_id, f"Loaded {ld.label}", public_message(notes, app.upload_dir))
