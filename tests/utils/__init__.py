"""Test helpers shared by the suites (factories, free ports, process control)."""
