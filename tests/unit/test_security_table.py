"""docs/security.md's table of faces (issue 42): every face is listed with who may read and who
may change, and each row names tests that exist."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
HEADING = "## Who may read and who may change, face by face"
FACES = [
    "ZeroMQ requests",
    "ZeroMQ publish",
    "ZeroMQ events",
    "the dashboard",
    "the Foxglove server",
    "the ROS 2 bridge",
    "the service lock",
    "`/dev/shm`",
    "the camera workers' command sockets",
]
# named before it exists: the file the branch changing the lock adds (the lead checks it on merging)
COMING = {"tests/integration/test_lock.py"}


def rows() -> list[list[str]]:
    text = (ROOT / "docs" / "security.md").read_text()
    section = text.split(HEADING, 1)[1].split("\n## ", 1)[0]
    lines = [line for line in section.splitlines() if line.startswith("| ")]
    return [[cell.strip() for cell in line.strip("|").split(" | ")] for line in lines[2:]]


def test_every_face_has_a_row_saying_who_reads_and_who_changes():
    table = rows()
    assert [next(f for f in FACES if row[0].startswith(f)) for row in table] == FACES
    for row in table:
        assert len(row) == 4 and all(row), row


def test_every_row_names_tests_that_exist():
    for face, *_, tested in rows():
        named = re.findall(r"`([^`]+)`", tested)
        assert named, face
        for test in named:
            path, _, name = test.partition("::")
            if not (ROOT / path).exists():
                assert path in COMING and not name, (face, test)
                continue
            if name:
                assert re.search(rf"^(async )?def {re.escape(name)}\(", (ROOT / path).read_text(), re.M), (face, test)
