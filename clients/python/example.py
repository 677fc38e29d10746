"""Plan from an image and its depth, then optimise a request file.

    cargo run --release -- serve &                 # the service with the shipped model
    cargo run --release -- serve --print-typical-request 1 > req.json
    python3 clients/python/example.py data/synth/targets/c0022_b00.json data/synth req.json

The first argument is a dataset record (`dpmp data generate` writes them):
its box, scene and image/depth paths (relative to the dataset folder, the
second argument) make the plan request (POST /v1/plan). The third is a
/v1/optimize request (a prior, obstacles, start, goal, ...; the line above
writes a typical one), which is then optimised (POST /v1/optimize).
DPMP_URL and DPMP_API_TOKEN pick the service and its token.
"""

import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from dpmp_client import Client, DpmpError  # noqa: E402


def summary(answer):
    """One line on an optimise or plan answer."""
    last = answer["trajectory"]["points"][-1]
    report = answer["report"]
    return (f"status {answer['status']}, {len(answer['trajectory']['points'])} points, "
            f"final q {[round(q, 3) for q in last['positions']]}, "
            f"min clearance {report.get('min_clearance_m')} m, "
            f"acceleration / jerk ratio {report.get('max_acceleration_ratio')} / {report.get('max_jerk_ratio')}")


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    record_path, dataset, request_path = sys.argv[1], sys.argv[2], sys.argv[3]
    with open(record_path) as f:
        record = json.load(f)
    with open(request_path) as f:
        request = json.load(f)
    dpmp = Client(os.environ.get("DPMP_URL", "http://127.0.0.1:8080"), os.environ.get("DPMP_API_TOKEN"))
    try:
        # 1. Plan: the network's prior for the berry in the box, then the optimiser.
        plan = dpmp.plan(
            os.path.join(dataset, record["image"]),
            record["box"],
            depth_path=os.path.join(dataset, record["depth"]) if record.get("depth") else None,
            mask_applied=True,
            obstacles=record["scene"]["obstacles"],
            clearance_m=0.02,
            boundary="rest",              # start and end at rest, as a Franka needs (the default)
            trajectory_format="ros2",     # trajectory_msgs/msg/JointTrajectory, ready to publish
        )
        print(f"plan: goal {plan.get('target', {}).get('goal')}, {summary(plan)}")
        # 2. Optimise: the Mahalanobis-closest feasible trajectory for the request's prior.
        optimized = dpmp.optimize(request)
        print(f"optimize: mahalanobis {optimized['mahalanobis']}, {summary(optimized)}")
    except DpmpError as e:
        if e.status is None:              # no answer: the service is down or unreachable
            sys.exit(str(e))
        sys.exit(f"refused: {e.code} ({e.field}): {e.message}")


if __name__ == "__main__":
    main()
