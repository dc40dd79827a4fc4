#!/usr/bin/env bash
# Re-evaluate the shipped zoo's apartment priors on 300 episodes (env seeds 10000+, sampled actions) and
# record the result on each card; docs/zoo.md is then rewritten by `python benchmarks/zoo_table.py`.
#   bash benchmarks/eval_zoo.sh [goal ...]        (default: all ten objects)
set -euo pipefail
goals=("$@")
[ ${#goals[@]} -gt 0 ] || goals=(shower bathtub toilet bed wardrobe nightstand stove toaster microwave table)
for goal in "${goals[@]}"; do
  OMP_NUM_THREADS=1 dopt priors eval "$goal" --episodes 300 --record --write-shipped
done
