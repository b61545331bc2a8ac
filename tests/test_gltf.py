"""glTF import: files built in the test with pygltflib (an independent writer) and trimesh."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pygltflib as g
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation
from stress_config import STRESS

from relray.core.errors import UserError
from relray.core.scene import geometry as scene
from relray.core.scene import gltf, job, motion

C = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])  # (x, y, z) -> (x, -z, y)


class GlbBuilder:
    """Accumulates arrays into one binary buffer and makes accessors for them."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.accessors: list[g.Accessor] = []
        self.views: list[g.BufferView] = []

    def add(self, array: np.ndarray, component: int, kind: str) -> int:
        while len(self.blob) % 4:
            self.blob += b"\0"
        data = np.ascontiguousarray(array).tobytes()
        self.views.append(g.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data)))
        self.blob += data
        count = len(array)
        self.accessors.append(
            g.Accessor(bufferView=len(self.views) - 1, componentType=component, count=count,
                       type=kind)
        )
        return len(self.accessors) - 1

    def finish(self, gl: g.GLTF2, path: Path) -> Path:
        gl.accessors = self.accessors
        gl.bufferViews = self.views
        gl.buffers = [g.Buffer(byteLength=len(self.blob))]
        gl.set_binary_blob(bytes(self.blob))
        gl.save(str(path))
        return path


QUAD_POS = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], np.float32)
QUAD_IDX = np.array([0, 1, 2, 0, 2, 3], np.uint16)
QUAD_NRM = np.tile(np.array([0, 0, 1], np.float32), (4, 1))

ROOT_T = [1.0, 2.0, 3.0]
ROOT_Q = Rotation.from_euler("y", 90, degrees=True).as_quat().tolist()  # x, y, z, w
CHILD_S = [2.0, 2.0, 2.0]
LIGHT_Q = Rotation.from_euler("x", -90, degrees=True).as_quat().tolist()  # -Z -> -Y (down)
SPOT_CD = 100.0


def build_test_glb(path: Path) -> Path:
    """A quad under a two-level node hierarchy, a material with extensions, a second
    primitive without material, three punctual lights and a perspective camera."""
    b = GlbBuilder()
    pos = b.add(QUAD_POS, g.FLOAT, g.VEC3)
    nrm = b.add(QUAD_NRM, g.FLOAT, g.VEC3)
    idx = b.add(QUAD_IDX, g.UNSIGNED_SHORT, g.SCALAR)
    tri_pos = b.add(np.array([[0, 0, 0], [0, 0, 1], [0, 1, 0]], np.float32), g.FLOAT, g.VEC3)
    material = g.Material(
        name="glowing",
        pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=[0.5, 0.25, 0.125, 1.0], metallicFactor=0.3, roughnessFactor=0.6
        ),
        emissiveFactor=[1.0, 0.5, 0.0],
        extensions={
            "KHR_materials_emissive_strength": {"emissiveStrength": 5.0},
            "KHR_materials_transmission": {"transmissionFactor": 0.7},
            "KHR_materials_ior": {"ior": 1.33},
        },
    )
    lights = [
        {"type": "spot", "intensity": SPOT_CD, "color": [1.0, 0.9, 0.8],
         "spot": {"outerConeAngle": math.pi / 6, "innerConeAngle": math.pi / 12}},
        {"type": "point", "intensity": 1000.0 * 683.0 / (4.0 * math.pi)},
        {"type": "directional", "intensity": 683.0 * 3.0},
    ]
    gl = g.GLTF2(
        scene=0,
        scenes=[g.Scene(nodes=[0, 2, 3, 4, 5])],
        nodes=[
            g.Node(translation=ROOT_T, rotation=ROOT_Q, children=[1]),
            g.Node(scale=CHILD_S, mesh=0),
            g.Node(translation=[0.0, 5.0, 0.0], rotation=LIGHT_Q,
                   extensions={"KHR_lights_punctual": {"light": 0}}),
            g.Node(translation=[0.0, 1.0, 5.0], camera=0),
            g.Node(translation=[3.0, 3.0, 3.0], extensions={"KHR_lights_punctual": {"light": 1}}),
            g.Node(rotation=LIGHT_Q, extensions={"KHR_lights_punctual": {"light": 2}}),
        ],
        meshes=[
            g.Mesh(primitives=[
                g.Primitive(attributes=g.Attributes(POSITION=pos, NORMAL=nrm), indices=idx,
                            material=0),
                g.Primitive(attributes=g.Attributes(POSITION=tri_pos)),
            ])
        ],
        materials=[material],
        cameras=[g.Camera(type="perspective",
                          perspective=g.Perspective(yfov=0.8, znear=0.1, aspectRatio=1.5))],
        extensions={"KHR_lights_punctual": {"lights": lights}},
        extensionsUsed=["KHR_lights_punctual", "KHR_materials_emissive_strength",
                        "KHR_materials_transmission", "KHR_materials_ior"],
    )
    return b.finish(gl, path)


def expected_world(points: np.ndarray) -> np.ndarray:
    """Root T·R, child S, then Y-up -> Z-up, computed independently with scipy."""
    p = np.asarray(points, float) * CHILD_S
    p = Rotation.from_quat(ROOT_Q).apply(p) + ROOT_T
    return p @ C.T


@pytest.fixture
def glb(tmp_path: Path) -> Path:
    return build_test_glb(tmp_path / "scene.glb")


def test_geometry_through_node_hierarchy(glb: Path) -> None:
    tris, normals, mids, mats, _, _ = gltf.load_gltf(glb)
    assert tris.shape == (3, 3, 3)
    want = expected_world(QUAD_POS)[QUAD_IDX.reshape(-1, 3)]
    np.testing.assert_allclose(tris[:2], want, atol=1e-6)
    # the quad's +z normal: rotated by R_y(90) to +x, then unchanged by the axis swap
    np.testing.assert_allclose(normals[:2], np.tile([1.0, 0.0, 0.0], (2, 3, 1)), atol=1e-6)
    # the primitive without normals gets its face normal
    face = np.cross(tris[2, 1] - tris[2, 0], tris[2, 2] - tris[2, 0])
    np.testing.assert_allclose(normals[2], np.tile(face / np.linalg.norm(face), (3, 1)))
    assert list(mids) == [0, 0, 1]
    assert mats[1] == gltf.DEFAULT_MATERIAL


def test_y_up_becomes_z_up() -> None:
    np.testing.assert_array_equal(gltf.Y_UP_TO_Z_UP @ [0, 1, 0], [0, 0, 1])
    np.testing.assert_array_equal(gltf.Y_UP_TO_Z_UP @ [0, 0, 1], [0, -1, 0])
    assert np.linalg.det(gltf.Y_UP_TO_Z_UP) == pytest.approx(1.0)


def test_materials(glb: Path) -> None:
    m = gltf.load_gltf(glb)[3][0]
    assert m.name == "glowing"
    assert m.base_color == pytest.approx((0.5, 0.25, 0.125))
    assert (m.metallic, m.roughness) == pytest.approx((0.3, 0.6))
    assert m.emission == pytest.approx((1.0, 0.5, 0.0))
    assert m.emission_strength == pytest.approx(5.0)
    assert m.transmission == pytest.approx(0.7)
    assert m.ior == pytest.approx(1.33)


def test_punctual_lights_blender_conversion(glb: Path) -> None:
    spot, point, sun = gltf.load_gltf(glb)[4]
    assert spot.type == "spot"
    np.testing.assert_allclose(spot.position, C @ [0, 5, 0])  # (0, 0, 5)
    np.testing.assert_allclose(spot.direction, [0, 0, -1], atol=1e-12)  # glTF -Y is down
    assert spot.power == pytest.approx(SPOT_CD * 4 * math.pi / 683)
    assert spot.spot_size == pytest.approx(math.pi / 3)
    assert spot.spot_blend == pytest.approx(0.5)
    np.testing.assert_allclose(spot.color, [1.0, 0.9, 0.8])
    assert point.type == "point" and point.power == pytest.approx(1000.0)
    np.testing.assert_allclose(point.position, C @ [3, 3, 3])
    assert sun.type == "sun" and sun.power == pytest.approx(3.0)  # W/m^2 from lux
    np.testing.assert_allclose(sun.direction, [0, 0, -1], atol=1e-12)


def test_camera(glb: Path) -> None:
    cam = gltf.load_gltf(glb)[5]
    np.testing.assert_allclose(cam.position, [0, -5, 1])
    np.testing.assert_allclose(cam.forward, [0, 1, 0], atol=1e-12)
    np.testing.assert_allclose(cam.rotation[:, 0], [1, 0, 0], atol=1e-12)  # right
    np.testing.assert_allclose(cam.rotation[:, 1], [0, 0, 1], atol=1e-12)  # up
    assert cam.fov == pytest.approx(math.degrees(0.8))
    assert gltf.find_camera(glb).fov == pytest.approx(cam.fov)


def test_gltf_with_data_uri_and_external_bin(glb: Path, tmp_path: Path) -> None:
    ref = gltf.load_gltf(glb)[0]
    for fmt, name in ((g.BufferFormat.DATAURI, "embedded.gltf"),
                      (g.BufferFormat.BINFILE, "external.gltf")):
        doc = g.GLTF2().load(str(glb))
        doc.convert_buffers(fmt)
        out = tmp_path / name
        if fmt == g.BufferFormat.BINFILE:
            doc.buffers[0].uri = "external.bin"
            (tmp_path / "external.bin").write_bytes(g.GLTF2().load(str(glb)).binary_blob())
        doc.save(str(out))
        np.testing.assert_allclose(gltf.load_gltf(out)[0], ref)


def test_trimesh_export_round_trip(tmp_path: Path) -> None:
    import trimesh

    box = trimesh.creation.box(extents=[1.0, 2.0, 3.0])
    sc = trimesh.Scene()
    transform = trimesh.transformations.rotation_matrix(0.3, [1, 1, 0])
    transform[:3, 3] = [0.5, -1.0, 2.0]
    sc.add_geometry(box, transform=transform)
    path = tmp_path / "box.glb"
    sc.export(str(path))
    tris = gltf.load_gltf(path)[0]
    want = (box.vertices @ transform[:3, :3].T + transform[:3, 3]) @ C.T
    assert tris.shape == (12, 3, 3)
    np.testing.assert_allclose(np.sort(tris.reshape(-1, 3), axis=0),
                               np.sort(want[box.faces].reshape(-1, 3), axis=0), atol=1e-5)


def test_strip_and_mirrored_node(tmp_path: Path) -> None:
    b = GlbBuilder()
    pos = b.add(QUAD_POS[[0, 1, 3, 2]], g.FLOAT, g.VEC3)  # a strip 0-1-3-2 covers the quad
    nrm = b.add(QUAD_NRM, g.FLOAT, g.VEC3)
    prim = g.Primitive(attributes=g.Attributes(POSITION=pos, NORMAL=nrm), mode=g.TRIANGLE_STRIP)
    gl = g.GLTF2(scene=0, scenes=[g.Scene(nodes=[0, 1])],
                 nodes=[g.Node(mesh=0), g.Node(mesh=0, scale=[1, 1, -1])],
                 meshes=[g.Mesh(primitives=[prim])])
    tris, normals, *_ = gltf.load_gltf(b.finish(gl, tmp_path / "strip.glb"))
    assert tris.shape == (4, 3, 3)
    geometric = np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])
    # winding agrees with the shading normal, also under the mirroring node
    assert np.all(np.einsum("ij,ij->i", geometric, normals[:, 0]) > 0)
    area = 0.5 * np.linalg.norm(geometric, axis=1)
    np.testing.assert_allclose(area, 0.5)


def test_interleaved_and_sparse_accessors(tmp_path: Path) -> None:
    interleaved = np.concatenate([QUAD_POS, QUAD_NRM], axis=1)  # stride 24: P P P N N N
    sparse_idx = np.array([2], np.uint16)
    sparse_val = np.array([[1.0, 1.0, 5.0]], np.float32)  # lift corner 2
    blob = interleaved.tobytes() + sparse_idx.tobytes() + b"\0\0" + sparse_val.tobytes()
    views = [
        g.BufferView(buffer=0, byteOffset=0, byteLength=96, byteStride=24),
        g.BufferView(buffer=0, byteOffset=96, byteLength=2),
        g.BufferView(buffer=0, byteOffset=100, byteLength=12),
    ]
    sparse = g.Sparse(
        count=1,
        indices=g.AccessorSparseIndices(bufferView=1, componentType=g.UNSIGNED_SHORT),
        values=g.AccessorSparseValues(bufferView=2),
    )
    accessors = [
        g.Accessor(bufferView=0, byteOffset=0, componentType=g.FLOAT, count=4, type=g.VEC3,
                   sparse=sparse),
        g.Accessor(bufferView=0, byteOffset=12, componentType=g.FLOAT, count=4, type=g.VEC3),
    ]
    prim = g.Primitive(attributes=g.Attributes(POSITION=0, NORMAL=1), mode=g.TRIANGLE_FAN)
    gl = g.GLTF2(scene=0, scenes=[g.Scene(nodes=[0])], nodes=[g.Node(mesh=0)],
                 meshes=[g.Mesh(primitives=[prim])], accessors=accessors, bufferViews=views,
                 buffers=[g.Buffer(byteLength=len(blob))])
    gl.set_binary_blob(blob)
    gl.save(str(tmp_path / "interleaved.glb"))
    tris, normals, *_ = gltf.load_gltf(tmp_path / "interleaved.glb")
    pos = QUAD_POS.astype(float).copy()
    pos[2] = [1.0, 1.0, 5.0]
    fan = [[1, 2, 0], [2, 3, 0]]  # glTF fan: (v[i+1], v[i+2], v[0])
    np.testing.assert_allclose(tris, (pos @ C.T)[fan])
    np.testing.assert_allclose(normals, np.tile(C @ [0, 0, 1], (2, 3, 1)))


def test_scene_from_gltf_plus_objects(glb: Path, tmp_path: Path) -> None:
    (tmp_path / "job.toml").write_text(
        '[scene]\nfile = "scene.glb"\n[[materials]]\nname = "red"\nbase_color = [1, 0, 0]\n'
        '[[objects]]\nshape = "box"\ncenter = [0, 0, 0]\nsize = 1\nmaterial = "red"\n'
    )
    j = job.load_job(tmp_path / "job.toml")
    assert j.camera is None  # the glTF supplies it
    s = scene.build_scene(j)
    assert s.camera is not None and s.camera.fov == pytest.approx(math.degrees(0.8))
    assert [m.name for m in s.materials] == ["glowing", "gltf_default", "red"]
    assert list(s.material_ids) == [0, 0, 1] + [2] * 12
    assert [light.type for light in s.lights] == ["spot", "point", "sun"]
    assert s.normals is not None and s.normals.shape == (15, 3, 3)


def test_job_camera_kept_when_gltf_has_none(tmp_path: Path) -> None:
    b = GlbBuilder()
    pos = b.add(QUAD_POS, g.FLOAT, g.VEC3)
    gl = g.GLTF2(scene=0, scenes=[g.Scene(nodes=[0])], nodes=[g.Node(mesh=0)],
                 meshes=[g.Mesh(primitives=[g.Primitive(attributes=g.Attributes(POSITION=pos),
                                                        mode=g.TRIANGLE_FAN)])])
    b.finish(gl, tmp_path / "nocam.glb")
    (tmp_path / "job.toml").write_text('[scene]\nfile = "nocam.glb"\n')
    j = job.load_job(tmp_path / "job.toml")
    assert j.camera is not None
    np.testing.assert_allclose(j.camera.position, [0, -3.9, 1])
    assert scene.build_scene(j).triangles.shape == (2, 3, 3)


def test_mesh_object_from_glb(glb: Path, tmp_path: Path) -> None:
    (tmp_path / "job.toml").write_text(
        '[[materials]]\nname = "m"\n[[objects]]\nshape = "mesh"\nfile = "scene.glb"\n'
        'translate = [10, 0, 0]\nmaterial = "m"\n'
    )
    s = scene.build_scene(job.load_job(tmp_path / "job.toml"))
    ref = gltf.load_gltf(glb)[0]
    np.testing.assert_allclose(s.triangles, ref + [10, 0, 0], atol=1e-5)
    assert list(s.material_ids) == [0, 0, 0]


def _corrupt_variants(glb: Path) -> dict[str, bytes]:
    raw = glb.read_bytes()
    doc = g.GLTF2().load(str(glb))
    doc.accessors[0].count = 10_000  # reads past its buffer view
    bad_accessor = b"".join(doc.save_to_bytes())
    return {
        "truncated": raw[: len(raw) // 2],
        "header only": raw[:12],
        "empty": b"",
        "garbage": b"glTF\x02\x00\x00\x00" + bytes(range(256)),
        "not json": b"{ this is not json",
        "bad accessor": bad_accessor,
        "no asset": b'{"meshes": []}',
    }


@pytest.mark.parametrize("variant", ["truncated", "header only", "empty", "garbage", "not json",
                                     "bad accessor", "no asset"])
def test_corrupt_file_is_a_user_error(glb: Path, tmp_path: Path, variant: str) -> None:
    bad = tmp_path / "bad.glb"
    bad.write_bytes(_corrupt_variants(glb)[variant])
    (tmp_path / "job.toml").write_text('[camera]\n[scene]\nfile = "bad.glb"\n')
    with pytest.raises(UserError) as err:
        scene.build_scene(job.load_job(tmp_path / "job.toml"))
    assert err.value.key == "scene.file"
    assert str(tmp_path / "job.toml") in str(err.value)
    assert "bad.glb" in str(err.value)


def test_corrupt_file_caught_while_loading_the_job(glb: Path, tmp_path: Path) -> None:
    bad = tmp_path / "bad.glb"
    bad.write_bytes(glb.read_bytes()[:40])
    (tmp_path / "job.toml").write_text('[scene]\nfile = "bad.glb"\n')  # no [camera]: peeks
    with pytest.raises(UserError) as err:
        job.load_job(tmp_path / "job.toml")
    assert err.value.key == "scene.file"


def test_job_with_the_gltf_camera_renders(glb: Path, tmp_path: Path) -> None:
    """Without [camera] the glTF's camera places the shutter events and renders the frame."""
    from relray.core import cli

    (tmp_path / "job.toml").write_text(
        '[render]\nwidth = 8\nheight = 6\nspp = 1\n[motion]\nbeta = [0.5, 0, 0]\nct = 1\n'
        '[scene]\nfile = "scene.glb"\n')
    j = job.load_job(tmp_path / "job.toml")
    cam = motion.camera_settings(j)
    (_, event), = motion.frame_events(j)
    np.testing.assert_allclose(event.x, cam.position + np.array([0.5, 0, 0]) / math.sqrt(0.75))
    assert cli.main(["render", str(tmp_path / "job.toml"), "--quiet"]) == 0
    assert (tmp_path / "out" / "frame_0001.exr").is_file()


# ----------------------------------------------------------------- hostile documents
# Hand-written .gltf JSON (data-URI buffer), each broken in one way an attacker or a
# buggy exporter would: every case is one UserError naming scene.file, fast.

def tri_doc(n_nodes: int = 1) -> dict:
    """One triangle (3 float32 vertices, 36 bytes) in a data URI, one node per mesh use."""
    import base64

    data = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32).tobytes()
    return {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": 36, "uri": "data:application/octet-stream;base64,"
                     + base64.b64encode(data).decode()}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3"}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}],
        "nodes": [{"mesh": 0} for _ in range(n_nodes)],
        "scenes": [{"nodes": list(range(n_nodes))}],
    }


def load_doc(tmp_path: Path, doc: dict | str) -> tuple:
    import json

    path = tmp_path / "s.gltf"
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return gltf.load_gltf(path, job_file=tmp_path / "job.toml")


def test_hand_written_document_loads(tmp_path: Path) -> None:
    """The base of the hostile cases is valid (so each case below fails for its own fault)."""
    triangles, *_ = load_doc(tmp_path, tri_doc())
    assert triangles.shape == (1, 3, 3)


def test_shared_children_dag_is_refused_quickly(tmp_path: Path) -> None:
    """40 levels of two nodes each pointing at both nodes of the next level: 2^40 paths
    if walked naively. glTF requires a forest, so the shared child is refused, at once."""
    import time

    doc = tri_doc(0)
    levels = 40
    nodes = []
    for lv in range(levels):
        nxt = [2 * (lv + 1), 2 * (lv + 1) + 1] if lv < levels - 1 else []
        nodes += [{"children": nxt, "mesh": 0}, {"children": nxt}]
    doc["nodes"], doc["scenes"] = nodes, [{"nodes": [0, 1]}]
    t0 = time.perf_counter()
    with pytest.raises(UserError, match=r"scene\.file.*reached twice.*trees"):
        load_doc(tmp_path, doc)
    with pytest.raises(UserError, match="reached twice"):
        gltf.find_camera(tmp_path / "s.gltf")
    assert time.perf_counter() - t0 < 10.0  # exponential would be hours; linear is ms


@pytest.mark.parametrize("case", [
    "cycle", "repeated root", "negative child", "float child", "negative mesh index",
    "negative accessor byteOffset", "negative view byteOffset", "Infinity count",
    "NaN factor", "huge count digits", "1e400 coordinate", "bool componentType",
    "bad accessor type", "string byteLength", "sparse count beyond count",
    "buffer index out of range", "coordinate 1e30", "deep nesting",
])
def test_hostile_document_is_one_user_error(tmp_path: Path, case: str) -> None:
    import base64
    import json

    doc = tri_doc(2)
    doc["scenes"] = [{"nodes": [0]}]
    doc["nodes"][0]["children"] = [1]
    text = None
    if case == "cycle":
        doc["nodes"][1]["children"] = [0]
    elif case == "repeated root":
        doc["scenes"] = [{"nodes": [0, 0]}]
    elif case == "negative child":
        doc["nodes"][0]["children"] = [-1]
    elif case == "float child":
        doc["nodes"][0]["children"] = [1.0]
    elif case == "negative mesh index":
        doc["nodes"][0]["mesh"] = -1
    elif case == "negative accessor byteOffset":
        doc["bufferViews"][0]["byteOffset"] = 12
        doc["bufferViews"][0]["byteLength"] = 24
        doc["accessors"][0]["byteOffset"] = -12
        doc["accessors"][0]["count"] = 2
    elif case == "negative view byteOffset":
        doc["bufferViews"][0]["byteOffset"] = -4
    elif case == "Infinity count":
        text = json.dumps(doc).replace('"count": 3', '"count": Infinity')
    elif case == "NaN factor":
        doc["materials"] = [{"pbrMetallicRoughness": {"metallicFactor": 0.5}}]
        doc["meshes"][0]["primitives"][0]["material"] = 0
        text = json.dumps(doc).replace('"metallicFactor": 0.5', '"metallicFactor": NaN')
    elif case == "huge count digits":
        text = json.dumps(doc).replace('"count": 3', '"count": ' + "9" * 5000)
    elif case == "1e400 coordinate":
        doc["nodes"][0]["translation"] = [0, 0, 0]
        text = json.dumps(doc).replace('"translation": [0, 0, 0]', '"translation": [1e400, 0, 0]')
    elif case == "bool componentType":
        doc["accessors"][0]["componentType"] = True
    elif case == "bad accessor type":
        doc["accessors"][0]["type"] = "VEC7"
    elif case == "string byteLength":
        doc["bufferViews"][0]["byteLength"] = "36"
    elif case == "sparse count beyond count":
        doc["accessors"][0]["sparse"] = {"count": 4, "indices": {"bufferView": 0,
                                         "componentType": 5125}, "values": {"bufferView": 0}}
    elif case == "buffer index out of range":
        doc["bufferViews"][0]["buffer"] = 1
    elif case == "coordinate 1e30":
        data = np.array([[0, 0, 0], [1, 0, 0], [1e30, 1, 0]], np.float32).tobytes()
        doc["buffers"][0]["uri"] = ("data:application/octet-stream;base64,"
                                    + base64.b64encode(data).decode())
    elif case == "deep nesting":
        text = json.dumps(doc)[:-1] + ', "extras": ' + "[" * 100000 + "]" * 100000 + "}"
    with pytest.raises(UserError) as err:
        load_doc(tmp_path, text if text is not None else doc)
    message = str(err.value)
    assert err.value.key == "scene.file" and "\n" not in message
    assert "s.gltf" in message


def test_buffer_uri_that_is_a_fifo_is_refused_without_waiting(tmp_path: Path) -> None:
    import json
    import os

    doc = tri_doc()
    doc["buffers"][0]["uri"] = "pipe.bin"
    os.mkfifo(tmp_path / "pipe.bin")
    (tmp_path / "s.gltf").write_text(json.dumps(doc))
    with pytest.raises(UserError, match="buffers\\[0\\].*not a regular file"):
        gltf.load_gltf(tmp_path / "s.gltf")


def test_buffer_uri_that_is_a_device_or_folder_is_refused(tmp_path: Path) -> None:
    import json

    doc = tri_doc()
    for uri, why in (("/dev/zero", "not a regular file"), (".", "directory")):
        doc["buffers"][0]["uri"] = uri
        (tmp_path / "s.gltf").write_text(json.dumps(doc))
        with pytest.raises(UserError, match=why):
            gltf.load_gltf(tmp_path / "s.gltf")


# A fuzzer over the hand-written document: any field replaced by a hostile value must
# load or be one UserError naming scene.file, never another exception, never a hang.

_PATHS = [("buffers", 0, "byteLength"), ("bufferViews", 0, "buffer"),
          ("bufferViews", 0, "byteOffset"), ("bufferViews", 0, "byteLength"),
          ("bufferViews", 0, "byteStride"), ("accessors", 0, "bufferView"),
          ("accessors", 0, "byteOffset"), ("accessors", 0, "componentType"),
          ("accessors", 0, "count"), ("accessors", 0, "type"), ("nodes", 0, "mesh"),
          ("nodes", 0, "children"), ("nodes", 0, "matrix"), ("nodes", 0, "scale"),
          ("scenes", 0, "nodes"), ("meshes", 0, "primitives"), ("nodes", 0, "camera")]
_HOSTILE = st.one_of(st.integers(-2**70, 2**70), st.floats(allow_nan=False),
                     st.booleans(), st.none(), st.text(max_size=4),
                     st.lists(st.integers(-3, 3), max_size=17), st.just({}))


def _fuzz_one(tmp_path: Path, edits: list) -> None:
    doc = tri_doc(2)
    doc["scenes"] = [{"nodes": [0]}]
    doc["nodes"][0]["children"] = [1]
    for (table, index, key), value in edits:
        doc[table][index][key] = value
    try:
        load_doc(tmp_path, doc)
    except UserError as e:
        assert e.key == "scene.file" and "\n" not in str(e)


_fuzz = given(edits=st.lists(st.tuples(st.sampled_from(_PATHS), _HOSTILE), min_size=1,
                             max_size=3))


@settings(max_examples=80, deadline=None)
@_fuzz
def test_fuzzed_documents_are_loaded_or_refused(tmp_path_factory, edits) -> None:
    _fuzz_one(tmp_path_factory.mktemp("g"), edits)


@pytest.mark.stress
@pytest.mark.skipif(not STRESS, reason="make stress: RELRAY_STRESS=1")
@settings(max_examples=3000, deadline=None)
@_fuzz
def test_fuzzed_documents_are_loaded_or_refused_long(tmp_path_factory, edits) -> None:
    _fuzz_one(tmp_path_factory.mktemp("g"), edits)


# ------------------------------------------------------------ moving nodes (extras.relray)

def moving_doc(relray: dict | None, translation=(0.0, 0.0, -5.0)) -> dict:
    """Two nodes of the one-triangle mesh: node 0 static, node 1 with ``extras.relray``."""
    doc = tri_doc(2)
    doc["nodes"][1]["translation"] = list(translation)
    if relray is not None:
        doc["nodes"][1]["extras"] = {"relray": relray, "blender": "ignored"}
    return doc


def test_a_node_with_a_velocity_is_a_moving_object_in_z_up_axes(tmp_path: Path) -> None:
    """glTF's (x, y, z) velocity is relray's (x, -z, y), like a point; the pivot defaults
    to the node's world translation; the node's triangles are tagged with its motion."""
    import json

    path = tmp_path / "s.gltf"
    path.write_text(json.dumps(moving_doc({"velocity": [0.1, 0.2, 0.3]})))
    gl = gltf.load_gltf_scene(path)
    assert gl.tri_motion.tolist() == [-1, 0] and len(gl.motions) == 1
    m = gl.motions[0]
    np.testing.assert_allclose(m.velocity, [0.1, -0.3, 0.2])
    np.testing.assert_allclose(m.pivot, [0.0, 5.0, 0.0])
    assert m.worldline is None and m.where == "nodes[1]"
    assert len(gltf.load_gltf(path)) == 6  # the static reader's result is unchanged


def test_a_node_worldline_and_pivot_convert_axes(tmp_path: Path) -> None:
    import json

    path = tmp_path / "s.gltf"
    path.write_text(json.dumps(moving_doc(
        {"pivot": [1.0, 2.0, 3.0],
         "worldline": {"t": [0.0, 10.0], "pivot": [[0, 0, 0], [0, 0, -5.0]]}})))
    m = gltf.load_gltf_scene(path).motions[0]
    np.testing.assert_allclose(m.pivot, [1.0, -3.0, 2.0])
    np.testing.assert_allclose(m.worldline.pivot, [[0, 0, 0], [0, 5.0, 0]])
    np.testing.assert_allclose(m.worldline.t, [0.0, 10.0])


@pytest.mark.parametrize("relray", [
    None, {"velocity": [0, 0, 0]}, {"velocity": [0.1, 0.2, 0.3]},
    {"worldline": {"t": [0.0, 10.0], "pivot": [[0, 0, 0], [0, 0, -5.0]]}}])
def test_has_moving_nodes_agrees_with_the_loader(tmp_path: Path, relray) -> None:
    """gltf.has_moving_nodes (the JSON only) is True exactly when load_gltf_scene finds
    moving nodes; a malformed extras.relray is the loader's UserError."""
    import json

    path = tmp_path / "s.gltf"
    path.write_text(json.dumps(moving_doc(relray)))
    assert gltf.has_moving_nodes(path) == bool(gltf.load_gltf_scene(path).motions)
    path.write_text(json.dumps(moving_doc({"velocity": [2.0, 0.0, 0.0]})))
    with pytest.raises(UserError, match="velocity"):
        gltf.has_moving_nodes(path)


def test_a_zero_velocity_node_is_static(tmp_path: Path) -> None:
    import json

    path = tmp_path / "s.gltf"
    path.write_text(json.dumps(moving_doc({"velocity": [0, 0, 0]})))
    gl = gltf.load_gltf_scene(path)
    assert gl.motions == [] and gl.tri_motion.tolist() == [-1, -1]


@pytest.mark.parametrize(("relray", "words"), [
    ({"velocity": [0.8, 0.7, 0.0]}, "nodes[1].extras.relray.velocity: |velocity| = 1.06"),
    ({"velocity": [0.1, "x", 0.0]}, "velocity must be an array of 3 numbers"),
    ({"speed": 0.5}, "unknown key 'speed'"),
    ("fast", "nodes[1].extras.relray must be an object"),
    ({"velocity": [0.1, 0, 0], "worldline": {"t": [0, 1], "pivot": [[0, 0, 0], [0, 0, 0]]}},
     "either velocity or worldline"),
    ({"worldline": {"t": [0], "pivot": [[0, 0, 0]]}}, "at least 2 numbers"),
    ({"worldline": {"t": [0, 0], "pivot": [[0, 0, 0], [0, 0, 0]]}}, "strictly increasing"),
    ({"worldline": {"t": [0, 1, 2], "pivot": [[0, 0, 0], [0, 0, 0]]}}, "one position per time"),
    ({"worldline": {"t": [0, 1], "pivot": [[0, 0, 0], [2, 0, 0]]}}, "segment 0 moves at 2 c"),
    ({"pivot": [0, 1e20, 0]}, "pivot must be finite and within ±1e+15"),
])
def test_bad_node_motion_is_one_error_naming_scene_file(tmp_path: Path, relray, words) -> None:
    with pytest.raises(UserError) as err:
        load_doc(tmp_path, moving_doc(relray))
    assert err.value.key == "scene.file" and words in str(err.value), str(err.value)


def test_a_moving_gltf_node_renders_in_its_own_velocity_group(tmp_path: Path) -> None:
    """build_scene: the static node stays in the lab group, the moving one gets a group
    with its own velocity and its triangles in its rest frame (about its pivot)."""
    import json

    (tmp_path / "s.gltf").write_text(json.dumps(moving_doc({"velocity": [0.5, 0, 0]})))
    (tmp_path / "job.toml").write_text('[scene]\nfile = "s.gltf"\n')
    from relray.core.scene.geometry import build_scene

    scene = build_scene(job.load_job(tmp_path / "job.toml"))
    assert scene.n_static == 1 and len(scene.groups) == 1
    np.testing.assert_allclose(scene.groups[0].segments[0].u, [0.5, 0, 0])
    np.testing.assert_allclose(scene.groups[0].segments[0].p_ref, [0.0, 5.0, 0.0])
    # node 1's triangle at world (x, -z, y) = (.., 5, ..) sits about its pivot
    np.testing.assert_allclose(scene.triangles[1][:, 1], 0.0, atol=1e-12)


def _uv_quad(path: Path, uv: np.ndarray) -> Path:
    b = GlbBuilder()
    pos = b.add(QUAD_POS, g.FLOAT, g.VEC3)
    tex = b.add(uv.astype(np.float32), g.FLOAT, g.VEC2)
    idx = b.add(QUAD_IDX, g.UNSIGNED_SHORT, g.SCALAR)
    gl = g.GLTF2(scene=0, scenes=[g.Scene(nodes=[0])], nodes=[g.Node(mesh=0)],
                 meshes=[g.Mesh(primitives=[g.Primitive(
                     attributes=g.Attributes(POSITION=pos, TEXCOORD_0=tex), indices=idx)])])
    return b.finish(gl, path)


def test_texcoord_0_is_read_with_v_flipped(tmp_path):
    """glTF's UV origin is the image's top-left; relray's (Blender's) its bottom-left."""
    uv = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 0.5], [0.0, 0.25]])
    s = gltf.load_gltf_scene(_uv_quad(tmp_path / "uv.glb", uv))
    want = np.stack([uv[:, 0], 1.0 - uv[:, 1]], axis=1)[QUAD_IDX.reshape(2, 3)]
    np.testing.assert_allclose(s.uvs, want)
    no_uv = gltf.load_gltf_scene(build_test_glb(tmp_path / "t.glb"))
    assert no_uv.uvs.shape == (len(no_uv.triangles), 3, 2) and not no_uv.uvs.any()


def test_nan_texcoord_is_a_user_error(tmp_path):
    uv = np.array([[0.0, 0.0], [np.nan, 0.0], [1.0, 0.5], [0.0, 0.25]])
    with pytest.raises(UserError, match="TEXCOORD_0 is not finite"):
        gltf.load_gltf_scene(_uv_quad(tmp_path / "nan.glb", uv), key="scene.file",
                             job_file=tmp_path / "job.toml")


def test_material_textures_factors_samplers_and_transform(tmp_path):
    """pbrMetallicRoughness textures (an embedded PNG in a bufferView), the sampler's wrap
    modes, KHR_texture_transform (in Blender's UV convention), the factors that multiply
    the textures, the metallicRoughness channels (G roughness, B metallic), the emissive
    and normal textures (external URI, normal scale)."""
    import OpenImageIO as oiio

    png = tmp_path / "e.png"
    out = oiio.ImageOutput.create(str(png))
    out.open(str(png), oiio.ImageSpec(2, 2, 3, "uint8"))
    out.write_image(np.zeros((2, 2, 3), np.uint8))
    out.close()
    b = GlbBuilder()
    pos = b.add(QUAD_POS, g.FLOAT, g.VEC3)
    idx = b.add(QUAD_IDX, g.UNSIGNED_SHORT, g.SCALAR)
    png_bytes = png.read_bytes()
    while len(b.blob) % 4:
        b.blob += b"\0"
    b.views.append(g.BufferView(buffer=0, byteOffset=len(b.blob), byteLength=len(png_bytes)))
    b.blob += png_bytes
    view = len(b.views) - 1
    transform = {"KHR_texture_transform": {"offset": [0.25, 0.5], "rotation": 0.0,
                                           "scale": [2.0, 3.0]}}
    mat = g.Material(
        pbrMetallicRoughness=g.PbrMetallicRoughness(
            baseColorFactor=[0.5, 0.25, 1.0, 1.0], metallicFactor=0.4, roughnessFactor=0.8,
            baseColorTexture=g.TextureInfo(index=0, extensions=transform),
            metallicRoughnessTexture=g.TextureInfo(index=0)),
        emissiveFactor=[1.0, 0.5, 0.25], emissiveTexture=g.TextureInfo(index=1),
        normalTexture=g.NormalMaterialTexture(index=1, scale=0.5), alphaMode="MASK",
        alphaCutoff=0.3)
    gl = g.GLTF2(scene=0, scenes=[g.Scene(nodes=[0])], nodes=[g.Node(mesh=0)],
                 meshes=[g.Mesh(primitives=[g.Primitive(attributes=g.Attributes(POSITION=pos),
                                                        indices=idx, material=0)])],
                 materials=[mat], samplers=[g.Sampler(wrapS=33648, wrapT=33071)],
                 textures=[g.Texture(source=0, sampler=0), g.Texture(source=1)],
                 images=[g.Image(bufferView=view, mimeType="image/png"), g.Image(uri="e.png")],
                 extensionsUsed=["KHR_texture_transform"])
    m = gltf.load_gltf_scene(b.finish(gl, tmp_path / "m.glb")).materials[0]
    base = m.base_color_texture
    assert base.file.read_bytes() == png_bytes and base.file.parent != tmp_path
    assert base.wrap == ("mirror", "clamp") and base.factor == (0.5, 0.25, 1.0, 1.0)
    # glTF: (u', v') = (2u + 0.25, 3v + 0.5); Blender's v = 1 - v_glTF on both sides:
    # v'_B = 1 - (3 (1 - v_B) + 0.5) = 3 v_B - 2.5
    np.testing.assert_allclose(base.uv, (2.0, 0.0, 0.25, 0.0, 3.0, -2.5), atol=1e-12)
    assert m.roughness_texture.channel == 1 and m.roughness_texture.factor == (0.8,) * 4
    assert m.metallic_texture.channel == 2 and m.metallic_texture.factor == (0.4,) * 4
    assert m.emission_texture.file == tmp_path / "e.png"
    assert m.emission_texture.factor == (1.0, 0.5, 0.25, 1.0) and m.emission_strength == 1.0
    assert m.normal_texture.wrap == ("repeat", "repeat") and m.normal_scale == 0.5
    assert m.alpha_mode == "mask" and m.alpha_cutoff == pytest.approx(0.3)
