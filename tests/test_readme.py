"""The README is one screen that stays true, and the user-facing docs carry no project history.

- README.md has at most 150 lines (benchmarks, conformance and design notes live in docs/).
- README.md, CONTRIBUTING.md and docs/ (outside docs/results/, whose pages are regenerated) name no
  issue numbers, rounds or dated run logs: history goes to CHANGELOG.md.
- The quick start's test command is the one CI runs (.ci/run), and its demo command works on a fresh
  clone and says what to do on a second run (the demo refuses a non-empty --out without --force).
- Every relative link of README.md and docs/*.md points at a file that exists.
"""

from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path

import pytest

from daa_sil.cli import main

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MAX_README_LINES = 150
#: what a user cannot see: an issue number, a "round" of work (the pattern of the docs check in the brief)
HISTORY = re.compile(r"\(?issue [0-9]+|previous round|last round|this round|round [0-9]", re.I)
#: a dated run log: "4 Dec 2026", "3 December 2026"
RUN_DATE = re.compile(r"\b[0-3]?[0-9] (Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec)[a-z]* 20[0-9]{2}\b")


def user_docs() -> list[Path]:
    """README, CONTRIBUTING and every text file under docs/ except the regenerated results pages."""
    docs = [p for p in sorted((ROOT / "docs").rglob("*"))
            if p.is_file() and p.suffix in (".md", ".py", ".txt") and "results" not in p.relative_to(ROOT / "docs").parts]
    return [README, ROOT / "CONTRIBUTING.md", *docs]


def history_lines(path: Path) -> list[str]:
    """``file:line: text`` of every line naming an issue, a round or a run's date."""
    out = []
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if HISTORY.search(line) or RUN_DATE.search(line):
            out.append(f"{path.relative_to(ROOT)}:{n}: {line.strip()[:120]}")
    return out


def quick_start() -> list[str]:
    """The commands of the README's quick-start block (comments dropped)."""
    text = README.read_text(encoding="utf-8")
    section = text.split("## Quick start", 1)[1].split("\n## ", 1)[0]
    block = re.search(r"```bash\n(.*?)```", section, re.S)
    assert block, "the quick start has no bash block"
    return [line for line in block.group(1).splitlines() if line.strip() and not line.startswith("#")]


def test_readme_is_one_screen():
    lines = README.read_text(encoding="utf-8").splitlines()
    assert len(lines) <= MAX_README_LINES, f"README.md has {len(lines)} lines (at most {MAX_README_LINES})"


def test_user_docs_carry_no_issue_numbers_rounds_or_run_dates():
    found = [hit for path in user_docs() for hit in history_lines(path)]
    assert not found, "history belongs in CHANGELOG.md:\n" + "\n".join(found)


def test_the_history_check_can_fail(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("fine\nWhat changed to get there (issue 15)\nas measured on 4 Dec 2026\nthis round's change\n")
    hits = [line for line in page.read_text().splitlines() if HISTORY.search(line) or RUN_DATE.search(line)]
    assert len(hits) == 3


def test_quick_start_is_the_ci_install_and_a_demo():
    demo, tests = quick_start()
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    steps = [s.strip() for s in tests.split("&&")]
    assert steps[:2] == ["python3 -m venv .venv", ". .venv/bin/activate"]
    for step in steps[2:]:  # the install, the bytecode and the test run: exactly the lines CI runs
        assert re.search(rf"^{re.escape(step)}$", ci, re.M), f"{step!r} is not a line of .ci/run"
    assert steps[-1] == "python -m pytest -q"
    assert demo.split("&&")[-1].strip() == "daa-sil demo --out runs/demo"


def test_the_readme_says_how_to_run_the_demo_a_second_time():
    text = README.read_text(encoding="utf-8")
    assert "daa-sil demo --out runs/demo --force" in text
    out = io.StringIO()
    with contextlib.redirect_stdout(out), pytest.raises(SystemExit) as stop:
        main(["demo", "--help"])
    assert stop.value.code == 0
    assert "--force" in out.getvalue()  # the flag the README names exists


def test_relative_links_point_at_files_that_exist():
    broken = []
    for path in [README, *sorted((ROOT / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", path.read_text(encoding="utf-8")):
            if "://" in target or target.startswith("mailto:"):
                continue
            if not (path.parent / target).exists():
                broken.append(f"{path.relative_to(ROOT)} -> {target}")
    assert not broken, broken
