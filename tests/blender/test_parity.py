"""What artists already have in Cycles: warnings once, missing images, ignored features
named, renders that would not fit refused."""

from __future__ import annotations

import tomllib
from pathlib import Path

import bpy
import numpy as np
import pytest
import rendering
import scenes
from conftest import HOST, ext_module


def odd_material(folder) -> bpy.types.Material:
    """A Principled BSDF with an image on its base colour whose file has gone, anisotropy,
    a thin film and rough glass."""
    mat = scenes.principled("odd", (0.5, 0.5, 0.5))
    bsdf = mat.node_tree.nodes["Principled BSDF"]
    made = bpy.data.images.new("brick", 4, 4)
    path = folder / "brick.png"
    made.filepath_raw = str(path)
    made.file_format = "PNG"
    made.save()
    bpy.data.images.remove(made)
    img = bpy.data.images.load(str(path), check_existing=False)
    path.unlink()  # moved away after the .blend was set up
    img.reload()
    tex = mat.node_tree.nodes.new("ShaderNodeTexImage")
    tex.image = img
    mat.node_tree.links.new(tex.outputs["Color"], bsdf.inputs["Base Color"])
    bsdf.inputs["Anisotropic"].default_value = 0.5
    bsdf.inputs["Thin Film Thickness"].default_value = 300.0
    bsdf.inputs["Transmission Weight"].default_value = 1.0
    bsdf.inputs["Roughness"].default_value = 0.3
    return mat


def export_farm(folder: Path) -> dict:
    """Export the farm job to ``folder`` (the add-on's operator); its job.toml's table."""
    assert bpy.ops.relray.export_farm(directory=str(folder)) == {"FINISHED"}
    return tomllib.loads((folder / "job.toml").read_text())


def f12_and_farm_png(scene, folder: Path) -> tuple[np.ndarray, np.ndarray, dict]:
    """Frame 1 of ``scene`` as two 8-bit RGB PNGs: F12's, saved by Blender to
    ``folder``/f12_.png, and `relray render`'s of the farm job exported to
    ``folder``/farm (the same seed, so the same linear pixels); and that job's table."""
    rendering.set_output(scene, folder, "f12_", "PNG")
    scene.render.image_settings.color_mode = "RGB"
    rendering.render_still(scene, write=True)
    f12 = rendering.load_image(folder / "f12_.png")[..., :3]
    out = folder / "farm"
    job = export_farm(out)
    cli = ext_module("core.cli")
    assert cli.main(["render", str(out / "job.toml"), "--quiet", "--frames", "1-1"]) == 0
    return f12, rendering.load_image(out / "out" / "frame_0001.png")[..., :3], job


def test_a_missing_image_is_magenta_and_every_ignored_feature_named_once(cornell, engine,
                                                                         tmp_path, capsys):
    scene = cornell
    box = next(o for o in scene.objects if o.type == "MESH")
    box.data.materials.clear()
    box.data.materials.append(odd_material(tmp_path))
    scene.frame_start, scene.frame_end = 1, 3
    rendering.set_output(scene, tmp_path, "anim_", "PNG")
    rendering.render_animation(scene)
    out = capsys.readouterr().out
    warned = [line for line in out.splitlines() if line.startswith("relray: warning:")]
    for what in ("rendered magenta", "anisotropy", "thin film", "rough glass"):
        hits = [w for w in warned if what in w]
        assert len(hits) == 1, (what, warned)  # once per render, not once per frame
    assert "brick.png" in next(w for w in warned if "magenta" in w)
    export = ext_module("relblend.export")
    ex = export.export_scene(bpy.context.evaluated_depsgraph_get())
    odd = next(m for m in ex.scene.materials if m.name == "odd")
    assert odd.base_color == pytest.approx((1.0, 0.0, 1.0))


def test_a_render_that_would_not_fit_is_refused(cornell, engine, monkeypatch):
    """As `relray render` does: a clear error naming the memory, not a traceback and a
    blank image reported as finished."""
    resources = ext_module("core.resources")
    monkeypatch.setattr(resources, "memory_limit",
                        lambda *a: resources.MemoryLimit(1 << 20, "a test limit"))
    engine.RESULTS.clear()
    with pytest.raises(RuntimeError, match=r"would not fit in memory: needs about .* GiB "
                                           r"of memory .* a test limit"):
        rendering.render_still(cornell)
    assert not engine.RESULTS


def test_an_animation_reports_each_warning_once(cornell, engine, tmp_path, capsys):
    scene = cornell
    mat = scenes.principled("coat", (0.5, 0.5, 0.5))
    mat.node_tree.nodes["Principled BSDF"].inputs["Coat Weight"].default_value = 1.0
    box = next(o for o in scene.objects if o.type == "MESH")
    box.data.materials.clear()
    box.data.materials.append(mat)
    scene.frame_start, scene.frame_end = 1, 2
    rendering.set_output(scene, tmp_path, "anim_", "PNG")
    rendering.render_animation(scene)
    assert capsys.readouterr().out.count("relray: warning: material 'coat': coat") == 1
    rendering.render_still(scene)  # a new render job: warned again
    assert capsys.readouterr().out.count("relray: warning: material 'coat': coat") == 1
    assert np.isfinite(engine.RESULTS[scene.frame_current]["rgba"]).all()


def test_the_noise_threshold_stops_converged_pixels(cornell, engine, tmp_path):
    """Noise Threshold on (Cycles' adaptive sampling): Samples becomes a cap and pixels
    stop early, so fewer paths are traced than width × height × samples; the farm job
    carries the threshold."""
    scene = cornell
    scene.relray.samples = 256
    rendering.render_still(scene)
    full = engine.RESULTS[1]["paths"]
    assert full == 48 * 48 * 256
    scene.relray.use_adaptive_sampling = True
    scene.relray.adaptive_threshold = 0.2
    rendering.render_still(scene)
    assert engine.RESULTS[1]["paths"] < 0.8 * full
    job = export_farm(tmp_path / "farm")
    assert job["render"]["noise_threshold"] == pytest.approx(0.2)


def test_the_farm_png_goes_through_the_scenes_view_transform(cornell, engine, tmp_path):
    """With AgX (Blender's default view) and the view's exposure at +2 stops, the farm
    job's PNG is F12's PNG (the same seed: codes within 2 of 255 on average), where the
    plain sRGB curve of the job's exposure was not."""
    scene = cornell
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.exposure = 2.0
    f12, farm, job = f12_and_farm_png(scene, tmp_path)
    assert job["output"]["view_transform"]["view"] == "AgX"
    assert (tmp_path / "farm" / job["output"]["view_transform"]["config"]).is_file()
    assert np.abs(farm - f12).mean() * 255 < 2.0, np.abs(farm - f12).mean() * 255
    assert job["output"]["exposure"] == 2.0
    plain = rendering.srgb_encode(4.0 * engine.RESULTS[1]["rgba"][..., :3])
    assert np.abs(plain - f12).mean() * 255 > 5.0  # what the farm PNG was before


def s_curve(scene) -> None:
    """The view's curves: an S on the combined curve, a lifted red, black and white
    levels (Extend Extrapolated, Blender's default for the view's curves)."""
    vs = scene.view_settings
    vs.use_curve_mapping = True
    cm = vs.curve_mapping
    c = cm.curves[3]
    c.points.new(0.25, 0.12)
    c.points.new(0.75, 0.88)
    cm.curves[0].points.new(0.5, 0.6)
    cm.black_level = (0.01, 0.0, 0.0)
    cm.white_level = (1.0, 0.9, 1.2)
    cm.update()


def test_the_farm_png_carries_the_views_gamma_and_curves(cornell, engine, tmp_path):
    """AgX with gamma 1.6 and an S-curve: the farm job's PNG is F12's PNG (the same
    seed, so the same linear pixels) within 2 codes, where leaving the gamma and the
    curves out (what the farm did before) is far off."""
    scene = cornell
    scene.view_settings.view_transform = "AgX"
    scene.view_settings.gamma = 1.6
    s_curve(scene)
    scene.render.dither_intensity = 0.0  # Blender's PNG dither adds ±1 code of noise
    f12, farm, table = f12_and_farm_png(scene, tmp_path)
    out = tmp_path / "farm"
    view = table["output"]["view_transform"]
    assert view["gamma"] == pytest.approx(1.6) and len(view["curves"]["red"]) == 257
    warnings: list[str] = []
    ext_module("relblend.farm").colour_management(scene, tmp_path / "cm", warnings)
    assert warnings == []  # nothing left out any more
    diff = np.abs(farm - f12) * 255
    print(f"farm vs F12 with gamma and curves: mean {diff.mean():.3f}, max {diff.max():.0f} "
          "codes")
    assert diff.max() <= 2.0, (diff.mean(), diff.max())
    # leaving out the gamma, the curves or both (the farm's PNG before) is far off: the
    # farm's own linear pixels through the view without them
    from dataclasses import replace

    job = ext_module("core.scene.job").load_job(out / "job.toml")
    vt = job.output.view_transform
    imageio = ext_module("core.output.imageio")
    rgba = imageio.read_exr(out / "out" / "frame_0001.exr")[0]
    rgba = np.stack([rgba[c] for c in "RGBA"], axis=2)
    for without in (replace(vt, gamma=1.0, curves=None), replace(vt, gamma=1.0),
                    replace(vt, curves=None)):
        codes = imageio.display_codes(rgba, job.output.exposure, without, alpha=False)
        assert np.abs(codes[..., :3] / 255.0 - f12).max() * 255 > 20.0


@pytest.mark.parametrize("extend", ["EXTRAPOLATED", "HORIZONTAL"])
def test_the_baked_curves_are_blenders_on_a_ramp(ext, tmp_path, extend):
    """A ramp from below black to 10 × white (every branch: the tables, black and white
    levels per channel, channel and combined curves, the extension on both sides) through
    Blender's Standard view with curves, saved as a 16-bit PNG by Blender itself
    (Image.save_render, as F12's Save as Render), against the farm's 8-bit codes of the
    same pixels from the baked tables: within the 8-bit rounding (0.5 code) plus half a
    16-bit step."""
    scene = scenes.reset_scene()
    w = 256
    img = bpy.data.images.new("ramp", w, 1, float_buffer=True, alpha=False)
    vals = np.concatenate([np.linspace(-0.2, 1.2, 200), np.logspace(0.1, 1.0, 56)])
    px = np.ones((1, w, 4), np.float32)
    px[..., 0], px[..., 1], px[..., 2] = vals, 0.7 * vals, 0.4 * vals
    img.pixels.foreach_set(px.ravel())
    settings = scene.render.image_settings
    settings.file_format, settings.color_mode, settings.color_depth = "PNG", "RGB", "16"
    scene.render.dither_intensity = 0.0
    vs = scene.view_settings
    vs.view_transform = "Standard"
    vs.use_curve_mapping = True
    cm = vs.curve_mapping
    cm.curves[3].points.new(0.25, 0.1)
    cm.curves[3].points.new(0.75, 0.9)
    cm.curves[0].points[1].location = (1.0, 0.8)
    cm.curves[0].points.new(0.5, 0.6)
    cm.curves[1].points.new(0.3, 0.2)
    cm.black_level, cm.white_level = (0.05, 0.02, 0.0), (0.9, 1.1, 1.3)
    cm.extend = extend
    cm.update()
    img.save_render(str(tmp_path / "ramp.png"), scene=scene)
    import OpenImageIO as oiio  # noqa: N813

    blender = oiio.ImageBuf(str(tmp_path / "ramp.png")).get_pixels(oiio.FLOAT)[0, :, :3]
    warnings: list[str] = []
    t = ext_module("relblend.farm").baked_curves(cm, warnings)
    assert not warnings
    description = ext_module("core.scene.description")
    curves = description.DisplayCurves(
        tuple(t["black"]), tuple(t["white"]), tuple(map(tuple, t["ranges"])),
        (tuple(t["red"]), tuple(t["green"]), tuple(t["blue"])), tuple(map(tuple, t["slopes"])))
    config = Path(bpy.utils.system_resource("DATAFILES", path="colormanagement")) / "config.ocio"
    view = description.ViewTransform(config, "sRGB", "Standard", curves=curves)
    codes = ext_module("core.output.imageio").display_codes(px, 0.0, view, alpha=False)
    diff = np.abs(codes[0, :, :3] - 255.0 * blender)
    assert diff.max() <= 0.5 + 0.5 * 255 / 65535 + 1e-3, diff.max()
    assert (t["slopes"] != [[0.0, 0.0]] * 3) == (extend == "EXTRAPOLATED")
    plain = description.ViewTransform(config, "sRGB", "Standard")
    without = ext_module("core.output.imageio").display_codes(px, 0.0, plain, alpha=False)
    assert np.abs(without[0, :, :3] - 255.0 * blender).max() > 20.0  # the curves matter


def compositor_denoise(scene):
    """Render Layers → Denoise (Image, Normal, Albedo) → the compositor's output, in
    Blender 5.0's node-group compositor or the older scene node tree."""
    if hasattr(scene, "compositing_node_group"):  # Blender 5.0
        tree = bpy.data.node_groups.new("denoise", "CompositorNodeTree")
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        scene.compositing_node_group = tree
        out = tree.nodes.new("NodeGroupOutput")
        out_socket = out.inputs[0]
    else:
        scene.use_nodes = True
        tree = scene.node_tree
        for n in list(tree.nodes):
            tree.nodes.remove(n)
        out = tree.nodes.new("CompositorNodeComposite")
        out_socket = out.inputs["Image"]
    layers = tree.nodes.new("CompositorNodeRLayers")
    denoise = tree.nodes.new("CompositorNodeDenoise")
    tree.links.new(layers.outputs["Image"], denoise.inputs["Image"])
    tree.links.new(layers.outputs["Denoising Normal"], denoise.inputs["Normal"])
    tree.links.new(layers.outputs["Denoising Albedo"], denoise.inputs["Albedo"])
    tree.links.new(denoise.outputs["Image"], out_socket)


def test_denoising_passes_feed_the_compositors_denoise_node(cornell, engine, tmp_path):
    """Denoising Data: the albedo and normal passes reach the render result and the
    multilayer EXR, and the compositor's Denoise node (OpenImageDenoise) fed with them
    turns a 4-spp Cornell box into a smoother image than its input."""
    scene = cornell
    scene.relray.samples = 4
    layer = scene.view_layers[0]
    layer.relray.use_pass_denoising = True
    assert "Denoising Albedo" in rendering.registered_passes(scene)
    rendering.set_output(scene, tmp_path, "noisy", "EXR_MULTILAYER")
    rendering.render_still(scene, write=True)
    aovs = engine.RESULTS[1]["aovs"]
    assert aovs["albedo"].shape == (48, 48, 3) and aovs["normal"].shape == (48, 48, 3)
    channels = rendering.exr_channels(tmp_path / "noisy.exr")
    for ch in ("Denoising Albedo.R", "Denoising Albedo.B", "Denoising Normal.X",
               "Denoising Normal.Z"):
        assert f"{layer.name}.{ch}" in channels, channels
    noisy = engine.RESULTS[1]["rgba"][..., :3]
    compositor_denoise(scene)
    scene.render.use_compositing = True
    rendering.set_output(scene, tmp_path, "clean", "OPEN_EXR")
    scene.render.image_settings.color_depth = "32"
    rendering.render_still(scene, write=True)
    clean = rendering.load_image(tmp_path / "clean.exr")[..., :3]

    def roughness(img):  # mean |Laplacian| over the back wall (rows 8..20, cols 16..32)
        y = rendering.luminance(img[8:20, 16:32])
        return float(np.abs(4 * y[1:-1, 1:-1] - y[:-2, 1:-1] - y[2:, 1:-1] - y[1:-1, :-2]
                            - y[1:-1, 2:]).mean())

    assert abs(clean.mean() / noisy.mean() - 1.0) < 0.1
    # Debian's Blender 4.3 (make test-blender) is built without OpenImageDenoise: there
    # the node passes the image through; the bpy module (make test) has it and denoises.
    has_oidn = "OpenImageDenoise" in Path("/proc/self/maps").read_text()
    assert has_oidn or HOST == "blender", "the bpy module ships OpenImageDenoise"
    if has_oidn:
        assert roughness(clean) < 0.5 * roughness(noisy), (roughness(clean),
                                                           roughness(noisy))
