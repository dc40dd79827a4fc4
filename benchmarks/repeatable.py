"""
Whether a run is repeatable: the same configuration and seed trained twice, side by side as two processes (one torch
thread each, so that the overlapped loop's two threads meet different timings), and a hash of each run's weights.

    python benchmarks/repeatable.py [--goal nightstand] [--mode kickstart] [--steps 6000]
"""

import argparse
import hashlib
import os
import subprocess
import sys
from pathlib import Path
from tempfile import TemporaryDirectory


def weights_hash(goal: str, mode: str, steps: int) -> str:
    """Train ``RunConfig(goal, mode, finish=False, steps)`` (the overlapped loop) and hash its policy's weights."""
    import torch as th

    from sb3_disagree.run import RunConfig, train

    th.set_num_threads(1)
    with TemporaryDirectory() as out:
        _, model, _ = train(RunConfig(goal=goal, mode=mode, finish=False, overlap=True, steps=steps), Path(out))
        data = b"".join(p.detach().cpu().numpy().tobytes() for p in model.policy.parameters())
    return hashlib.sha256(data).hexdigest()[:16]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--goal", default="nightstand")
    parser.add_argument("--mode", default="kickstart")
    parser.add_argument("--steps", type=int, default=6000)
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print(weights_hash(args.goal, args.mode, args.steps))
        return
    command = [sys.executable, __file__, "--child", "--goal", args.goal, "--mode", args.mode, "--steps", str(args.steps)]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    runs = [subprocess.Popen(command, env=env, stdout=subprocess.PIPE, text=True) for _ in range(2)]
    hashes = [run.communicate()[0].strip().splitlines()[-1] for run in runs]
    print(f"RunConfig(goal={args.goal!r}, mode={args.mode!r}, finish=False, overlap=True, steps={args.steps}), "
          f"seed 0, twice side by side: {hashes[0]} {hashes[1]} -> {'same' if hashes[0] == hashes[1] else 'differ'}")


if __name__ == "__main__":
    main()
