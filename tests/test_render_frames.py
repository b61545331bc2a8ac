"""Frame selection: ``--frames`` renders a sub-range of the *same* animation."""

from pathlib import Path

import numpy as np

from relray.core import job as jobmod
from relray.core.render import frame_events

FLYBY = Path(__file__).resolve().parents[1] / "presets" / "flyby.toml"


def test_sub_range_has_the_full_animations_shutter_events():
    job = jobmod.load_job(FLYBY)
    full = dict(frame_events(job))
    part = frame_events(jobmod.with_overrides(job, frames=(40, 42)))
    assert [f for f, _ in part] == [40, 41, 42]
    for f, ev in part:
        assert ev.t == full[f].t and ev.tau == full[f].tau
        np.testing.assert_array_equal(ev.x, full[f].x)
        np.testing.assert_array_equal(ev.beta, full[f].beta)
