"""The README and docs/: a short README that keeps the markers CI and the benchmark report read,
Python examples that run, and relative links that all land on a file and heading of the
repository."""

from __future__ import annotations

import io
import re
import sys
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, *sorted((ROOT / "docs").glob("*.md"))]
FENCE = re.compile(r"^```.*?^```", re.S | re.M)


def _between(text: str, begin: str, end: str) -> str:
    assert text.count(begin) == 1 and text.count(end) == 1, (begin, end)
    start, stop = text.index(begin), text.index(end)
    assert start < stop, (begin, end)
    return text[start + len(begin) : stop]


def test_readme_is_at_most_250_lines():
    # Issue 41: the README says what pinsettle is and how to start; the rest lives in docs/.
    assert len(README.read_text().splitlines()) <= 250


def test_readme_keeps_the_test_command_and_the_speed_summary():
    text = README.read_text()
    # .ci/run reads the test command between these markers; benchmarks/report.py rewrites the
    # block between the others.
    command = _between(text, "<!-- ci:test-command -->", "<!-- /ci:test-command -->")
    assert re.search(r"^```bash\npip install .*&& pytest\n```$", command, re.M), command
    summary = _between(
        text, "<!-- bench:summary (written by benchmarks/report.py) -->", "<!-- /bench:summary -->"
    )
    assert "docs/benchmarks.md" in summary


# A line of a README example that prints, with a trailing comment: the output it prints.
PRINT_WITH_OUTPUT = re.compile(r"^print\(.*\)\s*#\s*(?P<output>.+)$")
# A number as printed or as quoted (a quote may end in "...": its digits cut, not rounded).
NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?:\.\.\.)?(?![\w.])")


def _quote_mismatch(printed: str, quoted: str) -> str | None:
    """Why ``printed`` is not what the comment ``quoted`` says it prints (None: it is). The
    words and signs must match; an integer exactly; a decimal number to the digits shown
    (within half a unit of its last digit, or below one unit above it when it ends in "...")."""
    words = NUMBER.sub("#", printed).split(), NUMBER.sub("#", quoted).split()
    if words[0] != words[1]:
        return f"prints {printed!r}, the comment says {quoted!r}"
    # The same words around: as many numbers.
    for got_text, shown in zip(NUMBER.findall(printed), NUMBER.findall(quoted), strict=True):
        cut = shown.endswith("...")
        digits = shown.removesuffix("...")
        got, want = float(got_text), float(digits)
        if not re.search(r"[.eE]", digits):
            if got != want:
                return f"prints {got_text}, the comment says {shown}"
            continue
        mantissa, _, exponent = digits.lower().partition("e")
        decimals = len(mantissa.partition(".")[2])
        unit = 10.0 ** (int(exponent or 0) - decimals)  # of the last digit shown
        slack = 1e-9 * unit  # the decimal digits' binary round-off
        if cut:  # the same sign, and the digits shown then more
            close = got * want >= 0 and -slack <= abs(got) - abs(want) < unit + slack
        else:
            close = abs(got - want) <= unit / 2 + slack
        if not close:
            return f"prints {got_text}, the comment says {shown} (to the digits shown)"
    return None


def test_quoted_output_is_compared_to_the_digits_shown():
    assert _quote_mismatch("converged 23 2.249070279087094e-15", "converged 23 2.2e-15") is None
    assert _quote_mismatch("{'hinge': 0.637354} stable", "{'hinge': 0.6373...} stable") is None
    # A stale comment fails: another step count, another residual, another word.
    assert _quote_mismatch("converged 23 2.249070279087094e-15", "converged 48 2.9e-15")
    assert _quote_mismatch("converged 23 2.249070279087094e-15", "converged 23 2.9e-15")
    assert _quote_mismatch("max_steps 23 2.249070279087094e-15", "converged 23 2.2e-15")
    assert _quote_mismatch("{'hinge': 0.6372} stable", "{'hinge': 0.6373...} stable")
    assert _quote_mismatch("converged 23 2.26e-15", "converged 23 2.2e-15")  # rounds to 2.3
    assert _quote_mismatch("{'hinge': -0.63735} stable", "{'hinge': 0.6373...} stable")


def test_readme_python_examples_run_and_print_what_their_comments_say():
    blocks = re.findall(r"^```python\n(.*?)^```", README.read_text(), re.S | re.M)
    assert len(blocks) >= 2
    printed: dict[int, str] = {}  # a block's line number -> what its print printed

    def record(*args: object, **kwargs: Any) -> None:
        out = io.StringIO()
        print(*args, **kwargs, file=out)
        printed[sys._getframe(1).f_lineno] = out.getvalue().rstrip("\n")

    namespace: dict[str, object] = {"print": record}
    quoted = 0
    for block in blocks:  # in order: a later example may use an earlier one's imports
        printed.clear()
        exec(compile(block, str(README), "exec"), namespace)
        for number, line in enumerate(block.splitlines(), start=1):
            found = PRINT_WITH_OUTPUT.match(line)
            if found:
                quoted += 1
                assert number in printed, f"README: {line!r} printed nothing"
                mismatch = _quote_mismatch(printed[number], found["output"].strip())
                assert mismatch is None, f"README: {line!r} {mismatch}"
    assert quoted >= 2  # the output comments are there to be checked


def test_readme_cpp_example_is_a_whole_program():
    # tests/test_cpp.py builds and runs it; this says early, without a build, that it is one.
    block = _between(README.read_text(), "-->\n```cpp\n", "```\n<!-- /cpp:readme-example -->")
    assert "<!-- cpp:readme-example" in README.read_text()
    assert "int main(" in block and "#include <iostream>" in block, block


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = heading.strip().lower().replace("`", "")
    return re.sub(r"[^\w\- ]", "", text).replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    anchors: set[str] = set()
    counts: dict[str, int] = {}
    for heading in re.findall(r"^#{1,6}\s+(.*)$", FENCE.sub("", path.read_text()), re.M):
        slug = _slug(heading)
        count = counts.get(slug, 0)
        counts[slug] = count + 1
        anchors.add(slug if count == 0 else f"{slug}-{count}")  # GitHub numbers repeats
    return anchors


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_land_on_a_file_and_heading_of_the_repository(page):
    text = FENCE.sub("", page.read_text())
    bad = []
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        dest = (page.parent / path).resolve() if path else page
        if not dest.is_relative_to(ROOT):
            bad.append(f"{target}: outside the repository")
        elif not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in _anchors(dest):
            bad.append(f"{target}: no heading #{anchor} in {dest.name}")
    assert not bad, bad


# The numbers of a solve quoted in the docs and the scene files (steps and damping events with
# the default settings) are checked against a fresh solve, so they cannot drift when a default
# changes. benchmarks/pictures.py rewrites the playback caption's; the scene files' by hand.
STEPS = re.compile(r"(\d+) steps, (\d+) damping events")


def _steps_and_events(scene_file: Path) -> tuple[int, int]:
    import pinsettle  # here: the other tests of this file need only the text

    result = pinsettle.solve(pinsettle.load_scene(scene_file))
    assert result.status == "converged", (scene_file.name, result.status)
    return result.steps, result.peaks


def test_playback_caption_says_the_steps_of_a_fresh_solve():
    page = (ROOT / "docs" / "playback.md").read_text()
    caption = re.search(r"!\[[^]]*\]\(play_ur5_tool_spring\.png\)", page)
    assert caption, "docs/playback.md shows no play_ur5_tool_spring.png"
    quoted = STEPS.search(caption.group(0))
    assert quoted, caption.group(0)
    measured = _steps_and_events(ROOT / "robots" / "ur5_tool_spring.toml")
    assert (int(quoted[1]), int(quoted[2])) == measured, "run python benchmarks/pictures.py"


SCENES_WITH_STEPS = sorted(
    path
    for path in (ROOT / "robots").glob("*.toml")
    if re.search(r"^# Expected: converged \(\d+ steps", path.read_text(), re.M)
)


def test_scene_files_quote_steps_somewhere():
    assert len(SCENES_WITH_STEPS) >= 5, SCENES_WITH_STEPS


@pytest.mark.parametrize("scene_file", SCENES_WITH_STEPS, ids=lambda p: p.stem)
def test_scene_file_comment_says_the_steps_of_a_fresh_solve(scene_file):
    quoted = STEPS.search(scene_file.read_text())
    assert quoted
    measured = _steps_and_events(scene_file)
    assert (int(quoted[1]), int(quoted[2])) == measured, f"update {scene_file.name}'s comment"
