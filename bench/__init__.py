"""relray's benchmark harness (issue 4): run time against error, throughput, skips, profile.

``make bench`` (full, tens of minutes) and ``make bench-quick`` (under 3 minutes) run
:mod:`relray.bench.run`, which writes ``bench/results/*.csv``, PNG plots and
``bench/RESULTS.md``.  Modules:

- :mod:`.common` — machine facts, timers, jobs, error metrics, CSV;
- :mod:`.throughput` — paths and rays per CPU-second, Embree's share, the stage profile,
  thread scaling, the heavy scene and the β sweep;
- :mod:`.convergence` — error against time, relray against Cycles, and adaptive sampling;
- :mod:`.cycles_anchor` — the Cycles side (a bpy subprocess, :mod:`.cycles_worker`);
- :mod:`.skips` — what a scene does not need, measured;
- :mod:`.report` — plots and RESULTS.md.

None of this runs in ``make test``; ``tests/test_bench.py`` only runs the smallest
configuration so the harness cannot rot.
"""
