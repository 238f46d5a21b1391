"""docs/FORMAT.md lists exactly the fields of the Arrow schemas (the single source of truth)."""

from __future__ import annotations

import re
from pathlib import Path

from psg_data.schemas import TABLES

DOC = Path(__file__).resolve().parents[2] / "docs" / "FORMAT.md"


def _documented_tables() -> dict[str, list[tuple[str, str, str]]]:
    text = DOC.read_text(encoding="utf-8")
    out: dict[str, list[tuple[str, str, str]]] = {}
    for m in re.finditer(r"^### `(\w+)`\n(.*?)(?=^#{2,3} |\Z)", text, flags=re.S | re.M):
        rows = re.findall(r"^\| `(\w+)` \| `([^`]+)` \| (yes|no) \|", m.group(2), flags=re.M)
        out[m.group(1)] = rows
    return out


def test_format_doc_lists_exactly_the_schema_fields() -> None:
    documented = _documented_tables()
    for name, spec in TABLES.items():
        assert name in documented, f"FORMAT.md has no section for table {name!r}"
        expected = [(f.name, str(f.type), "yes" if f.nullable else "no") for f in spec.schema]
        assert documented[name] == expected, f"FORMAT.md table {name!r} differs from its Arrow schema"


def test_format_doc_has_no_stale_tables() -> None:
    extra = set(_documented_tables()) - set(TABLES)
    assert not extra, f"FORMAT.md documents tables that have no schema: {sorted(extra)}"
