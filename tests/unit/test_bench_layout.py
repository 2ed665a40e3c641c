"""bench/ is grouped by question (issue 37): bench/README.md names every bench and every module
beside them, and no folder tells groups of files apart by a name prefix alone."""

from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
MODULES = sorted(p.relative_to(ROOT) for p in ROOT.glob("bench/*/*.py"))


def test_the_readme_names_every_file_of_bench():
    readme = (ROOT / "bench/README.md").read_text()
    assert len(MODULES) >= 30
    assert [str(m) for m in MODULES if f"`{m.relative_to('bench')}`" not in readme and str(m) not in readme] == []


def test_no_folder_groups_files_by_a_name_prefix():
    prefixes = Counter((m.parent, m.stem.split("_")[0]) for m in MODULES if "_" in m.stem)
    assert [f"{folder}/{prefix}_*" for (folder, prefix), n in prefixes.items() if n > 1] == []


def test_bench_has_folders_only():
    assert sorted(p.name for p in (ROOT / "bench").iterdir() if p.suffix == ".py") == []


def test_every_bench_path_the_docs_name_exists():
    # a bench moved or renamed leaves no command in the README or docs/ that can no longer run
    import re

    texts = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "bench/README.md"]
    named = {(t.name, m) for t in texts for m in re.findall(r"\bbench/[\w/.-]+\.py\b", t.read_text())}
    gone = [(doc, path) for doc, path in named if not (ROOT / path).is_file() and "FOLDER/" not in path]
    assert sorted(gone) == []  # (bench/FOLDER/NAME.py: the README's pattern)
