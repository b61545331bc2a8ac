"""The job schema declared once (core/scene/schema.py): the generated reference page and
JSON Schema are current, presets validate against it, its errors are one line naming
the key and the file, and the CLI prints it."""

from __future__ import annotations

import json
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from relray.core import cli
from relray.core.errors import UserError
from relray.core.scene import description, job, schema

ROOT = Path(__file__).resolve().parents[1]
PRESETS = sorted((ROOT / "presets").rglob("*.toml"))
JOB_PRESETS = [p for p in PRESETS if p.parent.name != "motion"]
SCENE = '[[materials]]\nname = "w"\n[[objects]]\nshape = "sphere"\ncenter = [0, 0, 1]\n' \
        'radius = 0.5\nmaterial = "w"\n'


def test_generated_reference_and_json_schema_are_current():
    """Regenerate with: .venv/bin/python docs/job_reference.py"""
    page = (ROOT / "docs" / "job-reference.md").read_text(encoding="utf-8")
    assert page == schema.markdown(), "docs/job-reference.md is out of date: run " \
                                      ".venv/bin/python docs/job_reference.py"
    text = (ROOT / "docs" / "job.schema.json").read_text(encoding="utf-8")
    assert text == schema.json_text(), "docs/job.schema.json is out of date: run " \
                                       ".venv/bin/python docs/job_reference.py"


def test_reference_lists_every_key_of_every_table():
    page = schema.markdown()
    for table, keys in job.accepted_keys().items():
        for key in keys:
            if key not in ("shape", "type"):
                assert f"| `{key}` |" in page, f"{table}.{key} is missing"
    for key in ("scene.include", "render.transparent", "camera.shift",
                "materials.one_sided_emission", "lights (area).up", "objects (mesh).up"):
        section, _, name = key.rpartition(".")
        assert name in job.accepted_keys()[section]


def test_vocabularies_come_from_the_description():
    """One fact, one place: the choices are description.py's constants."""
    def choices(model, name):
        return schema._resolve(model, (name,)).choices

    assert choices(schema.Render, "spectral") == description.SPECTRAL_CHOICES
    assert choices(schema.Motion, "mode") == description.MOTION_MODES
    assert schema._resolve(schema.Output, ("formats", 0)).choices == description.OUTPUT_FORMATS
    assert schema._resolve(schema.Output, ("aovs", 0)).choices == description.AOV_NAMES
    assert tuple(schema.OBJECT_MODELS) == description.SHAPES
    assert tuple(schema.LIGHT_MODELS) == description.LIGHT_TYPES
    props = schema.json_schema()["$defs"]["Render"]["properties"]
    assert props["spectral"]["enum"] == list(description.SPECTRAL_CHOICES)


def test_json_schema_has_every_key_with_a_description():
    defs = schema.json_schema()["$defs"]
    models = {"Render": schema.Render, "Output": schema.Output, "Camera": schema.Camera,
              "Motion": schema.Motion, "Scene": schema.Scene, "Material": schema.Material,
              **{m.__name__: m for m in schema.OBJECT_MODELS.values()},
              **{m.__name__: m for m in schema.LIGHT_MODELS.values()}}
    for name, model in models.items():
        d = defs[name]
        assert d["additionalProperties"] is False
        assert list(d["properties"]) == list(model.model_fields)
        for key, prop in d["properties"].items():
            if key not in ("shape", "type"):
                assert prop.get("description"), f"{name}.{key} has no description"
    top = schema.json_schema()
    assert top["$schema"].endswith("2020-12/schema") and top["additionalProperties"] is False
    assert top["properties"]["objects"]["items"]["required"] == ["shape"]


@pytest.mark.parametrize("path", PRESETS, ids=lambda p: p.relative_to(ROOT).as_posix())
def test_presets_validate_against_the_schema(path):
    """Every preset is valid for the schema's model (and for the JSON Schema where the
    jsonschema package is installed: it is not a dependency)."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    model = schema.MotionProfile if path.parent.name == "motion" else schema.JobFile
    schema.validate(model, data, path)
    try:
        import jsonschema
    except ImportError:
        return
    if model is schema.JobFile:
        jsonschema.validate(data, schema.json_schema())


def test_cli_prints_and_writes_the_schema(tmp_path, capsys):
    assert cli.main(["schema"]) == 0
    assert capsys.readouterr().out == schema.json_text()
    out = tmp_path / "job.schema.json"
    assert cli.main(["schema", "-o", str(out)]) == 0
    assert json.loads(out.read_text()) == schema.json_schema()


def test_module_prints_markdown_and_json():
    for flag, want in (("--markdown", schema.markdown()), ("--json", schema.json_text())):
        r = subprocess.run([sys.executable, "-m", "relray.core.scene.schema", flag],
                           capture_output=True, text=True, timeout=120)
        assert r.returncode == 0 and r.stdout == want, r.stderr


# ------------------------------------------------------------------- the messages


def _error(tmp_path: Path, text: str) -> UserError:
    path = tmp_path / "job.toml"
    path.write_text(text)
    with pytest.raises(UserError) as err:
        job.load_job(path)
    message = str(err.value)
    assert "\n" not in message and str(path.resolve()) in message
    return err.value


@pytest.mark.parametrize(("text", "key", "message"), [
    ("[render]\nwidht = 3\n", "render.widht",
     "unknown key (did you mean 'width'?); known keys: width, height"),
    ("[[materials]]\nname = 'w'\nrougness = 1\n", "materials[0].rougness",
     "unknown key in a material (did you mean 'roughness'?)"),
    ("[render]\nspp = 1.5\n", "render.spp", "must be an integer, not a number"),
    ("[render]\ndoppler = 1\n", "render.doppler", "must be true or false, not an integer"),
    ("[motion]\nbeta = [0.5, 'x', 0]\n", "motion.beta",
     "must be a number, not a string (at [1])"),
    ("[motion]\nbeta = [0.5, 0]\n", "motion.beta", "must be an array of 3 numbers, not 2 values"),
    ("[motion]\nbeta = [0.8, 0.7, 0]\n", "motion.beta",
     "|beta| = 1.06301 must be below 1 (the speed of light, c = 1)"),
    ("[motion]\nct = nan\n", "motion.ct", "must be finite, not nan"),
    ("[motion]\nct = -2e15\n", "motion.ct",
     "-2e+15 is out of range: numbers must lie within ±1e+15 (relray computes in float32)"),
    ("[render]\nwidth = 40000\n", "render.width", "must be <= 32768 (got 40000)"),
    ("[camera]\nfov = 0\n", "camera.fov", "must be > 0 (got 0)"),
    ("[render]\nspectral = 'cie1964'\n", "render.spectral",
     "'cie1964' is not one of cie1931, seed-gaussian, rgb, auto (did you mean 'cie1931'?)"),
    ("[[lights]]\ntype = 'lazer'\n", "lights[0].type",
     "'lazer' is not one of point, spot, sun, area"),
    ("[[lights]]\npower = 3\n", "lights[0].type", "missing: one of point, spot, sun, area"),
    ("[[objects]]\nshape = 'box'\ncenter = [0, 0, 0]\nmaterial = 'w'\n", "objects[0].size",
     "missing: a box needs center and size"),
    ("[[lights]]\ntype = 'area'\nsize = [1, -2]\n", "lights[0].size",
     "must be > 0 (got -2) (at [1])"),
    ("[camera]\nrotation = [[1, 0, 0], [0, 1, 0], [0, 0]]\n", "camera.rotation",
     "must be 3 rows of 3 numbers (at [2])"),
    ("[output]\nname = 'x'\nformats = ['exr', 5]\n", "output.formats",
     "must be a string, not an integer (at [1])"),
    ("[scene]\ninclude = []\n", "scene.include",
     "must be a file name or an array of file names"),
    ("render = [1]\n", "render", "must be a table, not an array"),
    ("[render]\nseed = " + "9" * 30 + "\n", "render.seed",
     "must be <= 9.22337e+18 (got 1e+30)"),
])
def test_messages_name_key_file_and_keep_the_details(tmp_path, text, key, message):
    e = _error(tmp_path, text + SCENE)
    assert e.key == key, str(e)
    assert f"key '{key}': {message}" in str(e), str(e)


def test_huge_integers_and_deep_nesting_are_one_line(tmp_path):
    e = _error(tmp_path, "[render]\nnoise_threshold = " + "9" * 5000 + "\n" + SCENE)
    assert "more than 4300 digits" in str(e)
    e = _error(tmp_path, "a = " + "[" * 100_000 + "]" * 100_000 + "\n")
    assert "nested too deeply" in str(e)
    with pytest.raises(UserError, match="key 'render.noise_threshold': must be finite, not inf"):
        job.parse_job({"render": {"noise_threshold": 10**5000}}, tmp_path / "py.toml")
    with pytest.raises(UserError, match=r"got an integer of 5001 digits"):
        job.parse_job({"render": {"seed": 10**5000}}, tmp_path / "py.toml")
    deep: list = []
    for _ in range(100_000):
        deep = [deep]
    with pytest.raises(UserError, match="nested too deeply"):
        job.parse_job({"motion": {"beta": deep}}, tmp_path / "py.toml")


def test_clamping_notes_each_clamped_number():
    notes: list[str] = []
    light = job.light_from_dict({"type": "area", "color": [2.0, -1.0, 0.5], "power": -3.0,
                                 "size": 0.5}, "lights[4]", "scene.blend", clamped=notes)
    assert light.color.tolist() == [2.0, 0.0, 0.5] and light.power == 0.0
    assert notes == ["lights[4].color = -1 clamped to 0", "lights[4].power = -3 clamped to 0"]
    with pytest.raises(UserError, match="key 'lights\\[4\\].type': missing"):
        job.light_from_dict({"power": 3.0}, "lights[4]", "scene.blend")
