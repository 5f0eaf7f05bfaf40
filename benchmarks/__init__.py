"""Benchmarks: scripts that print figures side by side with a baseline, in one process."""
