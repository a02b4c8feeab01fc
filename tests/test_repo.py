"""The front door and the docs: README's two commands, CI running the test command verbatim, a
short README, the contributor's fast loop it names, links and § citations that resolve, no issue
letters, quiet TF."""

import csv
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
DOCS = sorted((REPO / "docs").glob("*.md"))
CODE = [
    REPO / "train.py",
    REPO / "evaluate.py",
    *sorted(p for d in ("dqfd_bc_keras", "studies", "benchmarks", "tests") for p in (REPO / d).rglob("*.py")),
]
NOTES = ("<!-- notes: hand-written, kept when the report is regenerated -->", "<!-- /notes -->")


def quick_start_commands() -> list[str]:
    section = README.read_text().split("## Quick start", 1)[1].split("\n## ", 1)[0]
    return re.findall(r"```bash\n(.+?)\n```", section, flags=re.S)


def test_quick_start_is_two_single_line_commands_and_ci_runs_the_second():
    """The main job, its Python equivalent (after the install), and the tests that CI runs."""
    commands = quick_start_commands()
    assert len(commands) == 3 and all("\n" not in c for c in commands)
    main, python, tests = commands
    assert main.startswith("python3.11 -m venv .venv && .venv/bin/pip install -q -e . && .venv/bin/dqfd-train")
    assert python.startswith('.venv/bin/python -c "import dqfd_bc_keras; dqfd_bc_keras.configure();')
    system, _, python_part = tests.partition(" >/dev/null && ")  # Debian's xvfb and xdotool where missing
    assert system.startswith("{ command -v Xvfb && command -v xdotool || {") and "apt-get install" in system
    assert python_part.startswith("python3.11 -m venv .venv && .venv/bin/pip install -q -r requirements.txt")
    assert tests.endswith(
        "&& .venv/bin/ruff check . && .venv/bin/ruff format --check . && .venv/bin/python -m mypy"
        " && .venv/bin/python -m pytest -q -n 2"
    )
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    assert tests in ci and "set -euo pipefail" in ci


def test_readme_is_a_front_door_of_at_most_250_lines():
    lines = README.read_text().splitlines()
    assert len(lines) <= 250, f"README.md has {len(lines)} lines; move reference detail to docs/"


FAST_LOOP = '.venv/bin/python -m pytest -m "not slow" -n 2'
"""The contributor's loop: every test but those marked `slow` (subprocess trainings, long commands)."""


def test_the_slow_marker_is_registered_strictly_and_only_selects():
    """A misspelt marker is an error, not a silently unmarked test; and nothing but `-m` leaves the
    slow tests out, so the README's full command (CI's) runs them all."""
    options = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert [m for m in options["markers"] if m.startswith("slow:")], options["markers"]
    addopts = options["addopts"].split()
    assert "--strict-markers" in addopts and "-m" not in addopts and "slow" not in options["addopts"]
    contributing = README.read_text().split("## Contributing", 1)[1].split("\n## ", 1)[0]
    assert f"`{FAST_LOOP}`" in contributing and "`.ci/run`" in contributing


@pytest.mark.slow
def test_the_fast_loop_selects_at_least_500_tests_and_leaves_the_slow_ones_out():
    done = subprocess.run(
        [sys.executable, "-m", "pytest", "--collect-only", "-q", "-p", "no:cacheprovider", "-m", "not slow"],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    counts = re.search(r"^(\d+)/(\d+) tests collected \((\d+) deselected\)", done.stdout, re.M)
    assert counts, done.stdout[-3000:]
    selected, collected, deselected = map(int, counts.groups())
    assert selected >= 500 and deselected > 0 and selected + deselected == collected


def relative_links(markdown: Path) -> list[str]:
    """Targets of [text](target) and ![alt](target) that point into the repository."""
    targets = re.findall(r"!?\[[^\]]*\]\(([^)\s]+)\)", markdown.read_text())
    return [t.split("#", 1)[0] for t in targets if not re.match(r"[a-z]+:|#", t)]


def test_every_relative_link_of_the_docs_resolves_to_a_file_in_the_repository():
    broken = [
        f"{md.relative_to(REPO)} → {target}"
        for md in [README, *DOCS]
        for target in relative_links(md)
        if not (md.parent / target).resolve().exists() or not (md.parent / target).resolve().is_relative_to(REPO)
    ]
    assert not broken, broken
    assert "docs/ALGORITHM.md" in relative_links(README)  # the scan sees the README's links at all


def test_relative_links_leave_out_urls_anchors_and_fragments(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("[a](there.md#part) ![b](fig.png) [c](https://example.org) [d](#top)")
    assert relative_links(page) == ["there.md", "fig.png"]


def algorithm_citations(text: str) -> set[int]:
    """Section numbers cited as `ALGORITHM.md §N` (also `§2–§3`, `§4, §5`)."""
    runs = re.findall(r"ALGORITHM\.md (§\d+(?:\s*(?:[–-]|,|and)\s*§\d+)*)", text)
    return {int(n) for run in runs for n in re.findall(r"§(\d+)", run)}


def test_algorithm_citations_are_parsed_with_ranges():
    assert algorithm_citations("(ALGORITHM.md §4–§5) and ALGORITHM.md §7, C1 and §9; ALGORITHM.md §2, §3") == {
        2,
        3,
        4,
        5,
        7,
    }


def test_every_algorithm_section_the_code_cites_is_a_heading_of_docs_algorithm_md():
    headings = {int(n) for n in re.findall(r"^## (\d+)\. ", (REPO / "docs" / "ALGORITHM.md").read_text(), flags=re.M)}
    cited = {
        (path.relative_to(REPO), n) for path in [*CODE, README, *DOCS] for n in algorithm_citations(path.read_text())
    }
    assert {n for _, n in cited} >= {1, 2, 3, 4, 5, 6, 7}  # the code's citations are all found
    assert not {c for c in cited if c[1] not in headings}, sorted(c for c in cited if c[1] not in headings)


ISSUE_LETTER = re.compile(r"\b[Ii]ssues? [A-L]\b|(?<![\w.])[A-L]'s\b")
"""How a project issue was cited: "issue H", "(issues D, E)", "E's protocol"."""


def user_facing_text() -> dict[str, str]:
    """README and docs/*.md; of RESULTS.md only its hand-written notes (the rest is generated)."""
    pages = {str(p.relative_to(REPO)): p.read_text() for p in [README, *DOCS]}
    results = pages["docs/RESULTS.md"]
    pages["docs/RESULTS.md"] = results[results.find(NOTES[0]) : results.find(NOTES[1])]
    return pages


def test_user_facing_docs_cite_no_issue_letters():
    assert [m.group(0) for m in ISSUE_LETTER.finditer("issue H, (issues D, E), E's protocol")] == [
        "issue H",
        "issues D",
        "E's",
    ]
    assert not ISSUE_LETTER.search("DQfD's margin, BCModel's fit, TD's target, C4's flags, the issue's goal")
    found = [
        f"{name}: {m.group(0)!r}" for name, text in user_facing_text().items() for m in ISSUE_LETTER.finditer(text)
    ]
    assert not found, found


@pytest.mark.slow
def test_the_quick_start_says_what_the_default_run_gives_on_any_cpu(tmp_path):
    """README's quick start: `train.py` with no flag stops early, at the first 10 episodes in a row
    that return ≥ 490, and evaluates at 500.00, on every machine. Its episodes and interactions depend
    on the CPU (float rounding), so the README says so and gives them per CPU, as counts a run that
    stops early can print: at least the 10 episodes of the rule, and at least their 10 × 490 steps."""
    text = README.read_text()
    start = text.index("## Quick start")
    quick_start = " ".join(text[start : text.index("\n## ", start)].split())
    assert "depend on the CPU" in quick_start, "the quick start no longer says that its figures vary by CPU"
    said = [(int(e), int(i.replace(",", ""))) for e, i in re.findall(r"(\d+) episodes and ([\d,]+) inter", quick_start)]
    assert said and all(episodes >= 10 and interactions >= 10 * 490 for episodes, interactions in said), said
    run = subprocess.run(
        [sys.executable, "train.py", "--out", str(tmp_path / "run")],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr
    summary = re.search(
        r"^(\d+) episodes, (\d+) env steps, (\d+) interactions in all \(early stop\), \d+ s of training$",
        run.stdout,
        re.MULTILINE,
    )
    assert summary, run.stdout
    episodes, env_steps = int(summary[1]), int(summary[2])
    with open(tmp_path / "run" / "metrics.csv") as file:
        rows = list(csv.DictReader(file))
    assert len(rows) == episodes >= 10 and int(rows[-1]["env_step"]) == env_steps >= 10 * 490
    assert min(float(row["return"]) for row in rows[-10:]) >= 490  # the rule, met
    assert len(rows) == 10 or float(rows[-11]["return"]) < 490  # and met then for the first time
    assert "return 500.00 ± 0.00  (min 500, max 500, solved at 475)" in run.stdout
