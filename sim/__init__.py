"""The simulator: scenario files, a raycast world, a pinhole depth camera, a mask detector, a robot.

One render+detect loop (`sim.stream`) turns a scenario and a seed into frames, detections and
ground truth; the evaluation, the robot and the demo all read their batches from it.
"""

from pathlib import Path

# The shipped scenario files (package data). Importing this package loads nothing heavy, so the
# `pbdag eval` plugin can name them without pulling in open3d.
SCENARIOS_DIR = Path(__file__).resolve().parent / "scenarios"
DEMO_SCENARIO = SCENARIOS_DIR / "demo.yaml"  # the world `make demo` walks
