"""render.spectral = "auto" (core/scene/spectral_model.py): rgb exactly when no wavelength
is shifted, and the rgb render it picks is the explicit rgb render, bit for bit."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from render_helpers import base_job, make_job, render
from test_gltf import moving_doc

from relray.core.scene.geometry import build_scene
from relray.core.scene.spectral_model import resolve, resolved_job

GREY = {"name": "grey", "base_color": [0.6, 0.5, 0.4], "roughness": 1.0}
LAMP = {"name": "lamp", "emission": [1.0, 0.9, 0.8], "emission_strength": 2.0}
BALL = {"shape": "sphere", "center": [0.0, 4.0, 0.0], "radius": 1.0, "material": "grey"}
PANEL = {"shape": "quad", "material": "lamp",
         "corners": [[-2, 6, -2], [2, 6, -2], [2, 6, 2], [-2, 6, 2]]}


def model(tmp_path, **sections) -> tuple[str, str]:
    data = base_job(**{"materials": [GREY, LAMP], "objects": [BALL, PANEL], **sections})
    data["render"] = {**data["render"], "spectral": "auto", **sections.get("render", {})}
    return resolve(make_job(data, tmp_path))


@pytest.mark.parametrize(("sections", "want"), [
    ({}, "rgb"),
    ({"motion": {"beta": [0.0, 0.3, 0.0]}}, "cie1931"),
    ({"motion": {"beta": [0.0, 0.3, 0.0]}, "render": {"doppler": False}}, "rgb"),
    ({"objects": [dict(BALL, velocity=[0.2, 0.0, 0.0]), PANEL]}, "cie1931"),
    ({"output": {"formats": ["exr", "spectral-exr"]}}, "cie1931"),
    ({"motion": {"mode": "snapshot", "frames": [1, 3], "ct_per_frame": 1.0,
                 "keyframes": [{"frame": 1, "beta": [0.0, 0.0, 0.0]},
                               {"frame": 3, "beta": [0.0, 0.0, 0.0]}]}}, "rgb"),
    ({"motion": {"mode": "snapshot", "frames": [1, 3], "ct_per_frame": 1.0,
                 "keyframes": [{"frame": 1, "beta": [0.0, 0.0, 0.0]},
                               {"frame": 3, "beta": [0.0, 0.2, 0.0]}]}}, "cie1931"),
])
def test_auto_is_rgb_exactly_when_nothing_shifts_wavelengths(tmp_path, sections, want):
    got, why = model(tmp_path, **sections)
    assert got == want, why
    assert why


def test_a_given_model_is_kept(tmp_path):
    data = base_job(materials=[GREY], objects=[BALL],
                    render={"spectral": "seed-gaussian"})
    job = make_job(data, tmp_path)
    assert resolve(job) == ("seed-gaussian", "as given")
    assert resolved_job(job) is job


@pytest.mark.parametrize(("relray", "want"), [
    (None, "rgb"),
    ({"velocity": [0.0, 0.0, 0.0]}, "rgb"),
    ({"velocity": [0.0, 0.0, -0.3]}, "cie1931"),
    ({"worldline": {"t": [0.0, 10.0], "pivot": [[0, 0, 0], [0, 0, -5.0]]}}, "cie1931"),
])
def test_auto_sees_the_moving_nodes_of_a_gltf_scene(tmp_path, relray, want):
    """A glTF mesh node moving by its extras.relray makes "auto" spectral, a node at rest
    does not; read from the file's JSON, it agrees with the velocity groups of the scene
    built from it."""
    path = tmp_path / "s.gltf"
    path.write_text(json.dumps(moving_doc(relray)))
    job = make_job(base_job(scene={"file": str(path)}, render={"spectral": "auto"}),
                   tmp_path)
    got, why = resolve(job)
    assert got == want, why
    assert bool(build_scene(job).groups) == (want == "cie1931")


def test_auto_at_rest_renders_the_rgb_image(tmp_path):
    """Same seed, same rays: "auto" at rest is the rgb render, pixel for pixel, and not
    the cie1931 one."""
    sections = {"materials": [GREY, LAMP], "objects": [BALL, PANEL],
                "camera": {"fov": 40.0}}
    auto = render(base_job(render={"spectral": "auto", "max_depth": 3}, **sections), tmp_path)
    rgb = render(base_job(render={"spectral": "rgb", "max_depth": 3}, **sections), tmp_path)
    cie = render(base_job(render={"spectral": "cie1931", "max_depth": 3}, **sections),
                 tmp_path)
    assert rgb.rgb.max() > 0.05
    assert np.array_equal(auto.rgb, rgb.rgb)
    assert not np.array_equal(auto.rgb, cie.rgb)


JOB = """
[render]
width = 8
height = 8
spp = 2
spectral = "auto"
[output]
dir = "out"
[motion]
beta = [0.0, {beta}, 0.0]
[[materials]]
name = "grey"
[[objects]]
shape = "sphere"
center = [0.0, 4.0, 0.0]
radius = 1.0
material = "grey"
"""


@pytest.mark.parametrize(("beta", "want"), [(0.0, "rgb"), (0.5, "cie1931")])
def test_cli_info_and_metadata_name_the_model_used(tmp_path, beta, want):
    import OpenImageIO as oiio
    job = tmp_path / "job.toml"
    job.write_text(JOB.format(beta=beta))
    info = subprocess.run([sys.executable, "-m", "relray.core.cli", "info", str(job)],
                          capture_output=True, text=True, cwd=tmp_path)
    assert info.returncode == 0, info.stderr
    assert f"auto renders with {want}" in info.stdout
    r = subprocess.run([sys.executable, "-m", "relray.core.cli", "render", str(job)],
                       capture_output=True, text=True, cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    exr = next((tmp_path / "out").glob("*.exr"))
    spec = oiio.ImageInput.open(str(exr)).spec()
    assert spec.getattribute("relray:spectral") == want


def test_cli_info_resolves_auto_from_a_moving_gltf_node(tmp_path):
    """relray info decides "auto" from the job and the glTF's node extras."""
    (tmp_path / "s.gltf").write_text(json.dumps(moving_doc({"velocity": [0.3, 0.0, 0.0]})))
    job = tmp_path / "job.toml"
    job.write_text(JOB.format(beta=0.0) + '[scene]\nfile = "s.gltf"\n')
    info = subprocess.run([sys.executable, "-m", "relray.core.cli", "info", str(job)],
                          capture_output=True, text=True, cwd=tmp_path)
    assert info.returncode == 0, info.stderr
    assert "auto renders with cie1931 (moving bodies shift wavelengths)" in info.stdout
