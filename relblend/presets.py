"""Motion presets: the TOML motion profiles in ``presets/motion/``, applied to a camera.

A profile is a ``[motion]`` table (job-format.md), read and validated by
``core.job.load_motion``. Applying it to a camera's Relativity settings:

=========================  ==================================================================
profile                    camera
=========================  ==================================================================
``mode``                   Mode (snapshot / worldline)
``beta``                   β (world axes, vector input), when there are no keyframes
``keyframes``              β keyframes at those frames, linear interpolation (the job
                           format's β is linear in frame between keys)
``proper_acceleration``    β keyframed at every frame from the exact hyperbolic motion
                           (worldline mode integrates them piecewise linearly: close to,
                           not exactly, the constant acceleration)
``ct``, ``ct_per_frame``   ct' and ct' per frame (snapshot: ct' keyframed linearly over the
                           frame range when ct_per_frame > 0)
``frames``                 the scene's frame range
=========================  ==================================================================

Earlier β and ct' animation of the camera is replaced.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.physics import relativity
from ..core.scene.description import MotionSettings
from ..core.scene.job import load_motion

#: Where the profiles live (inside the extension: the repository's presets/motion).
MOTION_DIR = Path(__file__).resolve().parent.parent / "presets" / "motion"


def motion_presets() -> list[Path]:
    """The motion profile files, sorted by name."""
    return sorted(MOTION_DIR.glob("*.toml")) if MOTION_DIR.is_dir() else []


def preset_label(path: Path) -> str:
    """A menu label from a file name: ``flyby_ramp.toml`` -> "Flyby Ramp"."""
    return path.stem.replace("_", " ").title()


def _fcurve_collections(id_data) -> list:
    """The F-curve collections of an ID's active action (legacy, or slotted in 4.4+)."""
    ad = id_data.animation_data
    if ad is None or ad.action is None:
        return []
    action = ad.action
    slot = getattr(ad, "action_slot", None)
    layers = getattr(action, "layers", None)
    if slot is not None and layers is not None and len(layers):
        bags = [strip.channelbag(slot) for layer in layers for strip in layer.strips]
        return [bag.fcurves for bag in bags if bag is not None]
    fcurves = getattr(action, "fcurves", None)
    return [fcurves] if fcurves is not None else []


def fcurves_of(id_data) -> list:
    """The F-curves of an ID's active action."""
    return [fc for coll in _fcurve_collections(id_data) for fc in coll]


def set_linear(id_data, data_path: str) -> None:
    """Linear interpolation for every key of ``data_path``'s F-curves."""
    for fc in fcurves_of(id_data):
        if fc.data_path == data_path:
            for kp in fc.keyframe_points:
                kp.interpolation = "LINEAR"


def clear_motion_keys(cam_data) -> None:
    """Remove the animation of a camera's Relativity settings (β, speed, ct', ...)."""
    for coll in _fcurve_collections(cam_data):
        for fc in [fc for fc in coll if fc.data_path.startswith("relray.")]:
            coll.remove(fc)


def keyframe_betas(motion: MotionSettings) -> list[tuple[int, np.ndarray]]:
    """(frame, β) keys that reproduce the profile's velocity (see the module table)."""
    f0, f1 = motion.frames
    if motion.keyframes:
        return [(int(f), np.asarray(b, np.float64)) for f, b in motion.keyframes]
    if motion.proper_acceleration is not None:
        events = relativity.worldline_events(
            np.zeros(3), (f0, f1), motion.ct, motion.ct_per_frame,
            beta_const=motion.beta, proper_acceleration=motion.proper_acceleration)
        return [(f0 + i, ev.beta) for i, ev in enumerate(events)]
    return []


def apply_motion(scene, cam_data, motion: MotionSettings) -> None:
    """Set a camera's Relativity settings (and keyframes) from a motion profile."""
    s = cam_data.relray
    clear_motion_keys(cam_data)
    s.mode = motion.mode.upper()
    s.velocity_input = "VECTOR"
    s.axes = "WORLD"
    s.ct = motion.ct
    s.ct_per_frame = motion.ct_per_frame
    f0, f1 = motion.frames
    scene.frame_start, scene.frame_end = f0, f1
    keys = keyframe_betas(motion)
    if keys:
        for f, beta in keys:
            s.beta = tuple(float(x) for x in beta)
            cam_data.keyframe_insert("relray.beta", frame=f)
        set_linear(cam_data, "relray.beta")
    else:
        s.beta = tuple(float(x) for x in motion.beta)
    if motion.mode == "snapshot" and motion.ct_per_frame > 0.0 and f1 > f0:
        s.ct = motion.ct
        cam_data.keyframe_insert("relray.ct", frame=f0)
        s.ct = motion.ct + (f1 - f0) * motion.ct_per_frame
        cam_data.keyframe_insert("relray.ct", frame=f1)
        set_linear(cam_data, "relray.ct")
        s.ct = motion.ct
    if scene.frame_current < f0 or scene.frame_current > f1:
        scene.frame_current = f0


def load_preset(scene, cam_data, path: str | Path) -> MotionSettings:
    """Read, validate and apply a motion profile file; returns the profile."""
    motion = load_motion(path)
    apply_motion(scene, cam_data, motion)
    return motion
