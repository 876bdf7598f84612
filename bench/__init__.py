"""Benchmarks (not timed tests): each ``bench/bench_*.py`` module exposes ``main() -> dict``.

Run one with ``python -m bench.bench_<name>`` or all of them with ``python -m bench``.
"""
