"""The Mitsuba 3 side of the benchmark: a long-lived process in Mitsuba's own venv.

Run by :class:`relray.bench.mitsuba_peer.MitsubaWorker` as
``.cache/mitsuba-venv/bin/python bench/mitsuba_worker.py VARIANT`` (it imports only
``mitsuba``, ``drjit`` and numpy, never relray, so Dr.Jit's numpy and the core's never
meet).  One JSON command per line on stdin; one reply per command, a line starting with
``@@MITSUBA@@`` on the original stdout (Mitsuba's log goes to stderr):

- ``{"cmd": "setup", "scene": "scene.json"}`` loads the scene dict written by
  :func:`relray.bench.mitsuba_peer.scene_files` or :mod:`relray.bench.peer_scenes`
  (meshes as OBJ or PLY files, an envmap's EXR, paths relative to the spec; a
  ``to_world_matrix`` (4 × 4 rows) becomes the plugin's ``to_world``) and replies with
  ``load_s``, the wall seconds of loading it (reading the meshes, building the BVH);
- ``{"cmd": "render", "spp": 64, "seed": 0, "threads": 1, "max_depth": 8,
  "out": "img.npy"}`` renders (the scene's integrator with ``max_depth`` replaced), saves
  the linear Rec.709 image (float32 (h, w, 3), row 0 = top) and replies with ``wall``
  and ``cpu`` seconds of the render alone (the ``mi.render`` call and the copy of its
  tensor into numpy, which for the LLVM variant is where the kernel runs), the ``spp``
  actually taken (the sampler's own count) and the number of ``passes``;
- ``{"cmd": "quit"}``.

Large wavefronts are split into passes of at most ``MAX_LANES`` samples (the LLVM
variant runs all of a pass's samples as one wavefront); the passes' images are averaged.
"""

from __future__ import annotations

import json
import math
import os
import sys
import time

import numpy as np

MARK = "@@MITSUBA@@"
MAX_LANES = 1 << 24


def _reply_stream():
    """Keep the real stdout for replies; send everything else printed on fd 1 to stderr."""
    fd = os.dup(1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    return os.fdopen(fd, "w", buffering=1)


def load(mi, spec_file: str):
    """The scene of a JSON spec: Mitsuba's scene dict with the camera's look-at given as
    ``origin``/``target``/``up`` (turned into a transform here) and the meshes' paths
    relative to the spec."""
    with open(spec_file) as f:
        spec = json.load(f)
    base = os.path.dirname(os.path.abspath(spec_file))
    sensor = spec["sensor"]
    look = sensor.pop("look_at")
    sensor["to_world"] = mi.ScalarTransform4f().look_at(origin=look["origin"],
                                                        target=look["target"],
                                                        up=look["up"])
    for v in spec.values():
        if isinstance(v, dict) and "filename" in v:  # obj, ply and envmap files
            v["filename"] = os.path.join(base, v["filename"])
        if isinstance(v, dict) and "to_world_matrix" in v:  # e.g. the envmap's frame
            v["to_world"] = mi.ScalarTransform4f(v.pop("to_world_matrix"))
    return mi.load_dict(spec), spec["integrator"]


def render(mi, dr, scene, integrator, cmd: dict) -> dict:
    """Render with the command's settings; time the render alone (module docstring)."""
    spp = int(cmd["spp"])
    film = scene.sensors()[0].film()
    w, h = (int(x) for x in film.crop_size())
    sampler = scene.sensors()[0].sampler()
    dr.set_thread_count(int(cmd.get("threads", 1)))
    passes = max(1, math.ceil(spp * w * h / MAX_LANES))
    while spp % passes:
        passes += 1
    per = spp // passes
    acc = np.zeros((h, w, 3), np.float64)
    c0, t0 = time.process_time(), time.perf_counter()
    for k in range(passes):
        img = mi.render(scene, integrator=integrator, spp=per,
                        seed=int(cmd.get("seed", 0)) * 1009 + k)
        acc += np.array(img, dtype=np.float64)[..., :3]
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    probe = sampler.clone()
    probe.set_sample_count(per)
    taken = int(probe.sample_count()) * passes
    np.save(cmd["out"], (acc / passes).astype(np.float32))
    return {"wall": wall, "cpu": cpu, "spp": taken, "passes": passes}


def main() -> None:
    """The command loop (see the module docstring)."""
    here = os.path.dirname(os.path.abspath(__file__))
    sys.path[:] = [p for p in sys.path if os.path.abspath(p or ".") != here]
    reply = _reply_stream()
    variant = sys.argv[1]
    try:
        import drjit as dr
        import mitsuba as mi

        mi.set_variant(variant)
    except Exception as e:  # report why (e.g. no libLLVM), then stop
        reply.write(f"{MARK} " + json.dumps({"error": f"{type(e).__name__}: {e}"}) + "\n")
        return
    reply.write(f"{MARK} " + json.dumps({"ready": True, "version": mi.__version__,
                                         "drjit": dr.__version__, "variant": variant})
                + "\n")
    scene, spec, integrators = None, None, {}
    for line in sys.stdin:
        cmd = json.loads(line)
        try:
            if cmd["cmd"] == "setup":
                t0 = time.perf_counter()
                scene, spec = load(mi, cmd["scene"])
                integrators = {}
                out = {"ok": True, "load_s": time.perf_counter() - t0}
            elif cmd["cmd"] == "render":
                depth = int(cmd.get("max_depth", spec["max_depth"]))
                if depth not in integrators:
                    integrators[depth] = mi.load_dict({**spec, "max_depth": depth})
                out = render(mi, dr, scene, integrators[depth], cmd)
            elif cmd["cmd"] == "quit":
                reply.write(f"{MARK} " + json.dumps({"bye": True}) + "\n")
                return
            else:
                out = {"error": f"unknown command {cmd['cmd']!r}"}
        except Exception as e:  # report, keep serving
            out = {"error": f"{type(e).__name__}: {e}"}
        reply.write(f"{MARK} " + json.dumps(out) + "\n")


if __name__ == "__main__":
    main()
