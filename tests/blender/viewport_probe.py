"""Runs inside an interactive Blender on a virtual display (``xvfb-run blender --python
viewport_probe.py -- OUT_DIR MODE``), driven by timers since the viewport renders while
Blender's event loop runs. Not a test file: :mod:`test_viewport_draw` starts it.

MODE "viewport": the Cornell box through the scene camera in a maximised 3D view with
Rendered shading; once the viewport session's image is done, the screen is captured with
``xwd`` and ``OUT_DIR/probe.json`` says where the 3D view's region is and where its
image (``view.npy``, linear RGBA, row 0 at the bottom) is.
MODE "panels": the Relativity panels (scene, camera with its motion from the animation,
object), each captured with the Properties editor's rectangle, for the README.
"""

import json
import os
import subprocess
import sys
import time

import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else []
OUT, MODE = argv[0], argv[1]
HERE = os.path.dirname(os.path.abspath(__file__))
sys.path[:0] = [p for p in ("/opt/relray-py313", HERE) if os.path.isdir(p)]
STATE = {"t0": time.monotonic()}
PACKAGE = "bl_ext.user_default.relray"


def fail(message: str) -> None:
    with open(os.path.join(OUT, "probe.json"), "w") as f:
        json.dump({"error": message}, f)
    bpy.ops.wm.quit_blender()


def capture(name: str) -> str:
    bpy.ops.wm.redraw_timer(type="DRAW_WIN_SWAP", iterations=3)
    path = os.path.join(OUT, name)
    subprocess.run(["xwd", "-root", "-silent", "-out", path], check=True)
    return path


def rect(obj) -> list[int]:
    return [int(obj.x), int(obj.y), int(obj.width), int(obj.height)]


def view_area():
    return next(a for a in bpy.context.window.screen.areas if a.type == "VIEW_3D")


def setup_viewport():
    import scenes

    bpy.ops.preferences.addon_enable(module=PACKAGE)
    scene = scenes.build_cornell(width=160, height=160)
    scene.relray.preview_samples = 4
    area = view_area()
    with bpy.context.temp_override(area=area, region=area.regions[-1]):
        bpy.ops.screen.screen_full_area()
    area = view_area()
    space = area.spaces[0]
    space.overlay.show_overlays = False
    space.show_gizmo = False
    space.region_3d.view_perspective = "CAMERA"
    space.shading.type = "RENDERED"
    bpy.app.timers.register(wait_viewport, first_interval=1.0)


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
        if time.monotonic() - STATE["t0"] > 400:
            fail("the viewport image was not done within 400 s")
            return None
        view_area().tag_redraw()
        return 0.5
    import numpy as np

    np.save(os.path.join(OUT, "view.npy"), done[-1].rgba)
    area = view_area()
    region = next(r for r in area.regions if r.type == "WINDOW")
    shot = capture("screen.xwd")
    with open(os.path.join(OUT, "probe.json"), "w") as f:
        json.dump({"screen": shot, "region": rect(region),
                   "window": [bpy.context.window.width, bpy.context.window.height],
                   "samples": done[-1].samples}, f)
    bpy.ops.wm.quit_blender()
    return None


def setup_panels():
    import scenes

    bpy.ops.preferences.addon_enable(module=PACKAGE)
    scene = scenes.build_cornell(width=160, height=160)
    scene.relray.speed_of_light = 10.0
    cam = scene.camera
    cam.data.relray.motion_source = "ANIMATION"
    props = next(a for a in bpy.context.window.screen.areas if a.type == "PROPERTIES")
    STATE["shots"] = [("scene", "SCENE", None), ("camera", "DATA", cam),
                      ("object", "OBJECT", next(o for o in scene.objects if o.type == "MESH"))]
    STATE["props"] = props
    bpy.app.timers.register(next_panel, first_interval=1.0)


def next_panel():
    if not STATE["shots"]:
        bpy.ops.wm.quit_blender()
        return None
    name, context, obj = STATE["shots"].pop(0)
    if obj is not None:
        bpy.context.view_layer.objects.active = obj
    props = next(a for a in bpy.context.window.screen.areas if a.type == "PROPERTIES")
    props.spaces[0].context = context
    bpy.app.timers.register(lambda: shoot_panel(name), first_interval=1.0)
    return None


def shoot_panel(name: str):
    props = next(a for a in bpy.context.window.screen.areas if a.type == "PROPERTIES")
    shot = capture(f"{name}.xwd")
    with open(os.path.join(OUT, f"{name}.json"), "w") as f:
        json.dump({"screen": shot, "area": rect(props),
                   "window": [bpy.context.window.width, bpy.context.window.height]}, f)
    bpy.app.timers.register(next_panel, first_interval=0.2)
    return None


def start():
    try:
        (setup_viewport if MODE == "viewport" else setup_panels)()
    except Exception as e:  # noqa: BLE001 - reported to the test
        import traceback

        fail(f"{e}\n{traceback.format_exc()}")
    return None


bpy.app.timers.register(start, first_interval=1.0)
