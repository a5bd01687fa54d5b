"""``experiments/`` stays a lab a newcomer can rerun (issue 64, item 6), read from the files
(nothing is imported or run, so this file runs in well under a second).

The top of ``experiments/`` holds one folder per study, the shared helpers' package
``_lab/`` and the index ``README.md``; every study has a ``README.md`` and a row in the
index; no write-up grows past 40 KB; no file name carries a commit hash or a date (git
keeps the history); no experiment imports a private module of ``jaxgrasp``.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
EXPERIMENTS = ROOT / "experiments"
WRITE_UP_MAX_BYTES = 40 * 1024
PRIVATE_IMPORT = re.compile(r"jaxgrasp\.[a-z_]+\._|from jaxgrasp\.[a-z_]+ import _")
HASH_OR_DATE = re.compile(r"(?<![0-9a-f])(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}(?![0-9a-f])|\d{4}-\d{2}-\d{2}")


def studies() -> list[Path]:
    # _lab is the shared helpers' package; __pycache__ and dot folders are not studies
    return sorted(p for p in EXPERIMENTS.iterdir() if p.is_dir() and not p.name.startswith(("_", ".")))


def tracked_files() -> list[Path]:
    return sorted(p for p in EXPERIMENTS.rglob("*") if p.is_file() and "__pycache__" not in p.parts
                  and "quick" not in p.relative_to(EXPERIMENTS).parts)


def test_top_holds_folders_and_its_readme_only():
    loose = sorted(p.name for p in EXPERIMENTS.iterdir() if p.is_file() and p.name != "README.md")
    assert loose == []
    assert (EXPERIMENTS / "_lab" / "__init__.py").is_file()
    assert len(studies()) >= 10


def test_every_study_has_a_readme_and_a_row_in_the_index():
    index = (EXPERIMENTS / "README.md").read_text(encoding="utf-8")
    missing = [s.name for s in studies() if not (s / "README.md").is_file()]
    unlisted = [s.name for s in studies() if f"]({s.name}/README.md)" not in index]
    assert missing == [] and unlisted == []


def test_write_ups_are_at_most_40_kb():
    big = [f"{p.relative_to(EXPERIMENTS)}: {p.stat().st_size} bytes" for p in EXPERIMENTS.rglob("*.md")
           if p.stat().st_size > WRITE_UP_MAX_BYTES]
    assert big == []


def test_no_file_name_carries_a_commit_hash_or_a_date():
    named = [str(p.relative_to(EXPERIMENTS)) for p in tracked_files() if HASH_OR_DATE.search(p.name)]
    assert named == []
    assert HASH_OR_DATE.search("batch_benchmark_533e2b5.log") and HASH_OR_DATE.search("gpu_run_h100_2026-11-28.log")
    assert not HASH_OR_DATE.search("fig7a_cube_max.png") and not HASH_OR_DATE.search("settle_real_part0.json")


def test_no_experiment_imports_a_private_module():
    offenders = [f"{p.relative_to(EXPERIMENTS)}:{i}: {line.strip()}"
                 for p in sorted(EXPERIMENTS.rglob("*.py"))
                 for i, line in enumerate(p.read_text(encoding="utf-8").splitlines(), 1)
                 if PRIVATE_IMPORT.search(line)]
    assert offenders == []
    assert PRIVATE_IMPORT.search("from jaxgrasp.engine._plan import grasps_by_count")
    assert PRIVATE_IMPORT.search("from jaxgrasp.solver import _lanes")
    assert not PRIVATE_IMPORT.search("from jaxgrasp.engine import plan_widths")
