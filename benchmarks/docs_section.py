"""Write a named, generated section of docs/benchmarks.md (or another page of docs/), leaving the rest as it is."""

from pathlib import Path

from sb3_disagree.experiments.writeup import write_section as write_block

DOCS = Path(__file__).resolve().parent.parent / "docs"


def write_section(name: str, title: str, body: str, page: str = "benchmarks.md") -> None:
    """The block between ``<!-- name:start -->`` and ``<!-- name:end -->`` in ``docs/<page>`` (appended under
    ``## title`` when the page does not have it yet)."""
    write_block(DOCS / page, name, title, body)
