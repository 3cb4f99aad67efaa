"""One line that says what an override key means (``wip-bench compare --list-keys``), read from
where the setting is documented, so that it is written once:

* ``env.<argument>``: the row of the ``## Arguments`` table in the env class's docstring
  (``help(wip_gym.envs.tasks.KrangTrayEnv)``); a row may name several arguments
  (```push_time`, `push_duration```) and span several lines.
* a config field (``plan.<field>``, ``<controller>.<field.path>``): the entry of the
  ``Attributes:`` section in the docstring of the dataclass that declares the field; an entry
  may name several fields (``horizon_s, dt: ...``) and continue on more indented lines.

The line is the entry's first sentence. A setting documented nowhere gets ``""`` (the tests hold
every shipped key to a description).
"""

from __future__ import annotations

import inspect
import re
from functools import cache

__all__ = ["attribute_docs", "config_field_doc", "env_argument_docs", "first_sentence"]

# a sentence ends at a full stop followed by a space, not inside ``...`` nor after these
_ABBREVIATIONS = ("e.g.", "i.e.", "etc.", "vs.", "eq.", "approx.")
_NAMES = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*(?:\s*,\s*[A-Za-z_][A-Za-z0-9_]*)*)\s*:\s*(.*)$")
#: the longest line (characters) a description keeps; a longer sentence is cut at a word
MAX_LENGTH = 160


def first_sentence(text: str) -> str:
    """``text`` as one line, up to the end of its first sentence (at most :data:`MAX_LENGTH`
    characters, a cut one ending in "...")."""
    words = " ".join(text.split())
    inside_code = False
    head = words
    i = 0
    while i < len(words):
        char = words[i]
        if char == "`":
            while i + 1 < len(words) and words[i + 1] == "`":
                i += 1  # ``code`` opens and closes like `code`
            inside_code = not inside_code
        elif (
            char == "."
            and not inside_code
            and (i + 1 == len(words) or words[i + 1] == " ")
            and not words[: i + 1].endswith(_ABBREVIATIONS)
        ):
            head = words[: i + 1]
            break
        i += 1
    if len(head) > MAX_LENGTH:
        head = head[: MAX_LENGTH - 4].rsplit(" ", 1)[0] + " ..."
    return head


@cache
def attribute_docs(cls: type) -> dict[str, str]:
    """Field name -> its entry's first sentence, from the ``Attributes:`` section of ``cls``'s
    own docstring (not inherited)."""
    doc = cls.__dict__.get("__doc__")
    if not doc:
        return {}
    lines = inspect.cleandoc(doc).splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.strip() == "Attributes:")
    except StopIteration:
        return {}
    entries: list[tuple[list[str], list[str]]] = []
    entry_indent: int | None = None
    for line in lines[start + 1 :]:
        if not line.strip():
            continue
        indent = len(line) - len(line.lstrip())
        if entry_indent is None:
            entry_indent = indent
        if indent < entry_indent:
            break  # the section ended
        match = _NAMES.match(line.strip()) if indent == entry_indent else None
        if match:
            names = [n.strip() for n in match.group(1).split(",")]
            entries.append((names, [match.group(2)]))
        elif entries and indent > entry_indent:
            entries[-1][1].append(line.strip())
        elif indent == entry_indent:
            break  # prose after the entries
    docs: dict[str, str] = {}
    for names, text in entries:
        sentence = first_sentence(" ".join(text))
        for name in names:
            docs.setdefault(name, sentence)
    return docs


def config_field_doc(config_cls: type, field: str) -> str:
    """The description of ``field`` of the dataclass ``config_cls``: the first class along its
    MRO whose docstring documents it; ``""`` if none does."""
    for cls in config_cls.__mro__:
        text = attribute_docs(cls).get(field)
        if text:
            return text
    return ""


def _cells(row: str) -> list[str]:
    return [cell.strip() for cell in row.strip().strip("|").split("|")]


@cache
def env_argument_docs(env_cls: type) -> dict[str, str]:
    """Argument name -> the ``meaning`` cell of its row in the ``## Arguments`` table of
    ``env_cls``'s docstring (first sentence); ``{}`` without such a table."""
    doc = env_cls.__doc__ or ""
    lines = inspect.cleandoc(doc).splitlines()
    try:
        start = next(i for i, line in enumerate(lines) if line.startswith("## Arguments"))
    except StopIteration:
        return {}
    rows: list[str] = []
    for line in lines[start + 1 :]:
        text = line.strip()
        if text.startswith("## "):
            break
        if rows and not rows[-1].endswith("|"):
            rows[-1] += " " + text  # a row continued on the next line
        elif text.startswith("|"):
            rows.append(text)
    docs: dict[str, str] = {}
    for row in rows:
        cells = _cells(row)
        if len(cells) < 3 or set(cells[0]) <= {"-"} or cells[0] == "argument":
            continue
        names = [name.strip().strip("`") for name in cells[0].split(",")]
        meaning = first_sentence(" | ".join(cells[2:]))
        for name in names:
            docs.setdefault(name, meaning)
    return docs
