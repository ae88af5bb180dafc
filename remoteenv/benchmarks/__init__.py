"""Benchmarks behind ``python -m remoteenv bench`` (agent side; they launch sims).

The modules here are the entry points: each has ``add_arguments(parser)`` for
its own options and ``run(args) -> int`` (``scaling`` and ``render_cost`` also
run as ``python -m remoteenv.benchmarks.<name>``). Their shared parts (the
anchors, a CPU hog, contenders in this process, transport floors, the
batched step's stage profile, timing and the report) are in
:mod:`remoteenv.benchmarks.harness`. They measure and print; they assert nothing.
"""
