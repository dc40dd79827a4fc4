"""
A shipped zoo as a table in docs/zoo.md, read from the cards (goal, method, steps, memory, phase, success greedy
and sampled, size): the default zoo, or one shipped beside it by name.

    python benchmarks/zoo_table.py [--zoo greedy]
"""

import argparse

from docs_section import write_section

from sb3_disagree.priors.zoo import Zoo, memory_label


def _success(ev: dict) -> str:
    """Successes out of episodes: 0.947 must not read as 0.95 against a 0.95 bar; "-" where not measured."""
    episodes = ev.get("episodes", 0)
    return f"{ev['success_rate']:.3f} ({round(ev['success_rate'] * episodes)}/{episodes})" if episodes else "-"


def _length(ev: dict) -> str:
    return f"{ev['mean_length']:.1f}" if ev.get("episodes") else "-"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--zoo", default=None, help="a shipped zoo's name (default: the default zoo)")
    args = parser.parse_args()
    zoo = Zoo(args.zoo)
    rows, total = [], 0
    for e in zoo.entries():
        size = e.model_path.stat().st_size if e.model_path.exists() else 0
        total += size
        card = e.card
        if card is None:
            rows.append(f"| {e.goal} | {e.env_id} | - | - | - | - | - | - | - | - | {e.problem} |")
            continue
        tr = card.training
        memory = memory_label(tr)
        phase = sum(p.get("rounds", 0) for p in [tr.get("consistency") or {}, *tr.get("consistency_more", [])])
        rows.append(
            f"| {e.goal} | {e.env_id} | {tr.get('method', '?')} | {tr.get('steps', '?')} | {memory} | {phase} | "
            f"{_success(card.evaluation_greedy)} | {_success(card.evaluation)} | "
            f"{_length(card.evaluation_greedy)} / {_length(card.evaluation)} | "
            f"{size / 1e6:.1f} MB | {'ok' if not e.problem else e.problem} |"
        )
    name = f"the shipped {args.zoo} zoo (`--zoo {args.zoo}`)" if args.zoo else "the shipped zoo"
    body = (
        f"{name[0].upper() + name[1:]}, read from the cards by `python benchmarks/zoo_table.py"
        f"{f' --zoo {args.zoo}' if args.zoo else ''}`. Success: the prior alone from its env's "
        "start distribution (the apartment: random corridor poses; the office: random poses anywhere on the "
        "floor), over the episodes on the card (env seeds 10000+): greedy (SB3's default; \"-\" where the card "
        "has no greedy evaluation yet: `dopt priors eval GOAL --episodes 300 --record` adds it) and sampled, "
        "as the method follows priors. Memory: frames the prior sees (`+flags`: the newest frame and loop flags; "
        "`all+flags`: every frame and loop flags). "
        "Phase: rounds of the greedy-consistency phase after training. Mean length greedy / sampled. Each card "
        "keeps the command that made the prior.\n\n"
        "| goal | env | method | labelled steps | memory | phase | success greedy | success sampled | mean length "
        "| size | status |\n"
        "|---|---|---|---|---|---|---|---|---|---|---|\n" + "\n".join(rows) + f"\n\nTotal size: {total / 1e6:.1f} MB.\n"
    )
    section = f"zoo-table-{args.zoo}" if args.zoo else "zoo-table"
    write_section(section, f"The shipped {args.zoo + ' ' if args.zoo else ''}zoo", body, page="zoo.md")
    print(body)


if __name__ == "__main__":
    main()
