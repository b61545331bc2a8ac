"""The TOML job: defaults, every validation error, overrides, camera forms, presets."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from relray.core.errors import UserError
from relray.core.scene import job, motion

ROOT = Path(__file__).resolve().parents[1]

SCENE = """
[[materials]]
name = "white"

[[objects]]
shape = "sphere"
center = [0.0, 0.0, 1.0]
radius = 0.5
material = "white"
"""


def write_job(tmp_path: Path, text: str, name: str = "job.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def load(tmp_path: Path, text: str) -> job.Job:
    return job.load_job(write_job(tmp_path, text))


# ------------------------------------------------------------------------ defaults


def test_defaults_match_job_format(tmp_path: Path) -> None:
    j = load(tmp_path, SCENE)
    assert j.path == tmp_path.resolve() / "job.toml"
    assert j.render == job.RenderSettings(
        width=256, height=256, spp=64, noise_threshold=0.0, max_depth=8, seed=0,
        spectral="cie1931", doppler=True, searchlight=True, threads=0,
    )
    o = j.output
    assert o.dir == tmp_path.resolve() / "out"
    assert o.name == "frame_{frame:04d}"
    assert o.formats == ("exr", "png")
    assert o.spectral_bands == (380.0, 780.0, 10.0)
    assert o.aovs == ("depth", "doppler", "lab_time")
    assert o.exposure == 0.0
    c = j.camera
    np.testing.assert_array_equal(c.position, [0.0, -3.9, 1.0])
    # looking along +y with z up: right = +x, up = +z, back = -y
    np.testing.assert_allclose(c.rotation, [[1, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-15)
    assert c.fov == 39.6 and c.shift == (0.0, 0.0)
    m = j.motion
    assert m.mode == "snapshot" and m.ct == 0.0 and m.frames == (1, 1)
    assert m.ct_per_frame == 0.0 and m.keyframes == () and m.proper_acceleration is None
    np.testing.assert_array_equal(m.beta, [0, 0, 0])
    s = j.scene
    assert s.file is None and s.background == (0.0, 0.0, 0.0)
    assert s.materials == (job.MaterialSpec(name="white"),)
    obj = s.objects[0]
    assert (obj.name, obj.shape, obj.material) == ("objects[0]", "sphere", "white")
    assert obj.params["radius"] == 0.5 and obj.params["subdivisions"] == 5
    assert motion.frame_list(j) == [1]


def test_arrays_are_read_only(tmp_path: Path) -> None:
    j = load(tmp_path, SCENE)
    with pytest.raises(ValueError):
        j.camera.position[0] = 1.0
    with pytest.raises(ValueError):
        j.motion.beta[0] = 0.5


def test_full_job_round_trip(tmp_path: Path) -> None:
    j = load(tmp_path, """
[render]
width = 320
height = 200
spp = 8
spectral = "seed-gaussian"
searchlight = false
[output]
dir = "/tmp/relray-abs"
formats = ["spectral-exr", "png", "png"]
spectral_bands = [400, 700, 5]
aovs = []
exposure = -1.5
[motion]
mode = "worldline"
beta = [0.0, 0.3, 0.0]
proper_acceleration = [0.0, 0.1, 0.0]
frames = [1, 10]
ct_per_frame = 0.5
[scene]
background = [0.1, 0.2, 0.3]
[[materials]]
name = "glow"
emission_blackbody = 5800.0
emission_strength = 2.0
reflectance_uv = 0.1
reflectance_ir = 0.6
[[materials]]
name = "table"
emission_spectrum = { nm = [400, 500, 600], values = [1, 2, 0.5] }
[[objects]]
shape = "box"
center = [0, 0, 0]
size = [1, 2, 3]
material = "glow"
velocity = [0.0, 0.0, 0.0]
[[lights]]
type = "spot"
position = [0, 0, 3]
direction = [0, 0, -2]
spot_size = 60
power = 500
""")
    assert j.output.dir == Path("/tmp/relray-abs")
    assert j.output.formats == ("spectral-exr", "png")
    assert j.output.aovs == ()
    assert j.scene.materials[0].emission_blackbody == 5800.0
    assert j.scene.materials[1].emission_spectrum == ((400, 500, 600), (1, 2, 0.5))
    light = j.scene.lights[0]
    np.testing.assert_array_equal(light.direction, [0, 0, -1])
    assert light.spot_size == pytest.approx(math.radians(60)) and light.spot_blend == 0.15
    np.testing.assert_array_equal(j.scene.objects[0].params["size"], [1, 2, 3])
    assert motion.frame_list(j) == list(range(1, 11))
    assert "worldline" in job.job_summary(j)


# ------------------------------------------------------------- malformed jobs

BAD_JOBS = [
    # (id, TOML text, expected key, a word the message must contain)
    ("unknown key", "[render]\nwidht = 3\n" + SCENE, "render.widht", "did you mean 'width'"),
    ("unknown table", "[rendr]\nwidth = 3\n" + SCENE, "rendr", "did you mean 'render'"),
    ("section not a table", "render = 5\n" + SCENE, "render", "table"),
    ("string for int", '[render]\nwidth = "256"\n' + SCENE, "render.width", "integer"),
    ("bool for int", "[render]\nwidth = true\n" + SCENE, "render.width", "integer"),
    ("float for int", "[render]\nspp = 1.5\n" + SCENE, "render.spp", "integer"),
    ("width zero", "[render]\nwidth = 0\n" + SCENE, "render.width", ">= 1"),
    ("width huge", "[render]\nwidth = 40000\n" + SCENE, "render.width", "<= 32768"),
    ("too many pixels", "[render]\nwidth = 32768\nheight = 32768\n" + SCENE, "render.height",
     "2^28"),
    ("spp zero", "[render]\nspp = 0\n" + SCENE, "render.spp", ">= 1"),
    ("max_depth zero", "[render]\nmax_depth = 0\n" + SCENE, "render.max_depth", ">= 1"),
    ("nan", "[render]\nnoise_threshold = nan\n" + SCENE, "render.noise_threshold", "finite"),
    ("inf", "[output]\nexposure = inf\n" + SCENE, "output.exposure", "finite"),
    ("exposure nan", "[output]\nexposure = nan\n" + SCENE, "output.exposure", "finite"),
    ("exposure word", '[output]\nexposure = "autox"\n' + SCENE, "output.exposure",
     "did you mean 'auto'"),
    ("exposure case", '[output]\nexposure = "Auto"\n' + SCENE, "output.exposure",
     'nor "auto"'),
    ("exposure bool", "[output]\nexposure = true\n" + SCENE, "output.exposure",
     'a number of stops or "auto", not a boolean'),
    ("exposure array", '[output]\nexposure = ["auto"]\n' + SCENE, "output.exposure",
     "not an array"),
    ("exposure range", "[output]\nexposure = 65\n" + SCENE, "output.exposure", "<= 64"),
    ("negative threshold", "[render]\nnoise_threshold = -1\n" + SCENE, "render.noise_threshold",
     ">= 0"),
    ("clamp negative", "[render]\nclamp = -0.5\n" + SCENE, "render.clamp", ">= 0 (got -0.5)"),
    ("clamp nan", "[render]\nclamp = nan\n" + SCENE, "render.clamp", "finite, not nan"),
    ("clamp inf", "[render]\nclamp = inf\n" + SCENE, "render.clamp", "finite, not inf"),
    ("clamp string", '[render]\nclamp = "off"\n' + SCENE, "render.clamp", "not a string"),
    ("clamp bool", "[render]\nclamp = true\n" + SCENE, "render.clamp", "not a boolean"),
    ("spectral mode", '[render]\nspectral = "cie1964"\n' + SCENE, "render.spectral", "cie1931"),
    ("bool as int", "[render]\ndoppler = 1\n" + SCENE, "render.doppler", "true or false"),
    ("beta above c", "[motion]\nbeta = [0.8, 0.7, 0.0]\n" + SCENE, "motion.beta",
     "speed of light"),
    ("beta equals c", "[motion]\nbeta = [1, 0, 0]\n" + SCENE, "motion.beta", "speed of light"),
    ("beta length", "[motion]\nbeta = [0.5, 0.0]\n" + SCENE, "motion.beta", "3 numbers"),
    ("keyframe above c",
     "[motion]\nkeyframes = [{frame = 1, beta = [0, 0, 0]}, {frame = 5, beta = [0, 0, -1.2]}]\n"
     + SCENE, "motion.keyframes[1].beta", "speed of light"),
    ("keyframes unsorted",
     "[motion]\nkeyframes = [{frame = 5, beta = [0, 0, 0]}, {frame = 1, beta = [0, 0, 0]}]\n"
     + SCENE, "motion.keyframes[1].frame", "sorted"),
    ("keyframes repeated",
     "[motion]\nkeyframes = [{frame = 2, beta = [0, 0, 0]}, {frame = 2, beta = [0, 0, 0]}]\n"
     + SCENE, "motion.keyframes[1].frame", "sorted"),
    ("keyframe missing beta", "[motion]\nkeyframes = [{frame = 2}]\n" + SCENE,
     "motion.keyframes[0].beta", "missing"),
    ("frames reversed", "[motion]\nframes = [5, 1]\n" + SCENE, "motion.frames", "before"),
    ("motion mode", '[motion]\nmode = "worldlines"\n' + SCENE, "motion.mode", "worldline"),
    ("acceleration in snapshot", "[motion]\nproper_acceleration = [0.1, 0, 0]\n" + SCENE,
     "motion.proper_acceleration", "worldline"),
    ("acceleration not parallel",
     '[motion]\nmode = "worldline"\nbeta = [0, 0.5, 0]\nproper_acceleration = [0.1, 0, 0]\n'
     + SCENE, "motion.beta", "parallel"),
    ("acceleration reaches c",
     '[motion]\nmode = "worldline"\nproper_acceleration = [10.0, 0, 0]\nframes = [1, 100]\n'
     "ct_per_frame = 1.0\n" + SCENE, "motion.proper_acceleration", "speed of light"),
    ("negative ct per frame", "[motion]\nct_per_frame = -0.1\n" + SCENE, "motion.ct_per_frame",
     ">= 0"),
    ("format", '[output]\nformats = ["jpg"]\n' + SCENE, "output.formats", "exr"),
    ("no formats", "[output]\nformats = []\n" + SCENE, "output.formats", "at least one"),
    ("aov", '[output]\naovs = ["normals"]\n' + SCENE, "output.aovs", "depth"),
    ("band step", "[output]\nspectral_bands = [380, 780, 0]\n" + SCENE, "output.spectral_bands",
     "step"),
    ("band order", "[output]\nspectral_bands = [700, 400, 10]\n" + SCENE,
     "output.spectral_bands", "below"),
    ("band range", "[output]\nspectral_bands = [100, 780, 10]\n" + SCENE,
     "output.spectral_bands", "100..10000"),
    ("band steps", "[output]\nspectral_bands = [380, 785, 10]\n" + SCENE,
     "output.spectral_bands", "whole"),
    ("spectral exr in rgb", '[render]\nspectral = "rgb"\n[output]\nformats = ["spectral-exr"]\n'
     + SCENE, "output.formats", "spectral mode"),
    ("bad name template", '[output]\nname = "frame_{frme}"\n' + SCENE, "output.name", "template"),
    ("broken name template", '[output]\nname = "frame_{"\n' + SCENE, "output.name", "template"),
    # names that are not one file name per frame: tests/test_frame_files.py (every frame's
    # name is checked before rendering, by plan_frames, not only the first at load time)
    ("look_at at position", "[camera]\nposition = [1, 2, 3]\nlook_at = [1, 2, 3]\n" + SCENE,
     "camera.look_at", "equals position"),
    ("up parallel", "[camera]\nposition = [0, 0, 0]\nlook_at = [0, 0, 5]\nup = [0, 0, 1]\n"
     + SCENE, "camera.up", "parallel"),
    ("two orientations", "[camera]\nlook_at = [0, 0, 0]\nrotation = [[1,0,0],[0,1,0],[0,0,1]]\n"
     + SCENE, "camera.rotation", "exactly one"),
    ("rotation not orthonormal", "[camera]\nrotation = [[1,0,0],[0,2,0],[0,0,1]]\n" + SCENE,
     "camera.rotation", "orthonormal"),
    ("rotation mirrored", "[camera]\nrotation = [[-1,0,0],[0,1,0],[0,0,1]]\n" + SCENE,
     "camera.rotation", "determinant"),
    ("matrix shape", "[camera]\nmatrix = [[1,0,0],[0,1,0],[0,0,1]]\n" + SCENE, "camera.matrix",
     "4 rows"),
    ("matrix with position",
     "[camera]\nposition = [0, 0, 0]\nmatrix = [[1,0,0,0],[0,1,0,0],[0,0,1,0],[0,0,0,1]]\n"
     + SCENE, "camera.position", "matrix"),
    ("fov 180", "[camera]\nfov = 180\n" + SCENE, "camera.fov", "< 180"),
    ("material undefined", SCENE.replace('material = "white"', 'material = "whte"'),
     "objects[0].material", "did you mean 'white'"),
    ("duplicate material", '[[materials]]\nname = "white"\n' + SCENE, "materials[1].name",
     "already defined"),
    ("material without name", "[[materials]]\nroughness = 0.5\n" + SCENE, "materials[0].name",
     "missing"),
    ("base colour out of range", SCENE.replace('name = "white"',
     'name = "white"\nbase_color = [1.2, 0.5, 0.5]'), "materials[0].base_color", "<= 1"),
    ("two emission spectra", SCENE.replace('name = "white"',
     'name = "white"\nemission_blackbody = 3000\nemission_line = [550, 5]'),
     "materials[0].emission_line", "only one"),
    ("spectrum not increasing", SCENE.replace('name = "white"',
     'name = "white"\nemission_spectrum = { nm = [500, 400], values = [1, 1] }'),
     "materials[0].emission_spectrum.nm", "increasing"),
    ("unknown shape", '[[materials]]\nname = "w"\n[[objects]]\nshape = "cone"\nmaterial = "w"\n',
     "objects[0].shape", "sphere"),
    ("missing param", '[[materials]]\nname = "w"\n[[objects]]\nshape = "sphere"\n'
     'center = [0, 0, 0]\nmaterial = "w"\n', "objects[0].radius", "needs center and radius"),
    ("extra param", '[[materials]]\nname = "w"\n[[objects]]\nshape = "box"\ncenter = [0, 0, 0]\n'
     'size = 1\nradius = 2\nmaterial = "w"\n', "objects[0].radius", "not a parameter of a box"),
    ("unknown object key", SCENE.replace("radius = 0.5", "radius = 0.5\nradiuss = 1"),
     "objects[0].radiuss", "did you mean 'radius'"),
    ("radius zero", SCENE.replace("radius = 0.5", "radius = 0.0"), "objects[0].radius", "> 0"),
    ("box size negative", '[[materials]]\nname = "w"\n[[objects]]\nshape = "box"\n'
     'center = [0, 0, 0]\nsize = [1, -1, 1]\nmaterial = "w"\n', "objects[0].size", "> 0"),
    ("degenerate quad", '[[materials]]\nname = "w"\n[[objects]]\nshape = "quad"\n'
     'corners = [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]]\nmaterial = "w"\n',
     "objects[0].corners", "degenerate"),
    ("non-planar quad", '[[materials]]\nname = "w"\n[[objects]]\nshape = "quad"\n'
     'corners = [[0, 0, 0], [1, 0, 0], [1, 1, 1], [0, 1, 0]]\nmaterial = "w"\n',
     "objects[0].corners", "plane"),
    ("quad with 3 corners", '[[materials]]\nname = "w"\n[[objects]]\nshape = "quad"\n'
     'corners = [[0, 0, 0], [1, 0, 0], [1, 1, 0]]\nmaterial = "w"\n', "objects[0].corners",
     "4 rows"),
    ("mesh file missing", '[[materials]]\nname = "w"\n[[objects]]\nshape = "mesh"\n'
     'file = "nothere.obj"\nmaterial = "w"\n', "objects[0].file", "not found"),
    ("mesh file type", '[[materials]]\nname = "w"\n[[objects]]\nshape = "mesh"\n'
     'file = "model.fbx"\nmaterial = "w"\n', "objects[0].file", ".obj"),
    ("velocity and worldline", SCENE.replace(
        "radius = 0.5", "radius = 0.5\nvelocity = [0.1, 0, 0]\n"
        "worldline = { t = [0, 1], pivot = [[0, 0, 1], [0.5, 0, 1]] }"),
     "objects[0].worldline", "not both"),
    ("worldline of one sample", SCENE.replace(
        "radius = 0.5", "radius = 0.5\nworldline = { t = [0], pivot = [[0, 0, 1]] }"),
     "objects[0].worldline.t", "2 to 4096"),
    ("worldline times not increasing", SCENE.replace(
        "radius = 0.5", "radius = 0.5\n"
        "worldline = { t = [0, 2, 2], pivot = [[0, 0, 1], [0.5, 0, 1], [1, 0, 1]] }"),
     "objects[0].worldline.t", "strictly increasing"),
    ("worldline counts differ", SCENE.replace(
        "radius = 0.5", "radius = 0.5\n"
        "worldline = { t = [0, 2, 3], pivot = [[0, 0, 1], [0.5, 0, 1]] }"),
     "objects[0].worldline.pivot", "one per time"),
    ("worldline segment at c", SCENE.replace(
        "radius = 0.5", "radius = 0.5\n"
        "worldline = { t = [0, 2, 3], pivot = [[0, 0, 1], [0.5, 0, 1], [0.5, 1, 1]] }"),
     "objects[0].worldline.pivot", "segment 1 (t = 2 .. 3) moves at 1 c"),
    ("worldline nan", SCENE.replace(
        "radius = 0.5", "radius = 0.5\n"
        "worldline = { t = [0, nan], pivot = [[0, 0, 1], [0.5, 0, 1]] }"),
     "objects[0].worldline.t", "finite, not nan (at [1])"),
    ("worldline unknown key", SCENE.replace(
        "radius = 0.5", "radius = 0.5\n"
        "worldline = { t = [0, 1], pivot = [[0, 0, 1], [0.5, 0, 1]], u = 1 }"),
     "objects[0].worldline.u", "unknown"),
    ("pivot inf", SCENE.replace("radius = 0.5", "radius = 0.5\npivot = [0, inf, 0]"),
     "objects[0].pivot", "finite, not inf (at [1])"),
    ("object velocity above c", SCENE.replace("radius = 0.5", "radius = 0.5\nvelocity = [1, 0, 0]"),
     "objects[0].velocity", "speed of light"),
    ("scene file missing", '[scene]\nfile = "nothere.glb"\n', "scene.file", "not found"),
    ("scene file type", '[scene]\nfile = "scene.blend"\n', "scene.file", ".glb"),
    ("empty scene", "[render]\nspp = 4\n", "scene", "empty"),
    ("only materials", '[[materials]]\nname = "w"\n', "scene", "empty"),
    ("objects not an array", 'objects = "ball"\n' + SCENE.split("[[objects]]")[0], "objects",
     "array of tables"),
    ("light type", '[[lights]]\ntype = "laser"\n' + SCENE, "lights[0].type", "point"),
    ("light key for another type", '[[lights]]\ntype = "point"\nspot_size = 30\n' + SCENE,
     "lights[0].spot_size", "spot"),
    ("light direction zero", '[[lights]]\ntype = "sun"\ndirection = [0, 0, 0]\n' + SCENE,
     "lights[0].direction", "zero"),
    ("light power negative", '[[lights]]\ntype = "point"\npower = -5\n' + SCENE,
     "lights[0].power", ">= 0"),
    ("area up parallel", '[[lights]]\ntype = "area"\ndirection = [0, 0, -2]\nup = [0, 0, 3]\n'
     + SCENE, "lights[0].up", "parallel"),
    ("area up zero", '[[lights]]\ntype = "area"\nup = [0, 0, 0]\n' + SCENE, "lights[0].up",
     "zero"),
    ("up on a spot light", '[[lights]]\ntype = "spot"\nup = [0, 1, 0]\n' + SCENE,
     "lights[0].up", "area"),
    ("include missing", '[scene]\ninclude = "other.toml"\n', "scene.include", "not found"),
    ("include itself", '[scene]\ninclude = "job.toml"\n' + SCENE, "scene.include", "cycle"),
    ("background negative", "[scene]\nbackground = [0, -1, 0]\n" + SCENE, "scene.background",
     ">= 0"),
]


def test_the_table_is_large_and_distinct() -> None:
    assert len(BAD_JOBS) >= 30
    assert len({case[0] for case in BAD_JOBS}) == len(BAD_JOBS)


@pytest.mark.parametrize(("text", "key", "word"), [c[1:] for c in BAD_JOBS],
                         ids=[c[0] for c in BAD_JOBS])
def test_malformed_job(tmp_path: Path, text: str, key: str, word: str) -> None:
    path = write_job(tmp_path, text)
    with pytest.raises(UserError) as err:
        job.load_job(path)
    e = err.value
    assert e.key == key, str(e)
    assert e.file == str(path.resolve())
    message = str(e)
    assert f"key '{key}'" in message and str(path.resolve()) in message
    assert word in message, message


@pytest.mark.parametrize(("text", "want"), [('"auto"', "auto"), ("2", 2.0), ("-1.5", -1.5),
                                            ("64", 64.0), ("-64.0", -64.0)])
def test_exposure_is_a_number_of_stops_or_auto(tmp_path: Path, text: str, want) -> None:
    j = load(tmp_path, f"[output]\nexposure = {text}\n" + SCENE)
    assert j.output.exposure == want and type(j.output.exposure) is type(want)
    shown = f"{want:g}" if isinstance(want, float) else want
    assert f", exposure {shown}\n" in job.job_summary(j)


def test_toml_syntax_error_names_the_line(tmp_path: Path) -> None:
    path = write_job(tmp_path, "[render]\nwidth = 256\nheight = \n")
    with pytest.raises(UserError, match="line 3") as err:
        job.load_job(path)
    assert err.value.file == str(path.resolve())


def test_missing_job_file(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="not found") as err:
        job.load_job(tmp_path / "nope.toml")
    assert err.value.file == str(tmp_path.resolve() / "nope.toml")


def test_unreadable_job_files(tmp_path: Path) -> None:
    with pytest.raises(UserError, match="directory"):
        job.load_job(tmp_path)
    bad = tmp_path / "latin1.toml"
    bad.write_bytes(b'[output]\nname = "caf\xe9"\n')
    with pytest.raises(UserError, match="UTF-8"):
        job.load_job(bad)


def test_error_in_included_file_names_that_file(tmp_path: Path) -> None:
    write_job(tmp_path, "[render]\nspp = 0\n" + SCENE, "inc.toml")
    with pytest.raises(UserError) as err:
        load(tmp_path, '[scene]\ninclude = "inc.toml"\n')
    assert err.value.key == "render.spp"
    assert err.value.file == str((tmp_path / "inc.toml").resolve())


def test_include_cycle_through_two_files(tmp_path: Path) -> None:
    write_job(tmp_path, '[scene]\ninclude = "a.toml"\n' + SCENE, "b.toml")
    write_job(tmp_path, '[scene]\ninclude = "b.toml"\n' + SCENE, "a.toml")
    with pytest.raises(UserError, match="cycle") as err:
        job.load_job(tmp_path / "a.toml")
    assert err.value.key == "scene.include"


def test_include_merges_materials_objects_lights(tmp_path: Path) -> None:
    sub = tmp_path / "lib"
    sub.mkdir()
    (sub / "tri.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    write_job(sub, SCENE + '[[objects]]\nshape = "mesh"\nfile = "tri.obj"\nmaterial = "white"\n'
              '[[lights]]\ntype = "point"\n[render]\nspp = 1\n', "base.toml")
    j = load(tmp_path, '[scene]\ninclude = "lib/base.toml"\n[[materials]]\nname = "red"\n'
                       '[[objects]]\nshape = "box"\ncenter = [0, 0, 0]\nsize = 1\n'
                       'material = "white"\n')
    assert [m.name for m in j.scene.materials] == ["white", "red"]
    assert [o.shape for o in j.scene.objects] == ["sphere", "mesh", "box"]
    assert j.scene.objects[1].params["file"] == (sub / "tri.obj").resolve()  # relative to lib/
    assert len(j.scene.lights) == 1
    assert j.render.spp == 64  # the included file's other settings are not used
    assert j.scene.includes == ((sub / "base.toml").resolve(),)
    with pytest.raises(UserError, match="already defined") as err:
        load(tmp_path, '[scene]\ninclude = "lib/base.toml"\n[[materials]]\nname = "white"\n')
    assert err.value.key == "materials[0].name"


# ----------------------------------------------------------------- camera forms


def test_camera_orientation_forms_agree(tmp_path: Path) -> None:
    position, target, up = [1.0, -4.0, 2.0], [0.2, 0.5, 0.8], [0.1, 0.0, 1.0]
    a = load(tmp_path, f"[camera]\nposition = {position}\nlook_at = {target}\nup = {up}\n"
                       + SCENE).camera
    R = a.rotation
    forward = np.subtract(target, position) / np.linalg.norm(np.subtract(target, position))
    np.testing.assert_allclose(a.forward, forward, atol=1e-15)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)
    assert np.dot(R[:, 1], up) > 0 and abs(np.dot(R[:, 0], up)) < 1e-15  # right ⟂ up
    rows = [list(map(float, r)) for r in R]
    b = load(tmp_path, f"[camera]\nposition = {position}\nrotation = {rows}\n" + SCENE).camera
    M = np.eye(4)
    M[:3, :3] = R * [2.0, 2.0, 0.5]  # a scaled camera object, as Blender may export it
    M[:3, 3] = position
    mrows = [list(map(float, r)) for r in M]
    c = load(tmp_path, f"[camera]\nmatrix = {mrows}\n" + SCENE).camera
    for other in (b, c):
        np.testing.assert_allclose(other.rotation, R, atol=1e-14)
        np.testing.assert_allclose(other.position, position, atol=1e-15)


def test_look_at_rotation_convention() -> None:
    R = job.look_at_rotation(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    # forward +x, up +z: right = forward × up = -y, back = -x
    np.testing.assert_allclose(R, np.column_stack([[0, -1, 0], [0, 0, 1], [-1, 0, 0]]))


# -------------------------------------------------------------------- overrides


def test_overrides(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    j = load(tmp_path, "[motion]\nkeyframes = [{frame = 1, beta = [0, 0, 0]}, "
                       "{frame = 9, beta = [0, 0.8, 0]}]\nframes = [1, 9]\n" + SCENE)
    monkeypatch.chdir(tmp_path)
    k = job.with_overrides(j, spp=4, beta=(0.5, 0.0, 0.0), ct=2.5, frames=[3, 4], out="renders",
                           threads=2)
    assert k.render.spp == 4 and k.render.threads == 2
    np.testing.assert_array_equal(k.motion.beta, [0.5, 0, 0])
    assert k.motion.keyframes == ()  # --beta replaces the keyframes
    assert k.motion.ct == 2.5 and k.motion.frames == (1, 9)  # the animation is unchanged
    assert k.motion.render_frames == (3, 4)
    assert k.output.dir == tmp_path.resolve() / "renders"
    assert motion.frame_list(k) == [3, 4]
    np.testing.assert_array_equal(motion.beta_at_frame(k, 3), [0.5, 0, 0])
    assert job.with_overrides(j) == j
    np.testing.assert_array_equal(job.with_overrides(j, beta=np.array([0, 0, 0.25])).motion.beta,
                                  [0, 0, 0.25])


@pytest.mark.parametrize(
    ("kwargs", "key"),
    [
        ({"spp": 0}, "--spp"),
        ({"spp": True}, "--spp"),
        ({"beta": [0.6, 0.8, 0.0]}, "--beta"),
        ({"beta": [0.1, 0.2]}, "--beta"),
        ({"beta": [float("nan"), 0, 0]}, "--beta"),
        ({"ct": float("inf")}, "--ct"),
        ({"frames": (4, 2)}, "--frames"),
        ({"threads": -1}, "--threads"),
        ({"out": ""}, "--out"),
    ],
)
def test_bad_overrides(tmp_path: Path, kwargs: dict, key: str) -> None:
    j = load(tmp_path, SCENE)
    with pytest.raises(UserError) as err:
        job.with_overrides(j, **kwargs)
    assert err.value.key == key and err.value.file == str(j.path)


def test_frames_override_must_lie_inside_the_animation(tmp_path: Path) -> None:
    j = load(tmp_path, '[output]\nname = "still"\n' + SCENE)
    with pytest.raises(UserError, match="outside the animation") as err:
        job.with_overrides(j, frames=[1, 2])
    assert err.value.key == "--frames"


# ------------------------------------------------------------------- keyframes


def test_frame_list_and_beta_at_frame(tmp_path: Path) -> None:
    j = load(tmp_path, "[motion]\nframes = [0, 20]\nkeyframes = [\n"
                       "  {frame = 5, beta = [0.0, 0.0, 0.0]},\n"
                       "  {frame = 15, beta = [0.0, 0.9, 0.0]},\n"
                       "  {frame = 17, beta = [0.3, 0.0, 0.0]},\n]\n" + SCENE)
    assert j.motion.mode == "snapshot"  # keyframes are allowed in snapshot mode
    assert motion.frame_list(j) == list(range(0, 21))
    np.testing.assert_allclose(motion.beta_at_frame(j, 0), [0, 0, 0])  # held before the first key
    np.testing.assert_allclose(motion.beta_at_frame(j, 10), [0, 0.45, 0])
    np.testing.assert_allclose(motion.beta_at_frame(j, 16), [0.15, 0.45, 0])
    np.testing.assert_allclose(motion.beta_at_frame(j, 20), [0.3, 0, 0])  # held after the last
    assert all(np.linalg.norm(motion.beta_at_frame(j, f)) < 1 for f in motion.frame_list(j))


def test_beta_without_keyframes(tmp_path: Path) -> None:
    j = load(tmp_path, "[motion]\nbeta = [0.1, 0.2, 0.3]\nframes = [1, 3]\n" + SCENE)
    for f in motion.frame_list(j):
        np.testing.assert_array_equal(motion.beta_at_frame(j, f), [0.1, 0.2, 0.3])


def test_summary_mentions_the_essentials(tmp_path: Path) -> None:
    text = job.job_summary(load(tmp_path, "[motion]\nbeta = [0.6, 0, 0]\n" + SCENE))
    for word in ("256 x 256", "64 spp", "cie1931", "snapshot", "gamma 1.25", "1 objects"):
        assert word in text, text


# ------------------------------------------------------------------- add-on API


def test_parse_job_accepts_python_values(tmp_path: Path) -> None:
    data = {
        "render": {"width": np.int64(64), "height": 48},
        "camera": {"position": np.array([0.0, -2.0, 1.0]), "look_at": (0.0, 0.0, 1.0)},
        "materials": [{"name": "m", "base_color": np.float32([0.5, 0.5, 0.5])}],
        "objects": [{"shape": "sphere", "center": (0, 0, 1), "radius": 0.5, "material": "m"}],
    }
    j = job.parse_job(data, tmp_path / "virtual.toml")
    assert j.render.width == 64
    np.testing.assert_array_equal(j.camera.position, [0, -2, 1])


def test_motion_profile(tmp_path: Path) -> None:
    path = write_job(tmp_path, '[motion]\nmode = "worldline"\nproper_acceleration = [0, 0.1, 0]\n')
    m = job.load_motion(path)
    assert m.mode == "worldline"
    np.testing.assert_array_equal(m.proper_acceleration, [0, 0.1, 0])
    with pytest.raises(UserError) as err:
        job.parse_motion({"motion": {}, "render": {}}, path)
    assert err.value.key == "render"


# --------------------------------------------------------------------- presets

PRESETS = sorted((ROOT / "presets").rglob("*.toml"))


def test_presets_exist() -> None:
    names = {p.relative_to(ROOT / "presets").as_posix() for p in PRESETS}
    assert {"cornell.toml", "flyby.toml"} <= names
    figures = {f"seed_figures/fig1-{i}.toml" for i in range(1, 7)}
    figures |= {f"seed_figures/fig2-{i}.toml" for i in range(1, 19)}
    assert figures <= names
    assert len([n for n in names if n.startswith("motion/")]) >= 2
    assert {f"moving/{n}.toml" for n in ("terrell", "ships", "mirror", "train")} <= names


@pytest.mark.parametrize("path", PRESETS, ids=lambda p: p.relative_to(ROOT / "presets").as_posix())
def test_preset_loads(path: Path) -> None:
    if path.parent.name == "motion":
        assert job.load_motion(path).frames[1] >= 1
    else:
        j = job.load_job(path)
        assert j.scene.objects and j.camera is not None


def test_seed_figure_axis_mapping() -> None:
    """Seed beta (bx, by, bz) with z towards the viewer is relray's (bx, -bz, by)."""
    figures = ROOT / "presets" / "seed_figures"
    seed = {"fig1-4": (5, (0.99, 0, 0)), "fig1-6": (5, (0, 0.99, 0)),
            "fig2-3": (1, (0, 0, -0.5)), "fig2-12": (6, (0, 0, 0.5))}
    for name, (ct, (bx, by, bz)) in seed.items():
        j = job.load_job(figures / f"{name}.toml")
        np.testing.assert_array_equal(j.motion.beta, [bx, -bz, by])
        assert j.motion.ct == ct
    assert job.load_job(figures / "fig2-1.toml").render.spectral == "rgb"
    fig22 = job.load_job(figures / "fig2-2.toml").render
    assert fig22.spectral == "seed-gaussian" and not fig22.searchlight
    fig27 = job.load_job(figures / "fig2-7.toml").render
    assert fig27.spectral == "seed-gaussian" and not fig27.searchlight


def test_moving_presets_move_what_they_say() -> None:
    """The gallery's moving presets: each has moving objects in the groups it describes."""
    from relray.core.scene import worldlines

    speeds = {"terrell": {0.9}, "ships": {0.63}, "mirror": {0.1}, "train": {0.8}}
    groups = {"terrell": 1, "ships": 2, "mirror": 1, "train": 1}
    for name, expect in speeds.items():
        j = job.load_job(ROOT / "presets" / "moving" / f"{name}.toml")
        index, gs, _ = worldlines.rest_frame_offsets(list(j.scene.objects))
        assert len(gs) == groups[name], name
        got = {round(float(np.linalg.norm(g.segments[0].u)), 6) for g in gs}
        assert got == expect, name


def test_flyby_preset() -> None:
    j = job.load_job(ROOT / "presets" / "flyby.toml")
    assert j.motion.mode == "worldline" and motion.frame_list(j) == list(range(1, 49))
    assert j.output.dir == ROOT / "out" / "flyby"
    assert np.linalg.norm(motion.beta_at_frame(j, 1)) == 0.0
    assert np.linalg.norm(motion.beta_at_frame(j, 48)) == pytest.approx(0.7)


# ----------------------------------------------------- validators for Python callers


def test_material_and_light_from_dict_validate_as_a_job_does() -> None:
    m = job.material_from_dict({"name": "red", "base_color": (0.6, 0.1, np.float32(0.05)),
                                "ior": np.float64(1.45)}, "materials[3]", "scene.blend")
    assert m == job.MaterialSpec(name="red", base_color=(0.6, 0.1, pytest.approx(0.05)),
                                 ior=1.45)
    with pytest.raises(UserError) as err:
        job.material_from_dict({"name": "red", "roughness": 2.0}, "materials[3]", "a.blend")
    assert str(err.value) == ("a.blend: key 'materials[3].roughness': must be <= 1 (got 2)")
    with pytest.raises(UserError, match="key 'iorr': unknown key.*did you mean 'ior'"):
        job.material_from_dict({"name": "x", "ior": 1.5, "iorr": 1.2})
    light = job.light_from_dict({"type": "spot", "spot_size": 60.0, "direction": (0, 0, -2),
                                 "name": "key"}, "lights[0]")
    assert light.spot_size == pytest.approx(math.radians(60.0))  # degrees, as in a job
    np.testing.assert_allclose(light.direction, (0, 0, -1))
    with pytest.raises(UserError, match="key 'lights\\[0\\].radius': does not apply"):
        job.light_from_dict({"type": "sun", "radius": 1.0}, "lights[0]")
    with pytest.raises(UserError, match="must be a table"):
        job.light_from_dict([1, 2], "lights[0]")


def test_from_dict_clamps_closed_ranges_on_request() -> None:
    notes: list[str] = []
    m = job.material_from_dict({"name": "hdr", "base_color": [1.25, 0.5, -0.1], "ior": 0.8,
                                "emission_strength": 3.0}, "", clamped=notes)
    assert m.base_color == (1.0, 0.5, 0.0) and m.ior == 1.0 and m.emission_strength == 3.0
    assert notes == ["base_color = 1.25 clamped to 1", "base_color = -0.1 clamped to 0",
                     "ior = 0.8 clamped to 1"]
    notes.clear()
    light = job.light_from_dict({"type": "spot", "power": -2.0, "spot_blend": 1.5}, "",
                                clamped=notes)
    assert (light.power, light.spot_blend) == (0.0, 1.0) and len(notes) == 2
    with pytest.raises(UserError, match="> 0"):  # an open bound cannot be clamped to
        job.material_from_dict({"name": "b", "emission_blackbody": 0.0}, clamped=notes)
    with pytest.raises(UserError, match="<= 1"):  # without the list: strict, as a job
        job.material_from_dict({"name": "hdr", "base_color": [1.25, 0.5, 0.1]})


def test_area_light_up_is_stored_perpendicular_and_unit(tmp_path: Path) -> None:
    j = load(tmp_path, '[[lights]]\ntype = "area"\ndirection = [0, 0, -1]\n'
                      'up = [1, 1, 0.5]\n' + SCENE)
    (light,) = j.scene.lights
    np.testing.assert_allclose(light.up, np.array([1, 1, 0]) / math.sqrt(2), atol=1e-15)
    assert not light.up.flags.writeable
    assert job.light_from_dict({"type": "area"}).up is None  # the shortest-arc default



def test_moving_objects_resolve_their_pivots_and_worldlines(tmp_path: Path) -> None:
    """The pivot defaults to a sphere's or box's center, a quad's mean corner, a mesh's
    translate; a worldline keeps its samples; static objects have zero velocity."""
    (tmp_path / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    text = """
[[materials]]
name = "w"
[[objects]]
shape = "sphere"
center = [1.0, 2.0, 3.0]
radius = 0.5
material = "w"
velocity = [0.5, 0, 0]
[[objects]]
shape = "box"
center = [4.0, 0.0, 1.0]
size = 1.0
material = "w"
velocity = [0.5, 0, 0]
pivot = [9.0, 9.0, 9.0]
[[objects]]
shape = "quad"
corners = [[0, 0, 0], [2, 0, 0], [2, 0, 2], [0, 0, 2]]
material = "w"
worldline = { t = [0.0, 4.0, 8.0], pivot = [[0, 0, 1], [2, 0, 1], [2, 3, 1]] }
[[objects]]
shape = "mesh"
file = "m.obj"
translate = [0.0, 5.0, 0.0]
material = "w"
"""
    j = job.load_job(write_job(tmp_path, text))
    sphere, box, quad, mesh = j.scene.objects
    np.testing.assert_array_equal(sphere.pivot, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(box.pivot, [9.0, 9.0, 9.0])
    np.testing.assert_array_equal(quad.pivot, [1.0, 0.0, 1.0])
    np.testing.assert_array_equal(mesh.pivot, [0.0, 5.0, 0.0])
    assert sphere.worldline is None and not np.any(mesh.velocity)
    np.testing.assert_array_equal(quad.worldline.t, [0.0, 4.0, 8.0])
    np.testing.assert_array_equal(quad.worldline.pivot[2], [2.0, 3.0, 1.0])
    summary = job.job_summary(j)
    assert "velocity group 1" in summary and "velocity group 2" in summary
    assert "segment 1: u (0, 0.75, 0)" in summary and "gamma 1.1547" in summary


def test_a_view_transform_is_checked_when_the_job_loads(tmp_path):
    """An unknown view (or display, look, or a config that is not one) fails before the
    render, naming the key and the file."""
    import importlib.util

    from relray.core.errors import UserError
    from relray.core.scene.job import parse_job

    origin = Path(importlib.util.find_spec("bpy").origin).parent
    config = sorted(origin.glob("*/datafiles/colormanagement/config.ocio"))[0]
    base = {"objects": [{"shape": "sphere", "center": [0, 0, 1], "radius": 0.5,
                         "material": "m"}], "materials": [{"name": "m"}]}
    job = parse_job({**base, "output": {"view_transform": {"config": str(config),
                                                           "view": "AgX"}}},
                    tmp_path / "job.toml")
    assert job.output.view_transform.view == "AgX"
    assert job.output.view_transform.config == config
    for table, key in (({"config": str(config), "view": "Agx"}, "view"),
                       ({"config": str(config), "display": "Nope"}, "display"),
                       ({"config": str(config), "look": "Very Punchy"}, "look")):
        with pytest.raises(UserError) as e:
            parse_job({**base, "output": {"view_transform": table}}, tmp_path / "job.toml")
        assert e.value.key == f"output.view_transform.{key}", e.value
    bad = tmp_path / "bad.ocio"
    bad.write_text("not a config\n")
    with pytest.raises(UserError) as e:
        parse_job({**base, "output": {"view_transform": {"config": str(bad)}}},
                  tmp_path / "job.toml")
    assert e.value.key == "output.view_transform.config"
