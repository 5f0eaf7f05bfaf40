"""Benchmarks: `python -m benchmarks.NAME [--json]` prints a table with a baseline from the same run."""
