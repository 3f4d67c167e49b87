"""Where things are in a level file's text, for error messages: tomllib gives no positions.

``load_level`` (engine.assets.level_read) parses with tomllib, which says what a file holds
but not on which line; a LevelError names the line, so ``line_map`` reads the text once
more, line by line, for where each entity, component table and field starts. Nesting is
bounded here too (``MAX_NESTING``): a value nested deeper than a level needs is refused
before anything walks it recursively (``nesting_depth``), and a file too deep for the TOML
parser itself is given the line where it goes too deep (``deep_line``).
"""
from __future__ import annotations

import re
from typing import Any

MAX_NESTING = 16  # arrays and inline tables inside one value (a level needs three at most)

_TABLE = re.compile(r"^\s*\[\s*entity\.([A-Za-z_]\w*)\s*\]")
_KEY = re.compile(r"^\s*([A-Za-z_][\w-]*)\s*=")
_HEADER = re.compile(r"^\s*\[\[?\s*([A-Za-z0-9_-]+)")


def line_map(text: str) -> dict[tuple, int]:
    """Line numbers of each ``[[entity]]`` (key (i,)), component table ((i, Class)) and field
    ((i, Class, field)), by the entity's index in the file; of the other tables' headers
    (("table", name): ``[level]``, a misspelt ``[[entitty]]``, and a key before any table),
    and their keys (("level", key), ("rules", key))."""
    lines: dict[tuple, int] = {}
    entity, table, section = -1, None, None
    for number, raw in enumerate(text.splitlines(), start=1):
        stripped = raw.strip()
        header = _HEADER.match(raw) if stripped.startswith("[") else None
        if header:
            lines.setdefault(("table", header.group(1)), number)
        if stripped.startswith("[[entity]]"):
            entity, table, section = entity + 1, None, None
            lines[(entity,)] = number
            continue
        match = _TABLE.match(raw)
        if match and entity >= 0:
            table = match.group(1)
            lines[(entity, table)] = number
            continue
        if stripped.startswith("["):
            entity, table = (entity if stripped.startswith("[entity") else -1), None
            section = None if stripped.startswith("[entity") or not header else header.group(1)
            continue
        match = _KEY.match(raw)
        if match and entity >= 0:
            key = match.group(1)
            if table is None:
                lines.setdefault((entity, key), number)  # an inline component table, or name
            else:
                lines.setdefault((entity, table, key), number)
        elif match:
            lines.setdefault((section, match.group(1)) if section else ("table", match.group(1)), number)
    return lines


def nesting_depth(value: Any) -> int:
    """How deep arrays and tables nest in ``value`` (a number is 0, ``[1]`` is 1; past
    MAX_NESTING the walk stops at MAX_NESTING + 1), without recursion."""
    deepest, stack = 0, [(value, 0)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, (list, dict)):
            deepest = max(deepest, depth + 1)
            if deepest > MAX_NESTING:
                return deepest
            stack.extend((child, depth + 1) for child in (item.values() if isinstance(item, dict) else item))
    return deepest


def deep_line(text: str) -> int | None:
    """The first line where brackets and braces outside strings and comments nest past
    ``MAX_NESTING`` (for a file too deep for the TOML parser to say where)."""
    depth, line, i, n = 0, 1, 0, len(text)
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
        elif c == "#":
            end = text.find("\n", i)
            i = n if end < 0 else end
            continue
        elif c in "\"'":
            quote = text[i:i + 3] if text[i:i + 3] in ('"""', "'''") else c
            j = i + len(quote)
            while j < n and not text.startswith(quote, j):
                if text[j] == "\\" and c == '"':
                    j += 1
                elif text[j] == "\n":
                    if len(quote) == 1:
                        break
                    line += 1
                j += 1
            i = j + len(quote)
            continue
        elif c in "[{":
            depth += 1
            if depth > MAX_NESTING + 2:  # a [[table]] header is two of them
                return line
        elif c in "]}":
            depth = max(0, depth - 1)
        i += 1
    return None
