"""Inspection runs: viewpoint planning, the loop, pose, pick and sort, results."""
