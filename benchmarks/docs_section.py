"""Write a named, generated section of docs/benchmarks.md (or another page), leaving the rest as it is."""

from pathlib import Path

DOCS = Path(__file__).resolve().parent.parent / "docs"


def write_section(name: str, title: str, body: str, page: str = "benchmarks.md") -> None:
    """
    Replace the block between ``<!-- name:start -->`` and ``<!-- name:end -->`` in ``docs/<page>``,
    or append it under ``## title`` when the page does not have it yet.
    """
    doc = DOCS / page
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    block = f"{start}\n{body.strip()}\n{end}"
    text = doc.read_text() if doc.exists() else f"# {page.removesuffix('.md').capitalize()}\n"
    if start in text:
        head, rest = text.split(start, 1)
        text = head + block + rest.split(end, 1)[1]
    else:
        text = text.rstrip() + f"\n\n## {title}\n\n{block}\n"
    doc.write_text(text)
