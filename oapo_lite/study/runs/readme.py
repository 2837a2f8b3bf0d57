"""The README's generated blocks: text between two HTML comments that a module rewrites from
the data (the claims table, the costs) and a test compares with what the data gives."""
from __future__ import annotations

from pathlib import Path

README = Path(__file__).resolve().parents[3] / "README.md"


def block(begin: str, end: str, path: Path = README) -> str:
    """The text between the markers ``begin`` and ``end``."""
    text = path.read_text()
    if begin not in text or end not in text:
        raise ValueError(f"{path} has no block between {begin!r} and {end!r}")
    return text.split(begin, 1)[1].split(end, 1)[0].strip()


def rewrite(begin: str, end: str, content: str, path: Path = README) -> None:
    """Replace the block between the markers with ``content``."""
    block(begin, end, path)  # both markers are there
    text = path.read_text()
    head, rest = text.split(begin, 1)
    path.write_text(f"{head}{begin}\n{content}\n{end}{rest.split(end, 1)[1]}")
