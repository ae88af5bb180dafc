"""Benchmarks behind ``python -m remoteenv bench`` (agent side; they launch sims).

Each module has ``add_arguments(parser)`` for its own options and
``run(args) -> int``. They measure and print; they assert nothing.
"""
