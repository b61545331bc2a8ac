"""Runs inside an interactive Blender on a virtual display (``xvfb-run blender --python
viewport_probe.py -- OUT_DIR MODE``), driven by timers since the viewport renders while
Blender's event loop runs. Not a test file: :mod:`test_viewport_draw` starts it.

The scene comes from the .blend the test saved (the add-on enabled with ``--addons``).
MODE "viewport": the Cornell box through the scene camera in a maximised 3D view with
Rendered shading; once the viewport session's image is done, the screen is captured with
``xwd`` and ``OUT_DIR/probe.json`` says where the 3D view's region is and where its
image (``view.npy``, linear RGBA, row 0 at the bottom) is.
MODE "animation": the same Rendered viewport, then Ctrl-F12 (``render.render`` invoked
as the shortcut does: a render job beside the running viewport) writes the scene's
frames; once Blender reports the job complete, the viewport must still finish an image.
``OUT_DIR/probe.json`` records the handler calls and the viewport's last image.
MODE "panels": the Relativity panels (scene, camera with its motion from the animation,
object), each captured with the Properties editor's rectangle, for the README.
"""

import json
import os
import subprocess
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
OUT, MODE = argv[0], argv[1]
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [p for p in ("/opt/relray-py313", HERE) if os.path.isdir(p)]
STATE: dict = {}
PACKAGE = "bl_ext.user_default.relray"


def fail(message: str) -> None:
    with open(os.path.join(OUT, "probe.json"), "w") as f:
        json.dump({"error": message}, f)
    bpy.ops.wm.quit_blender()


def capture(name: str) -> str:
    with bpy.context.temp_override(window=window()):
        bpy.ops.wm.redraw_timer(type="DRAW_WIN_SWAP", iterations=3)
    path = os.path.join(OUT, name)
    subprocess.run(["xwd", "-root", "-silent", "-out", path], check=True)
    return path


def rect(obj) -> list[int]:
    return [int(obj.x), int(obj.y), int(obj.width), int(obj.height)]


def window():
    return bpy.context.window_manager.windows[0]


def areas():
    return window().screen.areas


def view_area():
    return next(a for a in areas() if a.type == "VIEW_3D")


def guarded(fn):
    """A timer callback that reports an exception to the test instead of leaving an
    interactive Blender running."""
    def run(*args):
        try:
            return fn(*args)
        except Exception as e:  # noqa: BLE001 - reported to the test
            import traceback

            fail(f"{e}\n{traceback.format_exc()}")
            return None
    return run


#: The probe's budget, from Blender's start: the Rendered viewport waits for the add-on's
#: warm-up child, which compiles every kernel when the cache is cold (a new build of the
#: add-on has a cache of its own): 739 s measured on the slower 2-core AVX2 machine
#: (2026-11-27); 420 s timed out there under load (2026-11-28), and 840 s once the warm-up
#: also compiled the moving bodies' SIMD lanes (2026-11-28 08:48, on an idle machine).
WATCHDOG_S = 1800.0


@guarded
def watchdog():
    fail(f"the probe did not finish within {WATCHDOG_S:.0f} s")


def setup_viewport():
    """The scene (built and saved by the test) through its camera in the 3D view."""
    area = view_area()
    space = area.spaces[0]
    space.overlay.show_overlays = False
    space.show_gizmo = False
    space.show_region_toolbar = False
    space.show_region_ui = False
    space.region_3d.view_perspective = "CAMERA"
    space.shading.type = "RENDERED"
    bpy.app.timers.register(wait_viewport, first_interval=1.0)


@guarded
def wait_viewport():
    engine = sys.modules[PACKAGE + ".relblend.engine"] \
        if PACKAGE + ".relblend.engine" in sys.modules else None
    images = [] if engine is None else [s.latest() for s in list(engine._SESSIONS)]
    done = [i for i in images if i is not None and i.done]
    errors = [str(s.error) for s in list(engine._SESSIONS or [])] if engine else []
    if any(e != "None" for e in errors):
        fail(f"viewport error: {errors}")
        return None
    if not done:
        view_area().tag_redraw()
        return 0.5
    if "then" in STATE:  # MODE "animation": Ctrl-F12 next
        bpy.app.timers.register(STATE.pop("then"), first_interval=0.1)
        return None
    import numpy as np

    np.save(os.path.join(OUT, "view.npy"), done[-1].rgba)
    area = view_area()
    region = next(r for r in area.regions if r.type == "WINDOW")
    shot = capture("screen.xwd")
    with open(os.path.join(OUT, "probe.json"), "w") as f:
        json.dump({"screen": shot, "region": rect(region),
                   "window": [window().width, window().height],
                   "samples": done[-1].samples}, f)
    bpy.ops.wm.quit_blender()
    return None


def setup_panels():
    """The Properties editor, maximised, on the scene's, the camera's and an object's
    tab."""
    props = next(a for a in areas() if a.type == "PROPERTIES")
    with bpy.context.temp_override(window=window(), area=props,
                                   region=next(r for r in props.regions
                                               if r.type == "WINDOW")):
        bpy.ops.screen.screen_full_area()
    scene = bpy.context.scene
    STATE["shots"] = [("scene", "SCENE", None), ("camera", "DATA", scene.camera),
                      ("object", "OBJECT", next(o for o in scene.objects if o.type == "MESH"))]
    bpy.app.timers.register(next_panel, first_interval=1.0)


@guarded
def next_panel():
    if not STATE["shots"]:
        with open(os.path.join(OUT, "probe.json"), "w") as f:
            json.dump({"panels": "done"}, f)
        bpy.ops.wm.quit_blender()
        return None
    name, context, obj = STATE["shots"][0]
    if obj is not None:
        window().view_layer.objects.active = obj
        obj.select_set(True)
    bpy.app.timers.register(show_tab, first_interval=0.5)
    return None


@guarded
def show_tab():
    """The Properties editor's tab, once it lists the active object's tabs."""
    name, context, _ = STATE["shots"].pop(0)
    props = next(a for a in areas() if a.type == "PROPERTIES")
    props.spaces[0].context = context
    props.tag_redraw()
    bpy.app.timers.register(lambda: shoot_panel(name), first_interval=1.0)
    return None


@guarded
def shoot_panel(name: str):
    props = next(a for a in areas() if a.type == "PROPERTIES")
    shot = capture(f"{name}.xwd")
    with open(os.path.join(OUT, f"{name}.json"), "w") as f:
        json.dump({"screen": shot, "area": rect(props),
                   "window": [window().width, window().height]}, f)
    bpy.app.timers.register(next_panel, first_interval=0.2)
    return None


def setup_animation():
    """The viewport first; once it shows an image, Ctrl-F12."""
    STATE["then"] = start_animation
    STATE["events"] = []
    setup_viewport()


def _on(event: str):
    def handler(*_args):
        STATE["events"].append(event)
    return handler


@guarded
def start_animation():
    bpy.app.handlers.render_complete.append(_on("complete"))
    bpy.app.handlers.render_cancel.append(_on("cancel"))
    bpy.app.handlers.render_post.append(_on("frame"))
    with bpy.context.temp_override(window=window()):
        bpy.ops.render.render("INVOKE_DEFAULT", animation=True)
    bpy.app.timers.register(wait_animation, first_interval=0.5)
    return None


@guarded
def wait_animation():
    """After the render job: a changed setting must restart the viewport, which must
    finish a new image (it is not stuck behind the render job)."""
    events = STATE["events"]
    if "complete" not in events and "cancel" not in events:
        return 0.5
    engine = sys.modules[PACKAGE + ".relblend.engine"]
    STATE["before"] = {id(s.latest()) for s in list(engine._SESSIONS)}
    scene = bpy.context.scene
    scene.relray.preview_samples += 1
    STATE["want"] = scene.relray.preview_samples
    view_area().tag_redraw()
    bpy.app.timers.register(wait_view_after, first_interval=0.5)
    return None


@guarded
def wait_view_after():
    engine = sys.modules[PACKAGE + ".relblend.engine"]
    sessions = list(engine._SESSIONS)
    errors = [str(s.error) for s in sessions if s.error is not None]
    if errors:
        fail(f"viewport error after the animation: {errors}")
        return None
    new = [i for i in (s.latest() for s in sessions)
           if i is not None and i.done and id(i) not in STATE["before"]
           and i.samples == STATE["want"]]
    if not new:
        view_area().tag_redraw()
        return 0.5
    with open(os.path.join(OUT, "probe.json"), "w") as f:
        json.dump({"events": STATE["events"], "sessions": len(sessions),
                   "samples": new[-1].samples}, f)
    bpy.ops.wm.quit_blender()
    return None


@guarded
def start():
    {"viewport": setup_viewport, "panels": setup_panels,
     "animation": setup_animation}[MODE]()


bpy.app.timers.register(start, first_interval=1.0)
bpy.app.timers.register(watchdog, first_interval=WATCHDOG_S)
