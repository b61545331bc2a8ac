"""Smoke test of the benchmark harness (bench/): the smallest configuration end to end.

No timing assertions: the benchmarks themselves run with ``make bench`` / ``make
bench-quick``, never in ``make test``.  This only keeps the harness from rotting when the
core's interfaces change.
"""

import math
from pathlib import Path

import numpy as np
import pytest

from relray.bench import (
    ab,
    common,
    convergence,
    cycles_anchor,
    profile_scenes,
    report,
    run,
    skips,
    throughput,
    wavelength_pdf,
)


def test_metrics_and_interpolation():
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.1, 0.9, (8, 8, 3))
    assert common.rel_mse(ref, ref) == 0.0
    assert common.mean_de00(ref, ref) == pytest.approx(0.0, abs=1e-9)
    noisy = ref * (1 + 0.1 * rng.standard_normal(ref.shape))
    # relative MSE does not depend on the exposure
    assert common.rel_mse(2 * noisy, 2 * ref) == pytest.approx(common.rel_mse(noisy, ref))
    # a power law e = t^-1 crosses 0.1 at t = 10, inside and outside the sampled range
    t, _ = common.time_at_error([1, 4, 16], [1, 0.25, 1 / 16], 0.1)
    assert t == pytest.approx(10.0)
    t, extrapolated = common.time_at_error([1, 4], [1, 0.25], 0.01)
    assert t == pytest.approx(100.0) and extrapolated
    assert cycles_anchor.cycles_bounces(8) == 6 and cycles_anchor.cycles_bounces(2) == 0


def test_ab_pairs_a_revision_with_this_checkout(tmp_path):
    """bench/ab.py: the paired ratio's median and quartiles; a revision unpacked from git
    is a package tree; one worker process renders a scene and reports CPU ns per path."""
    s = ab.paired_ratios([2.0, 3.0, 5.0, 4.0], [4.0, 4.0, 5.0, 2.0])
    assert s["median"] == pytest.approx(0.875) and s["pairs"] == 4
    assert s["q1"] <= s["median"] <= s["q3"]
    here = Path(ab.__file__).resolve().parents[1]
    tree = ab.unpack("HEAD", here, tmp_path / "rev")
    assert (tree / "core" / "render" / "integrator.py").is_file()
    ns = ab.ns_per_path(here, "cornell", 1, 8, 1, tmp_path / "scenes")
    assert 0.0 < ns < 1e9


def test_profile_scenes_builds_one_scene_by_name(tmp_path):
    """profile_scenes.scene_bench: only the asked scene's files are written; an unknown
    name is refused with the names it knows."""
    bench = profile_scenes.scene_bench("environment", tmp_path, 2000)
    assert (tmp_path / "profile_env" / "sky.exr").is_file()
    assert not (tmp_path / "profile_tex").exists()
    assert bench.render(spp=1, width=4, height=4, threads=1).cpu > 0.0
    with pytest.raises(ValueError, match="cornell, heavy"):
        profile_scenes.scene_bench("nowhere", tmp_path, 2000)


def test_toml_writer_round_trips_the_presets():
    import tomllib

    for path in (common.CORNELL, common.FLYBY):
        data = common.job_dict(path)
        assert tomllib.loads(common.to_toml(data)) == data


def test_stage_meter_restores_the_core():
    """The three integrators are metered: the Cornell box's SIMD lanes and whole paths
    (the kernels' rays counted from what they return) and the wavefront's stages; the
    core is restored."""
    from relray.core.render import accel, integrator, lane_paths, whole_paths
    from relray.core.render import frames as render

    def core():
        return (render.trace, integrator.shade, accel.Accel.intersect, accel.intersect_rays,
                whole_paths.trace, whole_paths.lambert_paths, lane_paths.trace,
                lane_paths.lane_trace)

    before = core()
    b = common.RelrayBench(common.make_job(common.job_dict(), width=8, height=8, spp=1))
    fr = b.renderer(threads=1)
    assert fr.whole_paths and fr.lane_paths
    with throughput.StageMeter() as m:
        b.render(renderer=fr)
    assert m.seconds["lane-path kernel"] > 0 and "whole-path kernel" not in m.seconds
    assert m.rays_by["lane-path kernel"] >= 64 + m.rays_by["lane-path shadow"] > 64
    fr.lane_paths = False
    with throughput.StageMeter() as m:
        b.render(renderer=fr)
    assert m.seconds["whole-path kernel"] > 0 and "shade" not in m.seconds
    assert m.rays_by["whole-path kernel"] >= 64 + m.rays_by["whole-path shadow"] > 64
    fr.whole_paths = False
    with throughput.StageMeter() as m:
        b.render(renderer=fr)
    assert m.rays > 0 and m.seconds["shade"] > 0
    assert m.rays_by["embree run intersect"] >= 64   # every camera ray, at least
    assert core() == before


def test_smoke_run_writes_csvs_plots_and_results(tmp_path):
    out = tmp_path / "results"
    md = tmp_path / "RESULTS.md"
    # Mitsuba is left out here (its own venv and JIT are for make bench): the section then
    # runs relray's side and says why the peers are missing
    run.run(run.SMOKE, out, md, use_cycles=cycles_anchor.bpy_available(), use_mitsuba=False,
            log=lambda *a: None)
    for name in ("throughput", "profile", "scaling", "heavy", "beta_sweep", "skips",
                 "velocity_groups", "convergence_medians", "equal_error", "adaptive_gain",
                 "shade_breakdown", "environment_nee", "profile_scenes", "velocity_group_pairs",
                 "embree_floor", "path_floor"):
        rows = common.read_csv(out / f"{name}.csv")
        assert rows, name
    tp = common.read_csv(out / "throughput.csv")[0]
    assert tp["paths"] == 16 * 16 * 2 and tp["rays"] >= tp["paths"]
    assert math.isfinite(tp["embree_share"])
    fl = common.read_csv(out / "embree_floor.csv")[0]
    # relray's C-API scene answers as embreex's: the same distances (and triangles, but
    # where two meet at the hit, either), the same occlusion
    assert fl["agree_t"] == 1.0 and fl["agree_prim"] > 0.99 and fl["agree_occluded"] == 1.0
    assert fl["embree_intersect_ns"] > 0 and fl["embreex_intersect_ns"] > 0
    # the whole-path kernel against the wavefront: the same paths' radiance, and Embree
    # alone on its rays costs less than the kernel around them
    floor = common.read_csv(out / "path_floor.csv")
    assert {pf["scene"] for pf in floor} == {"cornell", "heavy", "environment", "moving"}
    for pf in floor:
        assert pf["paths_differing"] <= 0.005 and pf["rays_per_path"] >= 1.0
        assert 0.0 < pf["embree_ns"] < pf["whole_ns"]
    assert (out / "convergence.png").exists() and (out / "profile.png").exists()
    text = md.read_text()
    assert "## Headline" in text and "## 6. Profile" in text and "## 5b. Moving" in text
    assert "## 5d. Environment maps" in text and "### Per scene" in text
    prof = common.read_csv(out / "profile_scenes.csv")
    assert {r["scene"] for r in prof} == {"cornell", "heavy", "environment", "textured",
                                         "moving"}
    # (the moving scene is Lambert, lit by a triangle: the SIMD lanes, its rest-frame
    # traversal inside the kernel)
    moving = {r["stage"]: r for r in prof if r["scene"] == "moving"}
    assert moving["lane-path kernel (16 paths in SIMD lanes, with its Embree packets)"][
        "seconds"] > 0.0
    assert moving["velocity groups: rest-frame rays with their Embree traversals"][
        "seconds"] == 0.0
    assert all(r["ns_per_path"] > 0.0 for r in prof if r["stage"] == "total")
    # the moving scene's rays are counted from its loops' ray arrays (the same paths as the
    # box's: about as many rays; a wrong argument index counted the RTCRayHit buffer)
    per_path = {r["scene"]: float(r["rays_per_path"]) for r in prof if r["stage"] == "total"}
    assert per_path["moving"] > 0.6 * per_path["cornell"]
    assert "### Mitsuba 3 as a peer" in text and "left out (--no-mitsuba)" in text
    assert {r["renderer"] for r in common.read_csv(out / "mitsuba_throughput.csv")} == \
        {"relray"}
    # the peer scenes: relray's side always runs
    assert "### The heavy, environment-lit, textured and moving scenes" in text
    peer_status = common.read_csv(out / "peer_status.csv")
    assert {(r["scene"], r["peer"]) for r in peer_status if r["ran"] == "False"} >= {
        (s, v) for s in ("heavy", "environment", "textured", "moving")
        for v in ("scalar_spectral", "llvm_ad_spectral")}
    peer_med = common.read_csv(out / "peer_medians.csv")
    assert {(r["scene"], r["series"]) for r in peer_med} >= {
        (s, "relray") for s in ("heavy", "environment", "textured", "moving")}
    assert (out / "peer_converged_moving.png").exists()
    assert {r["renderer"] for r in common.read_csv(out / "peer_load.csv")} == {"relray"}
    groups = {r["variant"]: r for r in common.read_csv(out / "velocity_groups.csv")}
    assert [groups[f"{n} groups"]["groups"] for n in (0, 1, 2, 4, 8)] == [0, 1, 2, 4, 8]
    assert groups["0 groups"]["over_static"] == 1.0
    # the report regenerates from the CSVs alone
    report.write(out, tmp_path / "again.md")
    assert "## 5. Skip" in (tmp_path / "again.md").read_text()
    skip_rows = {r["skip"]: r for r in common.read_csv(out / "skips.csv")}
    assert set(skips._variant_jobs(tmp_path / "skip_images")) <= set(skip_rows)
    for name in ("no velocity-group traversal without moving bodies",
                 "no texture fetch for untextured materials",
                 "no environment sampling without a map", "no star pass without stars"):
        assert skip_rows[name]["B_over_A"] > 0.0, name
    # B's environment map enters the NEE table: one light more than A
    env = skip_rows["no environment sampling without a map"]
    assert env["lights_B"] == env["lights_A"] + 1
    assert convergence.ConvergenceConfig().ref_spp == 16 * 256


def test_the_wavelength_pdf_comparison_swaps_in_mitsubas_pdf_for_its_block_only():
    """bench/wavelength_pdf.py: Mitsuba's sech² pdf on relray's bins (normalised, its
    peak at 538 nm), used by renderers built inside the block, relray's own after it."""
    from relray.core.physics import spectrum

    own = spectrum.make_sampler("cie1931")
    with wavelength_pdf.mitsuba_pdf():
        sech = spectrum.make_sampler("cie1931")
    widths = np.diff(sech.edges_nm)
    assert np.sum(sech.pdf * widths) == pytest.approx(1.0)
    mid = 0.5 * (sech.edges_nm[:-1] + sech.edges_nm[1:])
    assert abs(mid[np.argmax(sech.pdf)] - 538.0) <= 1.0
    assert not np.allclose(sech.pdf, own.pdf)
    np.testing.assert_array_equal(spectrum.make_sampler("cie1931").pdf, own.pdf)
