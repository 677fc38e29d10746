"""Plan from an image and its depth, then optimise a request file.

    cargo run --release -- serve &                 # the service with the shipped model
    python3 clients/python/example.py data/synth/targets/c0022_b00.json data/synth

The first argument is a dataset record (`dpmp data generate` writes them):
its box, scene and image/depth paths (relative to the dataset folder, the
second argument) make the plan request.
"""

import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from dpmp_client import Client, DpmpError  # noqa: E402


def main():
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    record_path, dataset = sys.argv[1], sys.argv[2]
    with open(record_path) as f:
        record = json.load(f)
    dpmp = Client(os.environ.get("DPMP_URL", "http://127.0.0.1:8080"), os.environ.get("DPMP_API_TOKEN"))
    try:
        answer = dpmp.plan(
            os.path.join(dataset, record["image"]),
            record["box"],
            depth_path=os.path.join(dataset, record["depth"]) if record.get("depth") else None,
            mask_applied=True,
            obstacles=record["scene"]["obstacles"],
            clearance_m=0.02,
            boundary="rest",              # start and end at rest, as a Franka needs (the default)
            trajectory_format="ros2",     # trajectory_msgs/msg/JointTrajectory, ready to publish
        )
    except DpmpError as e:
        sys.exit(f"refused: {e.code} ({e.field}): {e.message}")
    last = answer["trajectory"]["points"][-1]
    report = answer["report"]
    print(f"status {answer['status']}, {len(answer['trajectory']['points'])} points, "
          f"goal {answer.get('target', {}).get('goal')}, final q {[round(q, 3) for q in last['positions']]}, "
          f"acceleration / jerk ratio {report.get('max_acceleration_ratio')} / {report.get('max_jerk_ratio')}")


if __name__ == "__main__":
    main()
