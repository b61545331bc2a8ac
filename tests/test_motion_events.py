"""``[motion] mode = "events"``: a camera's shutter events baked per frame (the Blender
add-on's animated camera), checked against the modes they must reproduce."""

from __future__ import annotations

import math

import numpy as np
import pytest
from render_helpers import base_job, make_job, render

from relray.core.errors import UserError
from relray.core.physics import relativity
from relray.core.scene.job import with_overrides
from relray.core.scene.motion import frame_events

SCENE = dict(
    materials=[{"name": "red", "base_color": [0.7, 0.1, 0.1], "roughness": 1.0},
               {"name": "lamp", "base_color": [0, 0, 0], "emission": [1, 1, 1],
                "emission_strength": 2.0}],
    objects=[{"shape": "sphere", "center": [0.3, 4.0, 0.0], "radius": 0.6, "material": "red"},
             {"shape": "sphere", "center": [-1.5, 3.0, 1.5], "radius": 0.4,
              "material": "lamp"}],
    render={"max_depth": 2, "spp": 4})


def event_table(frame: int, ev: relativity.ShutterEvent, rotation=None) -> dict:
    out = {"frame": frame, "t": ev.t, "position": ev.x.tolist(), "beta": ev.beta.tolist(),
           "tau": ev.tau}
    if rotation is not None:
        out["rotation"] = np.asarray(rotation).tolist()
    return out


def test_events_reproduce_the_snapshot_frames_exactly(tmp_path):
    """The events of a snapshot animation, baked, give the same events and pixels."""
    snap = base_job(**SCENE, motion={"mode": "snapshot", "beta": [0.3, 0.5, 0.0], "ct": 1.0,
                                     "frames": [1, 3], "ct_per_frame": 0.5})
    events = frame_events(make_job(snap, tmp_path))
    baked = base_job(**SCENE, motion={"mode": "events", "frames": [1, 3],
                                      "events": [event_table(f, e) for f, e in events]})
    for (f, a), (g, b) in zip(events, frame_events(make_job(baked, tmp_path)), strict=True):
        assert f == g and a.t == b.t and a.tau == b.tau and b.rotation is None
        assert np.array_equal(a.x, b.x) and np.array_equal(a.beta, b.beta)
    for f in (1, 3):
        one, two = render(snap, tmp_path, f), render(baked, tmp_path, f)
        assert np.array_equal(one.image.rgba, two.image.rgba)


def test_an_event_rotation_turns_the_camera_as_the_camera_table_does(tmp_path):
    """An event's ``rotation`` replaces the [camera]'s axes for that frame: the same image
    as a job whose camera has that rotation; the other frames keep the [camera]'s."""
    th = math.radians(25.0)
    rot = [[math.cos(th), 0.0, math.sin(th)], [math.sin(th), 0.0, -math.cos(th)],
           [0.0, 1.0, 0.0]]  # right, up (z), backward: looks along +y turned by 25° about z
    turned = base_job(**SCENE, camera={"position": [0, 0, 0], "rotation": rot, "fov": 20.0,
                                       "look_at": None, "up": None})
    turned["camera"] = {k: v for k, v in turned["camera"].items() if v is not None}
    ev = relativity.snapshot_event([0, 0, 0], [0.0, 0.6, 0.0], 0.0)
    baked = base_job(**SCENE, motion={"mode": "events", "frames": [1, 2], "events": [
        event_table(1, ev, rot), event_table(2, ev)]})
    plain = base_job(**SCENE, motion={"mode": "snapshot", "beta": [0.0, 0.6, 0.0],
                                      "frames": [1, 2]})
    a = render(turned | {"motion": plain["motion"]}, tmp_path, 1)
    b = render(baked, tmp_path, 1)
    assert np.array_equal(a.image.rgba, b.image.rgba)
    assert np.array_equal(render(baked, tmp_path, 2).image.rgba,
                          render(plain, tmp_path, 2).image.rgba)
    assert not np.array_equal(a.image.rgba, render(plain, tmp_path, 1).image.rgba)


@pytest.mark.parametrize("motion, key, match", [
    ({"mode": "events", "frames": [1, 2], "events": [
        {"frame": 1, "t": 0, "position": [0, 0, 0], "beta": [0, 0, 0]}]},
     "motion.events", "frame 2 has no event"),
    ({"mode": "events", "frames": [1, 2], "events": [
        {"frame": 2, "t": 0, "position": [0, 0, 0], "beta": [0, 0, 0]},
        {"frame": 1, "t": 0, "position": [0, 0, 0], "beta": [0, 0, 0]}]},
     "motion.events[1].frame", "sorted by frame"),
    ({"mode": "snapshot", "events": [
        {"frame": 1, "t": 0, "position": [0, 0, 0], "beta": [0, 0, 0]}]},
     "motion.events", "needs mode"),
    ({"mode": "events", "frames": [1, 1], "events": [
        {"frame": 1, "t": 0, "position": [0, 0, 0], "beta": [0.8, 0.7, 0]}]},
     "motion.events[0].beta", "speed of light"),
    ({"mode": "events", "frames": [1, 1], "events": [
        {"frame": 1, "t": 0, "position": [0, 0, 0], "beta": [0, 0, 0],
         "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 2]]}]},
     "motion.events[0].rotation", "rotation"),
])
def test_bad_events_are_refused_naming_the_key(tmp_path, motion, key, match):
    with pytest.raises(UserError, match=match) as e:
        make_job(base_job(**SCENE, motion=motion), tmp_path)
    assert e.value.key == key and e.value.file == str(tmp_path / "job.toml")


def test_beta_or_ct_from_the_command_line_are_refused_for_baked_events(tmp_path):
    ev = relativity.snapshot_event([0, 0, 0], [0.0, 0.6, 0.0], 0.0)
    job = make_job(base_job(**SCENE, motion={"mode": "events", "frames": [1, 1],
                                             "events": [event_table(1, ev)]}), tmp_path)
    with pytest.raises(UserError, match="baked") as e:
        with_overrides(job, beta=[0.1, 0.0, 0.0])
    assert e.value.key == "--beta"
