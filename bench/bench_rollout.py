"""Benchmark: a full autonomous rollout of the 300 m^2 world (section 3.4), in process.

From an empty memory and an unknown map to the plan's `done` (or the keyframe budget): render
and detect every keyframe and inspection frame, decide and fold each one-frame batch, decide
every plan and inspection. Goal: the whole rollout under 5 minutes on this 2-core machine; the
planner's time per decision is reported beside it (goal < 50 ms on a 20 m x 20 m map at 5 cm).
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from bench.perf_common import write_results
from bench.records import RolloutBenchResult
from sim import SCENARIOS_DIR
from sim.memories import InProcessMemory
from sim.rollout import rollout
from sim.scenario import load_scenario

WORLD = SCENARIOS_DIR / "active" / "floor.yaml"


def main(argv: list[str] | None = None) -> None:
    """Time one rollout and print the figures."""
    parser = argparse.ArgumentParser(description=main.__doc__)
    parser.add_argument("--scenario", type=Path, default=WORLD)
    parser.add_argument("--seed", type=int, default=7)
    arguments = parser.parse_args(argv)
    scenario = load_scenario(arguments.scenario)
    memory = InProcessMemory(scenario.name)
    result = rollout(scenario, arguments.seed, memory)
    plan_ms = sorted(result.plan_ms)
    p90 = plan_ms[min(len(plan_ms) - 1, int(0.9 * len(plan_ms)))]
    area = scenario.room_size[0] * scenario.room_size[1]
    figures = RolloutBenchResult(
        scenario=scenario.name,
        area_m2=area,
        seed=arguments.seed,
        rollout_s=round(result.seconds, 2),
        goal_rollout_s=300,
        keyframes=len(result.keyframes),
        inspections=len(result.captures),
        path_m=round(result.path_length_m, 1),
        decisions=len(plan_ms),
        planner_ms_median=round(statistics.median(plan_ms), 2),
        planner_ms_p90=round(p90, 2),
        planner_ms_max=round(plan_ms[-1], 2),
        goal_planner_ms=50,
        stop_reason=result.stop_reason,
    )
    print(
        f"{scenario.name} ({area:.0f} m^2), seed {arguments.seed}: rollout {result.seconds:.1f} s "
        f"(goal < 300 s): {len(result.keyframes)} keyframes, {len(result.captures)} inspections, "
        f"path {result.path_length_m:.0f} m; planner per decision: median "
        f"{figures.planner_ms_median} ms, p90 {figures.planner_ms_p90} ms, max "
        f"{figures.planner_ms_max} ms over {len(plan_ms)} decisions (goal < 50 ms)"
    )
    write_results("bench_rollout", figures)


if __name__ == "__main__":
    main()
