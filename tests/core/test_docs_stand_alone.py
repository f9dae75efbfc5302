"""docs/ and the tests stand alone: none names a path outside this repository (the shared
seed paper, the other labs' recordings or the machine's own directories). A reader of a
clone has only the clone; the shared recordings are reached through SOAKCAL_REALDATA."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
# The sibling checkout's shared directory and this machine's work and CI roots. Built from
# parts so that this file does not name them itself.
OUTSIDE = re.compile("|".join([re.escape("../" + "shared"), re.escape("/" + "work/"),
                               re.escape("/" + "check/work")]))


def _files() -> list[Path]:
    docs = sorted((ROOT / "docs").rglob("*.md"))
    tests = sorted(p for p in (ROOT / "tests").rglob("*.py") if p != Path(__file__).resolve())
    return [ROOT / "README.md", *docs, *tests]


def test_no_doc_or_test_names_a_path_outside_the_repository() -> None:
    found = []
    for path in _files():
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if OUTSIDE.search(line):
                found.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()[:100]}")
    assert not found, "paths outside the repository:\n" + "\n".join(found)


def test_the_check_sees_such_a_path() -> None:
    line = "git clone -q " + "/" + "work/main fresh && ln -s ../" + "shared shared"
    assert OUTSIDE.search(line)
    assert not OUTSIDE.search("soakcal import --format csv log.csv -o rec.csv")
