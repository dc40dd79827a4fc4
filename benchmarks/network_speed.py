"""
The price of the apartment policy's network on this CPU: a prior's NatureCNN (the zoo's shower) timed
on a rollout batch (one frame per env) and on an update batch (a 20-step segment of 4 envs plus its
bootstrap frames), in PyTorch's default NCHW layout and in channels-last, and the two priors of a
rollout step one after the other against one ``torch.func.vmap`` call over their stacked parameters.

    python benchmarks/network_speed.py [--threads 1 2] [--repeats 5] [--write]
"""

import argparse
import copy
import os
import platform
import statistics
import time
from collections.abc import Callable

import torch as th
from torch.func import functional_call, stack_module_state, vmap

ROLLOUT, UPDATE = 4, 84


def timed(variants: list[tuple[Callable[[], object], int]], repeats: int) -> list[float]:
    """Median over ``repeats`` of the mean milliseconds per call of each variant; the variants take turns
    within each repeat, so that a slow spell of a shared machine does not fall on one of them only."""
    times: list[list[float]] = [[] for _ in variants]
    for fn, _ in variants:
        fn()
    for _ in range(repeats):
        for out, (fn, calls) in zip(times, variants):
            start = time.perf_counter()
            for _ in range(calls):
                fn()
            out.append((time.perf_counter() - start) / calls * 1e3)
    return [statistics.median(t) for t in times]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--write", action="store_true")
    args = parser.parse_args()
    from sb3_disagree.priors.zoo import Zoo

    zoo = Zoo()
    nets = [zoo.load(zoo.get(goal, "sb3_disagree/Apartment-v0"), device="cpu").policy.net for goal in ("shower", "toilet")]
    net = nets[0]
    channels_last = copy.deepcopy(net).to(memory_format=th.channels_last)
    small, large = th.rand(ROLLOUT, 3, 60, 80), th.rand(UPDATE, 3, 60, 80)

    def forward(n, x):
        with th.no_grad():
            return n.logits(n.features_extractor(x))

    def forward_backward(n, x):
        logits, q = n(n.features_extractor(x))
        (logits.sum() + q.sum()).backward()

    params, _ = stack_module_state(nets)
    base = copy.deepcopy(net).to("meta")

    def both_vmapped():
        def logits(p, x):
            features = functional_call(base.features_extractor, {k.split(".", 1)[1]: v for k, v in p.items()
                                                                 if k.startswith("features_extractor.")}, (x,))
            return functional_call(base.action_net, {k.split(".", 1)[1]: v for k, v in p.items()
                                                     if k.startswith("action_net.")}, (features,))
        with th.no_grad():
            return vmap(logits, in_dims=(0, None))(params, small)

    def both_in_turn():
        return th.stack([forward(n, small) for n in nets])

    assert th.allclose(both_vmapped(), both_in_turn(), atol=1e-5)
    rows = []
    for threads in args.threads:
        th.set_num_threads(threads)
        cells = timed([
            (lambda: forward(net, small), 100),
            (lambda: forward(channels_last, small), 100),
            (lambda: forward(net, large), 20),
            (lambda: forward(channels_last, large), 20),
            (lambda: forward_backward(net, large), 10),
            (lambda: forward_backward(channels_last, large), 10),
            (both_in_turn, 100),
            (both_vmapped, 100),
        ], args.repeats)
        rows.append(f"| {threads} | " + " | ".join(f"{c:.2f}" for c in cells) + " |")
        print(rows[-1], flush=True)
    body = (
        f"Command: `python benchmarks/network_speed.py --threads {' '.join(map(str, args.threads))} --repeats "
        f"{args.repeats}`; {platform.machine()}, {os.cpu_count()} cores. Milliseconds per call (median of "
        f"{args.repeats} repeats, the variants taking turns within each) of a prior's network (NatureCNN, 128 features, 60x80 RGB): forward on a rollout "
        f"batch of {ROLLOUT} frames, forward and forward + backward on an update batch of {UPDATE} frames, in NCHW "
        "and channels-last; and both priors of a rollout step in turn against one vmapped call.\n\n"
        "| torch threads | fwd 4 NCHW | fwd 4 channels-last | fwd 84 NCHW | fwd 84 channels-last | "
        "fwd+bwd 84 NCHW | fwd+bwd 84 channels-last | 2 priors in turn | 2 priors vmapped |\n"
        "|---|---|---|---|---|---|---|---|---|\n" + "\n".join(rows) + "\n")
    if args.write:
        from docs_section import write_section

        write_section("network-speed", "The network's price per call", body)
    print(body)


if __name__ == "__main__":
    main()
