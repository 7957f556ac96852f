"""Read-only SQLite access with one-line errors (both the log DB and the GeoPackage map are SQLite)."""

from __future__ import annotations

import sqlite3
from collections.abc import Sequence
from pathlib import Path

from scenariomax.errors import InputError


def open_readonly(path: str) -> sqlite3.Connection:
    """Opens an SQLite file without locking or writing anything next to it."""
    if not Path(path).is_file():
        raise InputError(f"{path}: file not found")
    uri = Path(path).resolve().as_uri() + "?mode=ro&immutable=1"
    conn = None
    try:
        conn = sqlite3.connect(uri, uri=True)
        conn.text_factory = _decode_text  # corrupted text must not raise UnicodeDecodeError mid-query
        conn.execute("PRAGMA cell_size_check = ON")
        conn.execute("SELECT count(*) FROM sqlite_master").fetchone()
    except (sqlite3.Error, ValueError) as exc:  # ValueError: undecodable text in a corrupted file
        if conn is not None:
            conn.close()
        raise InputError(f"{path}: unreadable SQLite file ({one_line(exc)})") from None
    return conn


def _decode_text(raw: bytes) -> str:
    return raw.decode("utf-8", errors="replace")


def one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def table_columns(conn: sqlite3.Connection, path: str, table: str) -> set[str] | None:
    """Column names of a table, or None when the table does not exist."""
    try:
        exists = conn.execute("SELECT 1 FROM sqlite_master WHERE type IN ('table', 'view') AND name = ?",
                              (table,)).fetchone()
        if not exists:
            return None
        return {row[1] for row in conn.execute(f'PRAGMA table_info("{table}")').fetchall()}
    except (sqlite3.Error, ValueError) as exc:  # ValueError: undecodable text in a corrupted file
        raise InputError(f"{path}: unreadable SQLite file ({one_line(exc)})") from None


def require_columns(conn: sqlite3.Connection, path: str, table: str, columns: Sequence[str],
                    kind: str = "table") -> None:
    """Raises InputError naming the file and the missing table (or layer) / columns."""
    present = table_columns(conn, path, table)
    if present is None:
        raise InputError(f"{path}: {kind} '{table}' is missing")
    missing = [c for c in columns if c not in present]
    if missing:
        raise InputError(f"{path}: {kind} '{table}' lacks column(s) {', '.join(missing)}")


def fetch_all(conn: sqlite3.Connection, path: str, sql: str, params: Sequence = ()) -> list[tuple]:
    try:
        return conn.execute(sql, tuple(params)).fetchall()
    except (sqlite3.Error, ValueError) as exc:  # ValueError: undecodable text in a corrupted file
        raise InputError(f"{path}: SQLite query failed ({one_line(exc)})") from None
