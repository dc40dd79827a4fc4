"""The README's code blocks, as the tests that run them read them."""

import re
from pathlib import Path

README = Path(__file__).resolve().parents[1] / "README.md"
_BLOCK = re.compile(r"^```(\w+)\n(.*?)^```", re.S | re.M)


def blocks() -> list[tuple[str, str]]:
    """Every fenced block of the README with a language: (language, text)."""
    return _BLOCK.findall(README.read_text())


def commands(text: str) -> list[str]:
    """A shell block's commands: continuation lines joined, comments dropped."""
    joined = text.replace("\\\n", " ")
    return [line.split("  #")[0].strip() for line in joined.splitlines() if line.strip() and not line.startswith("#")]


def block_with(prefix: str) -> list[str]:
    """The commands of the one shell block whose commands start with ``prefix``."""
    (found,) = [commands(t) for lang, t in blocks() if lang == "bash" and commands(t)[0].startswith(prefix)]
    return found
