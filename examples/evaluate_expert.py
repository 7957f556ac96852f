"""Evaluate the log-replay expert and a constant-velocity policy on shards, from Python.

    python examples/evaluate_expert.py /tmp/shards
"""

import sys

from vmax_sim.evaluation import evaluate, format_summary


def main(path: str) -> None:
    for policy in ("expert", "constant"):
        result = evaluate(policy, path, batch_size=8)
        print(format_summary(result.summary))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "runs/demo/shards")
