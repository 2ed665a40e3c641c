"""No file of the checkout holds a merge's conflict markers (one reached docs/cli.md once)."""

import re
import subprocess
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MARKER = re.compile(r"^(<{7} |>{7} )", re.M)


def test_no_tracked_file_holds_conflict_markers():
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, capture_output=True, text=True, check=True).stdout.split()
    marked = []
    for name in tracked:
        path = ROOT / name
        if path.suffix in {".py", ".md", ".toml", ".c", ".h", ".sh", ".html", ".cfg", ".txt"} and path.is_file():
            if MARKER.search(path.read_text(errors="replace")):
                marked.append(name)
    assert marked == []
