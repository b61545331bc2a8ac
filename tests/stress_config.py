"""Shared switches of the stress suite (issue 5): tests/test_stress_*.py.

The stress tests are part of ``make test`` with small grids and few hypothesis examples
(well under a minute together). ``make stress`` runs them with ``RELRAY_STRESS=1``, which
enlarges every grid and example count and adds the long runs (the 1920×1080 memory
bound, every malformed job through a real subprocess).
"""

from __future__ import annotations

import os

import pytest

STRESS = os.environ.get("RELRAY_STRESS", "") not in ("", "0")
"""True under ``make stress`` (RELRAY_STRESS=1)."""

only_in_stress = pytest.mark.skipif(not STRESS, reason="long variant: run by `make stress`")


def pick(default, stress):
    """``stress`` under RELRAY_STRESS=1, else ``default`` (grids, example counts)."""
    return stress if STRESS else default
