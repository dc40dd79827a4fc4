"""
The shipped zoo as a table in docs/zoo.md, read from the cards (goal, method, steps, success greedy and
sampled, size).

    python benchmarks/zoo_table.py
"""

from docs_section import write_section

from sb3_disagree.priors.zoo import Zoo


def _success(ev: dict) -> str:
    """Successes out of episodes: 0.947 must not read as 0.95 against a 0.95 bar; "-" where not measured."""
    episodes = ev.get("episodes", 0)
    return f"{ev['success_rate']:.3f} ({round(ev['success_rate'] * episodes)}/{episodes})" if episodes else "-"


def main() -> None:
    zoo = Zoo()
    rows, total = [], 0
    for e in zoo.entries():
        size = e.model_path.stat().st_size if e.model_path.exists() else 0
        total += size
        card = e.card
        if card is None:
            rows.append(f"| {e.goal} | {e.env_id} | - | - | - | - | - | - | {e.problem} |")
            continue
        ev, tr = card.evaluation, card.training
        success, greedy = _success(ev), _success(card.evaluation_greedy)
        rows.append(
            f"| {e.goal} | {e.env_id} | {tr.get('method', '?')} | {tr.get('steps', '?')} | {greedy} | {success} | "
            f"{ev.get('mean_length', float('nan')):.1f} | "
            f"{size / 1e6:.1f} MB | {'ok' if not e.problem else e.problem} |"
        )
    body = (
        "Read from the cards by `python benchmarks/zoo_table.py`. Success: the prior alone from its env's "
        "start distribution (the apartment: random corridor poses; the office: random poses anywhere on the "
        "floor), over the episodes on the card (env seeds 10000+): greedy (SB3's default; \"-\" where the card "
        "has no greedy evaluation yet: `dopt priors eval GOAL --episodes 300 --record` adds it) and sampled, "
        "as the method follows priors. Mean length of the sampled episodes. Each card keeps the command that "
        "made the prior.\n\n"
        "| goal | env | method | labelled steps | success greedy | success sampled | mean length | size | status |\n"
        "|---|---|---|---|---|---|---|---|---|\n" + "\n".join(rows) + f"\n\nTotal size: {total / 1e6:.1f} MB.\n"
    )
    write_section("zoo-table", "The shipped zoo", body, page="zoo.md")
    print(body)


if __name__ == "__main__":
    main()
