"""One way to publish a table into a markdown page: between a begin marker and an end marker.

A page (the README, a guide, the journal) holds a begin marker (an HTML comment, invisible when
rendered) and, after it, the end marker; publishing replaces what stands between them and
nothing else. ``proteo eval --publish`` (:mod:`training.judging.report`) and ``python -m training.judging.results
--publish`` (the README's held-out table) both publish this way.
"""

from __future__ import annotations

from pathlib import Path

from proteo_env.config import ConfigError


def filled(path, tables: dict[str, str], end: str) -> str:
    """``path``'s text with each table of ``tables`` (``{begin marker: table}``) between its begin
    marker and the next ``end`` marker, for every begin marker the page holds; a
    :class:`ConfigError` naming the page and the markers when it holds none of them."""
    path = Path(path)
    text = path.read_text() if path.is_file() else ""
    found = [begin for begin in tables if begin in text and end in text.split(begin, 1)[1]]
    if not found:
        raise ConfigError(
            f"--publish {str(path)!r} is not allowed: no {' or '.join(map(repr, tables))} ... {end!r} markers; "
            "allowed: a markdown file that has them, in that order, where the table goes"
        )
    for begin in found:
        head, rest = text.split(begin, 1)
        text = f"{head}{begin}\n{tables[begin]}\n{end}{rest.split(end, 1)[1]}"
    return text


def publish(paths, tables: dict[str, str], end: str) -> None:
    """Write :func:`filled` into every page of ``paths``, after checking them all: a page without
    the markers is an error and nothing is written."""
    texts = {Path(p): filled(p, tables, end) for p in paths}
    for path, text in texts.items():
        path.write_text(text)
