"""Shapes, mesh import, degenerate triangles and area lights in the built scene."""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import pytest

from relray.core.errors import UserError
from relray.core.scene import geometry as scene
from relray.core.scene import job, shapes


def tri_areas(t: np.ndarray) -> np.ndarray:
    t = np.asarray(t, np.float64)
    return 0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1)


def build(tmp_path: Path, text: str) -> scene.Scene:
    (tmp_path / "job.toml").write_text('[[materials]]\nname = "m"\n' + text)
    return scene.build_scene(job.load_job(tmp_path / "job.toml"))


# ------------------------------------------------------------------------ spheres


@pytest.mark.parametrize("subdivisions", range(7))
def test_sphere_area_within_the_derived_bound(subdivisions: int) -> None:
    center, r = np.array([0.3, -1.0, 2.0]), 0.7
    tris, _ = shapes.sphere(center, r, subdivisions)
    assert len(tris) == 20 * 4**subdivisions
    area = tri_areas(tris).sum()
    normals = shapes.face_normals(tris)
    h_min = np.abs(np.einsum("ij,ij->i", tris[:, 0] - center, normals)).min()
    exact = 4 * math.pi * r * r
    # central projection of a face at plane distance h: dA_sphere/dA_face in [h/r, r²/h²]
    assert (h_min / r) ** 2 * exact <= area <= exact
    if subdivisions == 5:
        assert 1 - area / exact == pytest.approx(3.0e-4, rel=0.05)


def test_sphere_deficit_quarters_per_subdivision() -> None:
    deficits = [1 - tri_areas(shapes.sphere(np.zeros(3), 1.0, s)[0]).sum() / (4 * math.pi)
                for s in range(2, 7)]
    ratios = np.array(deficits[:-1]) / np.array(deficits[1:])
    np.testing.assert_allclose(ratios, 4.0, rtol=0.02)


def test_sphere_normals_unit_radial_and_winding_outward() -> None:
    center, r = np.array([1.0, 2.0, 3.0]), 2.5
    tris, normals = shapes.sphere(center, r, 3)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=2), 1.0, atol=1e-12)
    np.testing.assert_allclose(normals, (tris - center) / r, atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(tris - center, axis=2), r, atol=1e-12)
    outward = np.einsum("ij,ij->i", shapes.face_normals(tris), tris.mean(axis=1) - center)
    assert np.all(outward > 0)


def test_sphere_object_in_scene(tmp_path: Path) -> None:
    s = build(tmp_path, '[[objects]]\nshape = "sphere"\ncenter = [0, 0, 1]\nradius = 0.5\n'
                        'subdivisions = 2\nmaterial = "m"\n')
    assert s.triangles.dtype == np.float64 and s.triangles.shape == (320, 3, 3)
    assert s.normals is not None and s.normals.dtype == np.float32
    assert s.material_ids.dtype == np.int32
    lo, hi = s.bounds()
    assert np.all(lo >= [-0.5, -0.5, 0.5 - 1e-6]) and np.all(hi <= [0.5, 0.5, 1.5 + 1e-6])


# -------------------------------------------------------------------- box and quad


def test_box_twelve_outward_triangles_and_bounds() -> None:
    center, size = np.array([1.0, 2.0, 3.0]), np.array([0.4, 0.6, 1.2])
    tris = shapes.box(center, size)
    assert tris.shape == (12, 3, 3)
    pts = tris.reshape(-1, 3)
    np.testing.assert_allclose(pts.min(0), center - size / 2)
    np.testing.assert_allclose(pts.max(0), center + size / 2)
    assert tri_areas(tris).sum() == pytest.approx(2 * (0.4 * 0.6 + 0.6 * 1.2 + 0.4 * 1.2))
    outward = np.einsum("ij,ij->i", shapes.face_normals(tris), tris.mean(axis=1) - center)
    assert np.all(outward > 0)


def test_rotated_box_bounds() -> None:
    size, angle = np.array([2.0, 1.0, 1.0]), 30.0
    pts = shapes.box(np.zeros(3), size, angle).reshape(-1, 3)
    c, s = math.cos(math.radians(angle)), math.sin(math.radians(angle))
    half = np.array([size[0] * c + size[1] * s, size[0] * s + size[1] * c, size[2]]) / 2
    np.testing.assert_allclose(pts.max(0), half)
    np.testing.assert_allclose(pts.min(0), -half)


def test_box_scalar_size_in_scene(tmp_path: Path) -> None:
    s = build(tmp_path, '[[objects]]\nshape = "box"\ncenter = [0, 0, 0.5]\nsize = 1\n'
                        'rotation_z = 90\nmaterial = "m"\n')
    assert s.triangles.shape == (12, 3, 3) and s.normals is None
    lo, hi = s.bounds()
    np.testing.assert_allclose(lo, [-0.5, -0.5, 0.0], atol=1e-6)
    np.testing.assert_allclose(hi, [0.5, 0.5, 1.0], atol=1e-6)


def test_quad() -> None:
    corners = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0]], float)
    tris = shapes.quad(corners)
    assert tris.shape == (2, 3, 3)
    assert tri_areas(tris).sum() == pytest.approx(2.0)
    np.testing.assert_allclose(shapes.face_normals(tris), [[0, 0, 1], [0, 0, 1]])
    assert shapes.quad_problem(corners) is None


@pytest.mark.parametrize(
    ("corners", "word"),
    [
        ([[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]], "degenerate"),
        ([[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]], "degenerate"),
        ([[0, 0, 0], [1, 0, 0], [1, 1, 0.1], [0, 1, 0]], "plane"),
        ([[0, 0, 0], [1, 1, 0], [1, 0, 0], [0, 1, 0]], "convex"),  # bow tie
        ([[0, 0, 0], [2, 0, 0], [0.5, 0.5, 0], [0, 2, 0]], "convex"),  # dart
    ],
)
def test_quad_problems(corners: list, word: str) -> None:
    assert word in shapes.quad_problem(np.array(corners, float))


# ------------------------------------------------------------------------- meshes

OBJ = """# a unit square as one quad face, plus a triangle
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
f 1 2 3 4
f 1 2 5
"""


def test_mesh_from_obj_with_transform(tmp_path: Path) -> None:
    (tmp_path / "m.obj").write_text(OBJ)
    s = build(tmp_path, '[[objects]]\nshape = "mesh"\nfile = "m.obj"\ntranslate = [1, 2, 3]\n'
                        'scale = [2, 3, 4]\nrotation_z = 90\nmaterial = "m"\n')
    assert s.triangles.shape == (3, 3, 3) and s.normals is None
    # v -> Rz(90) (scale * v) + t: (x, y, z) -> (-3y, 2x, 4z) + (1, 2, 3)
    src = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1]], float)
    want = np.stack([-3 * src[:, 1], 2 * src[:, 0], 4 * src[:, 2]], axis=1) + [1, 2, 3]
    got = np.unique(s.triangles.reshape(-1, 3).round(6), axis=0)
    np.testing.assert_allclose(got, np.unique(want.round(6), axis=0), atol=1e-6)
    assert tri_areas(s.triangles).sum() == pytest.approx(6.0 + 0.5 * 2 * 4)


def test_mesh_y_up_and_smooth_normals(tmp_path: Path) -> None:
    (tmp_path / "m.obj").write_text(OBJ)
    s = build(tmp_path, '[[objects]]\nshape = "mesh"\nfile = "m.obj"\nup = "y"\nsmooth = true\n'
                        'material = "m"\n')
    # y-up file: its (x, y, z) is relray's (x, -z, y); the square (z = 0) lies in y = 0
    assert np.all(s.triangles[:2, :, 1] == 0)
    assert s.normals is not None
    np.testing.assert_allclose(np.linalg.norm(s.normals, axis=2), 1.0, atol=1e-6)


@pytest.mark.parametrize("suffix", ["ply", "stl"])
def test_mesh_formats_through_trimesh(tmp_path: Path, suffix: str) -> None:
    import trimesh

    trimesh.creation.box(extents=[1, 2, 3]).export(str(tmp_path / f"b.{suffix}"))
    s = build(tmp_path, f'[[objects]]\nshape = "mesh"\nfile = "b.{suffix}"\nmaterial = "m"\n')
    assert s.triangles.shape == (12, 3, 3)
    np.testing.assert_allclose(s.bounds()[1], [0.5, 1.0, 1.5], atol=1e-6)


def test_corrupt_mesh_is_a_user_error(tmp_path: Path) -> None:
    (tmp_path / "bad.ply").write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 99"
                                       b"\nend_header\n\x00\x01")
    with pytest.raises(UserError) as err:
        build(tmp_path, '[[objects]]\nshape = "mesh"\nfile = "bad.ply"\nmaterial = "m"\n')
    assert err.value.key == "objects[0].file"
    assert str(tmp_path / "job.toml") in str(err.value)


def test_degenerate_triangles_dropped_with_a_count(tmp_path: Path, caplog) -> None:
    (tmp_path / "d.obj").write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 2 0 0\nv nan 0 0\n"  # vertex 5 is never used
        "f 1 2 3\n"  # fine
        "f 1 2 4\n"  # collinear: zero area
        "f 1 1 3\n"  # repeated vertex
    )
    with caplog.at_level(logging.WARNING, logger="relray"):
        s = build(tmp_path, '[[objects]]\nshape = "mesh"\nfile = "d.obj"\nmaterial = "m"\n')
    assert s.triangles.shape == (1, 3, 3)
    assert s.dropped_degenerate == 2
    assert len(s.material_ids) == 1
    assert "dropped 2 degenerate" in caplog.text


@pytest.mark.parametrize("bad", ["nan", "inf", "1e30", "-2e15"])
def test_mesh_coordinates_bounded_like_job_numbers(tmp_path: Path, bad: str) -> None:
    """One vertex at 1e30 would move the float32 centre and collapse the real geometry:
    an error naming the object's file key, never a black frame."""
    (tmp_path / "d.obj").write_text(f"v 0 0 0\nv 1 0 0\nv 0 1 0\nv {bad} 0 0\n"
                                    "f 1 2 3\nf 1 2 4\n")
    with pytest.raises(UserError, match="objects\\[0\\].file.*(not finite|beyond)"):
        build(tmp_path, '[[objects]]\nshape = "mesh"\nfile = "d.obj"\nmaterial = "m"\n')


def test_mesh_transform_bounded(tmp_path: Path) -> None:
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(UserError, match="objects\\[0\\].*after its transform.*beyond"):
        build(tmp_path, '[[objects]]\nshape = "mesh"\nfile = "t.obj"\nmaterial = "m"\n'
                        'scale = 1e15\ntranslate = [1e15, 0, 0]\n')


def test_an_object_that_vanishes_is_an_error(tmp_path: Path) -> None:
    """A tiny object beside a huge one collapses to zero area in float32 around the
    scene's centre: an error naming that object, not a frame without it."""
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1e-9 0 0\nv 0 1e-9 0\nf 1 2 3\n")
    text = ('[[objects]]\nshape = "box"\ncenter = [1e9, 0, 0]\nsize = 1e6\nmaterial = "m"\n'
            '[[objects]]\nshape = "mesh"\nfile = "t.obj"\nmaterial = "m"\n')
    with pytest.raises(UserError, match=r"objects\[1\].*all 1 triangles vanish"):
        build(tmp_path, text)


def test_all_degenerate_is_a_user_error(tmp_path: Path) -> None:
    (tmp_path / "d.obj").write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    with pytest.raises(UserError, match="no triangles"):
        build(tmp_path, '[[objects]]\nshape = "mesh"\nfile = "d.obj"\nmaterial = "m"\n')


# -------------------------------------------------------------------------- lights

AREA = """[[objects]]
shape = "box"
center = [0, 0, 0]
size = 1
material = "m"
[[lights]]
type = "area"
name = "panel"
position = [0.0, 0.0, 1.9]
direction = [0.0, 0.0, -1.0]
size = [0.5, 0.4]
power = 40.0
color = [1.0, 0.8, 0.6]
[[lights]]
type = "point"
position = [0.0, 0.0, 1.0]
power = 100.0
"""


def test_area_light_becomes_emissive_quad(tmp_path: Path) -> None:
    s = build(tmp_path, AREA)
    assert [light.type for light in s.lights] == ["point"]
    quad = s.triangles[s.material_ids == 1]
    assert quad.shape == (2, 3, 3)
    m = s.materials[1]
    area = 0.5 * 0.4
    assert m.emission_strength == pytest.approx(40.0 / (math.pi * area))  # L = P / (pi A)
    assert m.emission == pytest.approx((1.0, 0.8, 0.6))
    assert m.one_sided_emission and m.base_color == (0.0, 0.0, 0.0)
    assert tri_areas(quad).sum() == pytest.approx(area, rel=1e-6)
    np.testing.assert_allclose(shapes.face_normals(quad), [[0, 0, -1]] * 2, atol=1e-7)
    np.testing.assert_allclose(quad.reshape(-1, 3).mean(0)[2], 1.9, atol=1e-6)
    extent = quad.reshape(-1, 3).max(0) - quad.reshape(-1, 3).min(0)
    np.testing.assert_allclose(extent, [0.5, 0.4, 0.0], atol=1e-6)  # width along x


@pytest.mark.parametrize("moving", [False, True], ids=["static", "moving-scene"])
def test_area_light_quads_are_the_last_static_triangles(tmp_path: Path, moving: bool) -> None:
    """The quads are lights, not geometry: ``light_triangles`` counts them and they are
    triangles[n_geometry:n_static], after the static objects and before any moving group
    (so the static BVH is triangles[:n_geometry] and the groups keep their places)."""
    moving_sphere = ('[[objects]]\nshape = "sphere"\ncenter = [3, 0, 0]\nradius = 0.5\n'
                     'material = "m"\nvelocity = [0.5, 0, 0]\n') if moving else ""
    s = build(tmp_path, moving_sphere + AREA)
    assert s.light_triangles == 2
    assert s.n_geometry == s.n_static - 2 == 12  # the box's 12 triangles
    lamp = [m.name for m in s.materials].index("area_light:panel")
    assert np.flatnonzero(s.material_ids == lamp).tolist() == [12, 13]
    assert (s.tri_group is not None) == moving
    if moving:
        assert s.tri_group[:14].tolist() == [0] * 14 and np.all(s.tri_group[14:] == 1)
    assert build(tmp_path, AREA.split("[[lights]]")[0]).light_triangles == 0


def test_area_light_emits_its_power() -> None:
    """P = pi A L for a one-sided Lambertian emitter, for any direction."""
    light = job.LightSpec(type="area", position=np.zeros(3),
                          direction=np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8]),
                          power=7.0, size=(0.3, 2.0))
    quad = shapes.area_light_quad(light.position, light.direction, light.size)
    L = scene.area_light_material(light, 0).emission_strength
    assert math.pi * tri_areas(quad).sum() * L == pytest.approx(7.0)
    np.testing.assert_allclose(shapes.face_normals(quad), [light.direction] * 2, atol=1e-12)


@pytest.mark.parametrize("direction", [[0, 0, 1], [0, 0, -1], [1, 0, 0], [0.2, 0.3, -0.9]])
def test_light_frame_is_a_rotation_with_minus_z_along_direction(direction: list) -> None:
    d = np.array(direction, float) / np.linalg.norm(direction)
    R = shapes.frame_towards(d)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(-R[:, 2], d, atol=1e-12)


def test_cornell_preset_scene() -> None:
    root = Path(__file__).resolve().parents[1]
    s = scene.build_scene(job.load_job(root / "presets" / "cornell.toml"))
    assert s.triangles.shape == (6 * 2 + 2 * 12, 3, 3)
    np.testing.assert_allclose(s.bounds()[0], [-1, -1, 0])
    np.testing.assert_allclose(s.bounds()[1], [1, 1, 2])
    light = [m.name for m in s.materials].index("light")
    assert np.count_nonzero(s.material_ids == light) == 2
    assert s.dropped_degenerate == 0 and s.camera is None


def test_area_light_up_turns_the_quad_about_its_direction(tmp_path: Path) -> None:
    """``up`` is the light's local +Y: the height (0.4) then runs along x, the width along y."""
    s = build(tmp_path, AREA.replace("size = [0.5, 0.4]", "size = [0.5, 0.4]\nup = [1, 0, 0]"))
    quad = s.triangles[s.material_ids == 1].reshape(-1, 3)
    np.testing.assert_allclose(quad.max(0) - quad.min(0), [0.4, 0.5, 0.0], atol=1e-6)
    np.testing.assert_allclose(shapes.face_normals(s.triangles[s.material_ids == 1]),
                               [[0, 0, -1]] * 2, atol=1e-7)
    frame = shapes.frame_towards(np.array([0.3, -0.5, 0.8]), np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(frame.T @ frame, np.eye(3), atol=1e-12)
    assert np.linalg.det(frame) == pytest.approx(1.0)
    assert frame[2, 0] == pytest.approx(0.0, abs=1e-12)  # local +x is horizontal


# ------------------------------------------------------------- scene_from_parts


def test_scene_from_parts_does_what_build_scene_does(caplog) -> None:
    tris = np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]],
                     [[0, 0, 0], [1, 0, 0], [2, 0, 0]],  # degenerate
                     [[0, 0, 1], [1, 0, 1], [np.nan, 1, 1]],  # non-finite
                     [[0, 0, 2], [0, 1, 2], [1, 0, 2]]], dtype=np.float32)
    normals = np.zeros((4, 3, 3))
    normals[0] = [0, 0, 2.0]  # scaled: made unit
    # normals[3] is zero: replaced by the face normal (0, 0, -1)
    mats = [job.MaterialSpec(name="a"), job.MaterialSpec(name="b")]
    lights = [job.LightSpec(type="point", name="p"),
              job.LightSpec(type="area", name="panel", position=np.array([0, 0, 3.0]),
                            size=(0.5, 0.4), power=10.0, up=np.array([1.0, 0, 0]))]
    with caplog.at_level(logging.WARNING, logger="relray"):
        s = scene.scene_from_parts(tris, normals, np.array([0, 1, 1, 1]), mats, lights,
                                   (0.1, 0.2, 0.3))
    assert "dropped 2 degenerate" in caplog.text and s.dropped_degenerate == 2
    assert s.triangles.dtype == np.float64 and len(s.triangles) == 4  # 2 kept + the quad
    assert [m.name for m in s.materials] == ["a", "b", "area_light:panel"]
    assert s.material_ids.tolist() == [0, 1, 2, 2]
    assert [light.name for light in s.lights] == ["p"]
    np.testing.assert_allclose(s.normals[0], [[0, 0, 1]] * 3)
    np.testing.assert_allclose(s.normals[1], [[0, 0, -1]] * 3)
    quad = s.triangles[2:].reshape(-1, 3)
    np.testing.assert_allclose(quad.max(0) - quad.min(0), [0.4, 0.5, 0.0], atol=1e-12)
    assert s.materials[2].emission_strength == pytest.approx(10.0 / (math.pi * 0.2))
    assert s.background.tolist() == [0.1, 0.2, 0.3] and s.camera is None
    one_id = scene.scene_from_parts(tris[:1], None, 0, mats, [], (0, 0, 0))
    assert one_id.normals is None and one_id.material_ids.tolist() == [0]
    with pytest.raises(UserError, match="x.blend: key 'scene': the scene has no triangles "
                                        r"\(all 1 were degenerate\)"):
        scene.scene_from_parts(tris[1:2], None, 0, mats, [], (0, 0, 0), file="x.blend")
    with pytest.raises(ValueError, match="do not index 2 materials"):
        scene.scene_from_parts(tris, None, 2, mats, [], (0, 0, 0))


# ------------------------------------------------------------ texture coordinates


def test_quad_and_box_uvs_map_corners_to_the_unit_square(tmp_path: Path) -> None:
    """A quad's corners in order to (0,0), (1,0), (1,1), (0,1); every box face likewise,
    counter-clockwise seen from outside (u × v along the outward normal: not mirrored)."""
    s = build(tmp_path, '[[objects]]\nshape = "quad"\ncorners = [[0, 0, 0], [2, 0, 0], '
                        '[2, 3, 0], [0, 3, 0]]\nmaterial = "m"\n')
    assert s.uvs.shape == (2, 3, 2) and s.uvs.dtype == np.float32
    # on this quad u = x / 2, v = y / 3 at every corner of both triangles
    np.testing.assert_allclose(s.uvs[..., 0], s.triangles[..., 0] / 2)
    np.testing.assert_allclose(s.uvs[..., 1], s.triangles[..., 1] / 3)
    tris = shapes.box(np.zeros(3), np.array([1.0, 2.0, 3.0]), 30.0)
    uv = shapes.box_uvs()
    n = shapes.face_normals(tris)
    for t, w, nn in zip(tris, uv, n, strict=True):
        # the world-space directions of +u and +v on the face: u × v is the outward normal
        m = np.column_stack([w[1] - w[0], w[2] - w[0]])
        e = np.column_stack([t[1] - t[0], t[2] - t[0]])
        duv = e @ np.linalg.inv(m)  # (3, 2): columns dP/du, dP/dv
        assert np.cross(duv[:, 0], duv[:, 1]) @ nn > 0
    assert {tuple(x) for x in uv.reshape(-1, 2)} == {(0, 0), (1, 0), (1, 1), (0, 1)}


def test_sphere_uvs_azimuth_and_polar_angle() -> None:
    """u = azimuth/2π about +Z from +X towards +Y, v = 1 - polar/π, per vertex; no
    triangle spans more than a small part of u (the seam is unwrapped)."""
    tris, normals = shapes.sphere(np.array([1.0, 2.0, 3.0]), 2.0, 3)
    uv = shapes.sphere_uvs(normals)
    x, y, z = normals[..., 0], normals[..., 1], normals[..., 2]
    away = x * x + y * y > 1e-12
    az = np.arctan2(y, x) / (2 * np.pi)
    d = np.mod(uv[..., 0] - az + 0.5, 1.0) - 0.5  # equal modulo 1
    assert np.abs(d[away]).max() < 1e-9
    np.testing.assert_allclose(uv[..., 1], 1 - np.arccos(z) / np.pi, atol=1e-12)
    span = uv[..., 0].max(axis=1) - uv[..., 0].min(axis=1)
    assert span.max() < 0.2


def test_mesh_uvs_from_obj_and_none_is_zero(tmp_path: Path) -> None:
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.25 0.5\nvt 0.75 0.5\n"
                                    "vt 0.25 1.0\nf 1/1 2/2 3/3\n")
    s = build(tmp_path, '[[objects]]\nshape = "mesh"\nfile = "t.obj"\nmaterial = "m"\n')
    np.testing.assert_allclose(s.uvs[0], [[0.25, 0.5], [0.75, 0.5], [0.25, 1.0]])
    (tmp_path / "m.obj").write_text(OBJ)
    s = build(tmp_path, '[[objects]]\nshape = "mesh"\nfile = "m.obj"\nmaterial = "m"\n')
    assert s.uvs.shape == (3, 3, 2) and not s.uvs.any()


def test_nan_uvs_are_a_user_error(tmp_path: Path) -> None:
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nvt nan 0.5\nvt 0.75 0.5\n"
                                    "vt 0.25 1.0\nf 1/1 2/2 3/3\n")
    with pytest.raises(UserError, match="not finite") as e:
        build(tmp_path, '[[objects]]\nshape = "mesh"\nfile = "t.obj"\nmaterial = "m"\n')
    assert e.value.key == "objects[0].file"


def test_textured_mesh_without_uvs_warns_once(tmp_path: Path, caplog) -> None:
    import OpenImageIO as oiio

    out = oiio.ImageOutput.create(str(tmp_path / "t.png"))
    out.open(str(tmp_path / "t.png"), oiio.ImageSpec(2, 2, 3, "uint8"))
    out.write_image(np.zeros((2, 2, 3), np.uint8))
    out.close()
    (tmp_path / "m.obj").write_text(OBJ)
    (tmp_path / "job.toml").write_text(
        '[[materials]]\nname = "t"\nbase_color_texture = "t.png"\n'
        + '[[objects]]\nshape = "mesh"\nfile = "m.obj"\nmaterial = "t"\n' * 2)
    with caplog.at_level(logging.WARNING, logger="relray"):
        scene.build_scene(job.load_job(tmp_path / "job.toml"))
    warnings = [r.getMessage() for r in caplog.records if "no texture coordinates" in
                r.getMessage()]
    assert len(warnings) == 1 and "objects[0]" in warnings[0]


PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\nproperty float y\n"
            "property float z\nproperty float s\nproperty float t\n")
PLY_VERTS = "0 0 0 0 0\n1 0 0 1 0\n1 1 0 1 1\n0 1 0 0 1\n0 0 1 0.5 0.5\n"


@pytest.mark.parametrize(("faces", "smooth"), [
    ("element face 2\nproperty list uchar int vertex_indices\nend_header\n"
     + PLY_VERTS + "3 0 1 2\n3 0 2 4\n", False),            # the PLY parser alone
    ("element face 2\nproperty list uchar int vertex_indices\nend_header\n"
     + PLY_VERTS + "3 0 1 2\n3 0 2 4\n", True),             # a Trimesh: vertex normals
    ("element face 1\nproperty list uchar int vertex_indices\nend_header\n"
     + PLY_VERTS + "4 0 1 2 3\n", False),                   # a quad: triangulated
])
def test_ply_read_fast_or_through_trimesh_gives_the_same_mesh(tmp_path: Path, faces, smooth):
    """_trimesh_arrays reads a triangle PLY with trimesh's parser alone and anything
    else through trimesh.load_mesh: the faces, vertices and UVs agree with load_mesh."""
    import trimesh
    path = tmp_path / "m.ply"
    path.write_text(PLY_HEAD + faces)
    f, v, n, uv = scene._trimesh_arrays(path, smooth)
    ref = trimesh.load_mesh(str(path), process=False)
    assert np.array_equal(f, ref.faces) and np.array_equal(v, ref.vertices)
    assert f.shape[1] == 3 and len(f) == 2
    assert np.allclose(uv, ref.visual.uv)
    assert (n is not None) == smooth
