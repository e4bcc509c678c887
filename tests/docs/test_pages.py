"""The hand-written pages against the repository: every shipped scene in the guide's table,
every script and scene file they name present, every citation of the source paper linked, and
the README's docs command building the site from a fresh copy of the repository."""
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PAGES = sorted((ROOT / "docs").rglob("*.md")) + [ROOT / "README.md"]
GENERATED = {ROOT / "docs" / "benchmarks.md", ROOT / "docs" / "reference" / "scene.md"}


def shipped_table() -> set[str]:
    """The scene names of the first column of the guide's "Shipped scenes" table."""
    text = (ROOT / "docs" / "guide.md").read_text()
    section = text.split("\n## Shipped scenes\n", 1)[1].split("\n## ", 1)[0]
    return set(re.findall(r"^\| `([^`]+\.toml)` \|", section, re.M))


def test_every_shipped_scene_is_in_the_guides_table():
    shipped = {p.name for p in (ROOT / "configs").glob("*.toml")}
    table = shipped_table()
    assert len(shipped) >= 22
    assert shipped - table == set(), "configs/ scenes missing from the guide's table"
    assert table - shipped == set(), "the guide's table names scenes configs/ lacks"


def test_every_file_the_pages_name_exists():
    """`scripts/x.py`, `configs/y.toml`, `tests/...` named in a page are in the repository."""
    named = re.compile(r"(?<![\w/.])((?:scripts|configs|tests|parsolve)/[\w./-]+\.(?:py|sh|toml|msh|md))")
    missing = []
    for page in PAGES:
        if page in GENERATED:
            continue
        for path in set(named.findall(page.read_text())):
            if not (ROOT / path).exists() and "*" not in path:
                missing.append(f"{page.relative_to(ROOT)}: {path}")
    assert not missing, missing


def test_the_source_paper_is_cited_with_its_reference():
    """"the paper" always links to the reference in docs/theory.md (outside code)."""
    theory = (ROOT / "docs" / "theory.md").read_text()
    assert "\n## The source paper\n" in theory
    bare = []
    for page in PAGES:
        if page in GENERATED:
            continue
        text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)   # code blocks
        text = re.sub(r"^    .*$", "", text, flags=re.M)                             # indented code
        for m in re.finditer(r"(?<!\[)\b[Tt]he paper\b(?!\]\()", text):
            bare.append(f"{page.relative_to(ROOT)}: …{text[max(0, m.start() - 30):m.end() + 20]}…")
    assert not bare, bare


def test_the_readme_sentences_are_whole():
    """No paragraph of the README runs into a heading (a cut-off sentence)."""
    lines = (ROOT / "README.md").read_text().splitlines()
    for before, line in zip(lines, lines[1:]):
        if line.startswith("#"):
            assert before.strip() == "", f"text runs into the heading {line!r}: {before!r}"


def readme_docs_command() -> str:
    text = (ROOT / "README.md").read_text()
    commands = re.findall(r"`(bash scripts/docs\.sh site/)`", text)
    assert commands, "the README gives no docs command with a site folder"
    return commands[0]


def repository_copy(dest: Path) -> None:
    """The files a fresh clone of this working tree has (tracked and new, not ignored)."""
    listed = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT,
                            capture_output=True, check=True).stdout.decode().split("\0")
    for name in filter(None, listed):
        src = ROOT / name
        if src.is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / name)


@pytest.mark.serial
@pytest.mark.slow
def test_readme_docs_command_builds_the_site_from_a_fresh_copy(tmp_path):
    """The README's exact command, relative site folder, in a copy without .venv: the script
    sets up the environment itself, regenerates the pages and pictures, checks every anchor."""
    clone = tmp_path / "clone"
    repository_copy(clone)
    assert not (clone / ".venv").exists()
    done = subprocess.run(readme_docs_command(), shell=True, cwd=clone, capture_output=True,
                          text=True, timeout=900)
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    assert "broken anchors" not in done.stderr
    site = clone / "site"
    for page in ("index.html", "guide/index.html", "reference/scene/index.html",
                 "theory/index.html"):
        assert (site / page).is_file(), page
    assert (clone / ".venv" / "bin" / "python").exists()
    # the generated pages of the copy are those committed here (nothing drifted in the build)
    for page in GENERATED:
        assert (clone / page.relative_to(ROOT)).read_text() == page.read_text(), page


def test_pages_speak_as_a_reference():
    """No tracker numbers, branch notes or changelog asides in the pages (the generated
    benchmark page included: its sources are scripts/results/*.md)."""
    stale = re.compile(r"\bissue \d+|\bthis branch\b|\bmain at\b|\(it was [^)]*\)|\bnow runs\b|"
                       r"bench_distributed", re.I)
    found = []
    for page in PAGES:
        for m in stale.finditer(page.read_text()):
            found.append(f"{page.relative_to(ROOT)}: {m.group(0)!r}")
    assert not found, found
