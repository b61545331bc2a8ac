"""The README's claims that can be checked mechanically."""

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "design"


@pytest.mark.parametrize("name", ["physics.md", "job-format.md"])
def test_docs_copies_match_the_design_pages(name):
    """docs/ carries copies of the design pages for readers of the repository alone."""
    if not SHARED.is_dir():
        pytest.fail(f"{SHARED} is missing: CI and developers have ../shared beside main")
    assert (ROOT / "docs" / name).read_text() == (SHARED / name).read_text(), (
        f"docs/{name} differs from ../shared/design/{name}: copy it again")


def test_readme_names_the_commands_and_images():
    text = (ROOT / "README.md").read_text()
    assert "make demo" in text and "make test" in text
    for image in ("docs/gallery/seed_figures.png", "docs/gallery/seed_figures_physical.png",
                  "docs/gallery/flyby.png"):
        assert image in text and (ROOT / image).is_file()


def _job_reference():
    import importlib.util

    spec = importlib.util.spec_from_file_location("job_reference",
                                                  ROOT / "docs" / "job_reference.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_job_reference_lists_every_accepted_key(monkeypatch):
    """docs/job-reference.md is generated from the validator's key tables and the
    docstring tables; every key the validator accepts is documented there."""
    ref = _job_reference()
    assert ref.missing_keys() == []
    assert (ROOT / "docs" / "job-reference.md").read_text() == ref.render(), \
        "docs/job-reference.md is out of date: run .venv/bin/python docs/job_reference.py"
    for key in ("scene.include", "render.transparent", "camera.shift",
                "materials.one_sided_emission", "lights (area).up"):
        section, _, name = key.rpartition(".")
        assert name in ref.job.accepted_keys()[section]
    from relray.core.scene import job

    real = job.accepted_keys
    monkeypatch.setattr(job, "accepted_keys", lambda: {**real(), "render": ("undocumented",)})
    assert ref.missing_keys() == ["render.undocumented"]  # the check can fail
