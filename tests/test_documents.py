"""The documents stay short and their links stay whole.

README.md is the front door (at most 12 KB); each reference file in docs/ (not the experiment logs in
docs/experiments/) is at most 20 KB; each cell of BENCHMARKS.md's Summary table is at most 300 characters;
every relative link in README.md, BENCHMARKS.md and docs/**/*.md names a file that exists, and a `#anchor`
names a heading of that file (GitHub's slugs). Each check is a function of paths, so the tests below also
run it on broken copies and see it fail.
"""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

README_LIMIT = 12 * 1024
REFERENCE_LIMIT = 20 * 1024
CELL_LIMIT = 300

_FENCE = re.compile(r"^\s*(```|~~~)")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_INLINE_CODE = re.compile(r"`+[^`]*`+")
_HTML_ANCHOR = re.compile(r"<a\s+(?:name|id)=\"([^\"]+)\"", re.IGNORECASE)


def _prose_lines(text: str) -> list[str]:
    """The lines outside fenced code blocks."""
    lines, fenced = [], False
    for line in text.splitlines():
        if _FENCE.match(line):
            fenced = not fenced
            continue
        if not fenced:
            lines.append(line)
    return lines


def slug(heading: str) -> str:
    """GitHub's anchor for a heading's text: markup dropped, lower case, punctuation removed, spaces to '-'."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading)  # a link keeps its text
    text = re.sub(r"<[^>]+>", "", text)  # inline HTML
    text = text.strip().lower()
    kept = []
    for char in text:
        if char in " -_" or unicodedata.category(char)[0] in "LNM":
            kept.append(char)
    return "".join(kept).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every anchor a markdown file offers: its headings' slugs (repeats get -1, -2, ...) and HTML anchors."""
    found: set[str] = set()
    seen: dict[str, int] = {}
    for line in _prose_lines(path.read_text(encoding="utf-8")):
        match = _HEADING.match(line)
        if match:
            base = slug(match.group(2))
            count = seen.get(base, 0)
            seen[base] = count + 1
            found.add(base if count == 0 else f"{base}-{count}")
        found.update(_HTML_ANCHOR.findall(line))
    return found


def links(path: Path) -> list[str]:
    """The link targets of a markdown file's prose (code blocks and inline code left out)."""
    targets = []
    for line in _prose_lines(path.read_text(encoding="utf-8")):
        targets.extend(_LINK.findall(_INLINE_CODE.sub("", line)))
    return targets


def broken_links(files: list[Path]) -> list[str]:
    """Relative links (and their #anchors) that name nothing; http(s) and mailto links are not checked."""
    problems = []
    for path in files:
        for target in links(path):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.IGNORECASE):  # http:, https:, mailto:
                continue
            file_part, _, anchor = target.partition("#")
            linked = (path.parent / file_part).resolve() if file_part else path
            if not linked.exists():
                problems.append(f"{path}: {target}: no such file")
            elif anchor and linked.suffix == ".md" and anchor.lower() not in anchors(linked):
                problems.append(f"{path}: {target}: no heading with that anchor")
    return problems


def too_large(path: Path, limit: int) -> list[str]:
    size = path.stat().st_size
    return [f"{path}: {size} bytes, over {limit}"] if size > limit else []


def reference_files(docs: Path) -> list[Path]:
    """docs/*.md: the reference, not the experiment logs under docs/experiments/."""
    return sorted(docs.glob("*.md"))


def oversized_references(docs: Path) -> list[str]:
    return [problem for path in reference_files(docs) for problem in too_large(path, REFERENCE_LIMIT)]


def summary_cells(benchmarks: Path) -> list[str]:
    """The cells of the table under BENCHMARKS.md's "## Summary" heading (`\\|` does not split a cell)."""
    cells, inside = [], False
    for line in benchmarks.read_text(encoding="utf-8").splitlines():
        if line.startswith("## "):
            inside = line.strip() == "## Summary"
            continue
        if not inside or not line.lstrip().startswith("|"):
            continue
        row = re.split(r"(?<!\\)\|", line.strip().strip("|"))
        if all(re.fullmatch(r"\s*:?-+:?\s*", cell) for cell in row):
            continue  # the header's rule
        cells.extend(cell.strip() for cell in row)
    return cells


def long_summary_cells(benchmarks: Path) -> list[str]:
    return [
        f"{len(cell)} characters: {cell[:80]}..." for cell in summary_cells(benchmarks) if len(cell) > CELL_LIMIT
    ]


def documents(root: Path) -> list[Path]:
    return [root / "README.md", root / "BENCHMARKS.md", *sorted((root / "docs").rglob("*.md"))]


# The project's documents.


def test_readme_is_at_most_12_kb():
    assert too_large(ROOT / "README.md", README_LIMIT) == []


def test_each_docs_reference_file_is_at_most_20_kb():
    assert reference_files(ROOT / "docs"), "no reference files found in docs/"
    assert oversized_references(ROOT / "docs") == []


def test_benchmarks_summary_cells_are_at_most_300_characters():
    assert len(summary_cells(ROOT / "BENCHMARKS.md")) > 10, "the Summary table was not found"
    assert long_summary_cells(ROOT / "BENCHMARKS.md") == []


def test_relative_links_name_files_and_headings_that_exist():
    assert broken_links(documents(ROOT)) == []


# The checks fail on broken copies.


def _copy(tmp_path: Path, text: str, name: str) -> Path:
    path = tmp_path / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def test_an_oversized_readme_or_reference_fails(tmp_path):
    readme = _copy(tmp_path, "x" * (README_LIMIT + 1), "README.md")
    assert too_large(readme, README_LIMIT)
    _copy(tmp_path, "# ok\n", "docs/small.md")
    _copy(tmp_path, "y" * (REFERENCE_LIMIT + 1), "docs/big.md")
    _copy(tmp_path, "z" * (REFERENCE_LIMIT * 3), "docs/experiments/log.md")  # the logs are exempt
    problems = oversized_references(tmp_path / "docs")
    assert len(problems) == 1 and "big.md" in problems[0]


def test_a_long_summary_cell_fails(tmp_path):
    row = "| a | b \\| c | " + "w" * (CELL_LIMIT + 1) + " | d |"
    text = "# B\n\n## Summary\n\n| what | figure | date |\n|---|---|---|\n" + row + "\n\n## Other\n\n| " + (
        "v" * 999
    ) + " |\n"
    path = _copy(tmp_path, text, "BENCHMARKS.md")
    assert summary_cells(path)[:3] == ["what", "figure", "date"]
    assert "b \\| c" in summary_cells(path)  # an escaped bar stays in its cell
    assert len(long_summary_cells(path)) == 1  # the table of another section is not the Summary's


def test_a_broken_link_or_anchor_fails(tmp_path):
    _copy(tmp_path, "# Target\n\n## The person's detail: `what` stays\n\n## Repeat\n\n## Repeat\n", "docs/t.md")
    good = _copy(
        tmp_path,
        "[a](docs/t.md) [b](docs/t.md#the-persons-detail-what-stays) [c](docs/t.md#repeat-1) "
        "![d](docs/t.md) [e](https://example.com/x.md) [f](mailto:a@b.c) [g](#top)\n\n# Top\n"
        "```\n[not a link](missing.md)\n```\n`[code](missing.md)`\n",
        "README.md",
    )
    assert broken_links([good]) == []
    bad = _copy(
        tmp_path,
        "[a](docs/missing.md) ![b](img/none.jpg) [c](docs/t.md#no-such-heading) [d](#nowhere)\n",
        "BAD.md",
    )
    problems = broken_links([bad])
    assert len(problems) == 4, problems


def test_slugs_follow_github():
    assert slug("Photos without cast shadows (`--preset no-cast-shadows`)") == (
        "photos-without-cast-shadows---preset-no-cast-shadows"
    )
    assert slug("2. The scene's light (`deface/priors/illuminant.py`)") == "2-the-scenes-light-defacepriorsilluminantpy"
    assert slug("Quick start") == "quick-start"
