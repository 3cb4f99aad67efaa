"""The sweep's store: ``DIR/episodes.jsonl``, one JSON row per finished episode, appended and
flushed as each episode ends (a killed driver loses only the episodes in flight).

A torn last line (the process died mid-write) is ignored when reading and cut off before the
next append. An episode's rows are keyed by ``id``; the last row of an id wins (a rerun of an
error row appends the new outcome).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import IO, Any

STORE_NAME = "episodes.jsonl"


def store_path(directory: str | Path) -> Path:
    return Path(directory) / STORE_NAME


def read_rows(directory: str | Path) -> list[dict[str, Any]]:
    """Every complete row in order; a torn last line is left out."""
    path = store_path(directory)
    if not path.exists():
        return []
    rows = []
    with open(path, "rb") as f:
        lines = f.read().split(b"\n")
    for number, line in enumerate(lines, start=1):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            if number == len(lines):  # the last line, without its newline: torn
                continue
            raise ValueError(f"{path}:{number} is not a JSON row") from None
        rows.append(row)
    return rows


def latest_rows(rows: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """The last row of each episode id."""
    latest: dict[str, dict[str, Any]] = {}
    for row in rows:
        latest[row["id"]] = row
    return latest


def cut_torn_tail(directory: str | Path) -> int:
    """Remove a torn last line (bytes after the last newline); the number of bytes removed."""
    path = store_path(directory)
    if not path.exists():
        return 0
    with open(path, "rb+") as f:
        data = f.read()
        end = data.rfind(b"\n") + 1
        if end == len(data):
            return 0
        f.truncate(end)
        return len(data) - end


class StoreWriter:
    """Appends rows to the store, one line each, flushed and synced."""

    def __init__(self, directory: str | Path) -> None:
        self.path = store_path(directory)
        self._file: IO[str] = open(self.path, "a")  # noqa: SIM115 (closed by close())

    def write(self, row: dict[str, Any]) -> None:
        self._file.write(json.dumps(row) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()

    def __enter__(self) -> StoreWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
