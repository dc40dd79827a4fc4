#!/usr/bin/env bash
# Train the shipped zoo's apartment priors (RGB) by DAgger on the scripted expert, one goal after another.
#   bash benchmarks/train_zoo.sh [goal ...]        (default: all ten objects)
set -euo pipefail
goals=("$@")
[ ${#goals[@]} -gt 0 ] || goals=(shower bathtub toilet bed wardrobe nightstand stove toaster microwave table)
for goal in "${goals[@]}"; do
  OMP_NUM_THREADS=1 dopt priors train --goal "$goal" --method dagger --rounds 5 --epochs 5 --seed 0 --replace \
    --zoo zoo/default --write-shipped
done
