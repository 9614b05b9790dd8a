"""Benchmarks: commands that print tables (``tools/bench.sh``). Never timed assertions."""
