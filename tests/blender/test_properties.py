"""relblend/properties.py: the add-on's data (Relativity settings, render settings)."""

from __future__ import annotations

import math

import bpy
import pytest
from conftest import ext_module


def test_spectral_model_items_are_the_cores_modes():
    """The Spectral Model menu offers exactly the core's spectral modes (one fact)."""
    spectrum = ext_module("core.physics.spectrum")
    prop = bpy.context.scene.relray.bl_rna.properties["spectral"]
    assert tuple(item.identifier for item in prop.enum_items) == spectrum.MODES


def test_gamma_readout_is_the_cores_gamma():
    relativity = ext_module("core.physics.relativity")
    cam = bpy.data.cameras.new("gamma-test")
    s = cam.relray
    s.velocity_input = "VECTOR"
    s.beta = (0.3, 0.4, 0.0)
    assert s.gamma == pytest.approx(relativity.gamma([0.3, 0.4, 0.0]), rel=1e-6)
    s.velocity_input = "SPEED"
    s.speed, s.direction = 0.6, (0.0, 0.0, 0.0)
    assert s.gamma == 1.0                                 # no direction: at rest
    s.direction = (1.0, 0.0, 0.0)
    assert s.gamma == pytest.approx(1.25, rel=1e-6)
    assert math.isfinite(s.gamma)
    bpy.data.cameras.remove(cam)
