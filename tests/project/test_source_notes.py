"""The source says what a comment means, never which issue asked for it (an issue number tells a reader nothing
once the issue is closed): no "issue 36", "Issue #47" in src/."""

import re

from conftest import ROOT

ISSUE_NUMBER = re.compile(r"\bissues? ?#?\d+", re.IGNORECASE)


def test_no_issue_numbers_in_the_source():
    found = [f"{path.relative_to(ROOT)}:{n}: {line.strip()}"
             for path in sorted((ROOT / "src" / "ncfmu").rglob("*")) if path.suffix in (".py", ".c", ".h")
             for n, line in enumerate(path.read_text().splitlines(), start=1) if ISSUE_NUMBER.search(line)]
    assert not found, "\n".join(found)


def test_the_rule_catches_the_forms_used():
    assert all(ISSUE_NUMBER.search(s) for s in ("(issue 47, the 11 modules)", '"Issue 36, lever 3"', "issue #5"))
    assert not ISSUE_NUMBER.search("tissue 3") and not ISSUE_NUMBER.search("the issue is 3 mm")
