"""relblend: the Blender add-on of relray (a thin layer, one job per file).

==================  ===================================================================
module              owns
==================  ===================================================================
``properties``      the data: camera Relativity settings, scene render settings, passes,
                    the add-on's preferences (the farm's scheduler)
``ui``              panels, and Blender's panels reused through COMPAT_ENGINES
``operators``       velocity keyframe, motion presets, export for farm, render on farm
``engine``          the "Relativistic" RenderEngine (bl_idname "RELRAY"): hands off to
                    the core
``export``          depsgraph → core Scene (pure numpy out of bpy)
``motion``          β and shutter events per frame (snapshot / worldline)
``farm``            scene.glb + job TOML for ``relray render``
``farm_run``        ``relray render`` in a child process: JSON progress, cancel (no bpy)
``presets``         the TOML motion profiles of presets/motion
``warmup``          the render kernels compiled in a child process when enabled
``animation``       motion from the animation: sampled worldlines and shutter events
``packaging``       building the extension zips (a tool for make; not loaded by Blender)
==================  ===================================================================

Blender installs the extension as ``bl_ext.<repository>.relray``; everything here uses
relative imports, and the core (``from ..core import ...``) is imported lazily, when a
frame is rendered or exported, so registering is quick and never needs the wheels.
"""

from __future__ import annotations

_modules = None


def _load():
    from . import engine, operators, properties, ui

    return (properties, operators, ui, engine)


def register() -> None:
    """Register properties, operators, panels and the engine (in that order), then start
    compiling the render kernels in the background (:mod:`.warmup`)."""
    global _modules
    _modules = _load()
    for module in _modules:
        module.register()
    from . import properties, warmup

    if properties.compile_at_startup():
        warmup.start()


def unregister() -> None:
    """Unregister everything register() registered, in reverse order."""
    global _modules
    from . import warmup

    warmup.unregister()
    for module in reversed(_modules or _load()):
        module.unregister()
    _modules = None
