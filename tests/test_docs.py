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


# docs/job-reference.md and docs/job.schema.json: tests/test_schema.py (generated from
# core/scene/schema.py, checked to be current there).
