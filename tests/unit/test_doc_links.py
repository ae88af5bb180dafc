"""Every relative link of the README and the guides leads somewhere.

A link to a file must name one that exists in this checkout, and a link to
a section (``page.md#anchor``, or ``#anchor`` within the page) must name a
heading of that page by the anchor GitHub gives it. Links with a scheme
(``https:``, ``mailto:``) are not followed. pytest-check-links was looked
at: it checks anchors in HTML pages only, not in the Markdown pages linked
here.
"""

from __future__ import annotations

import functools
import os
import re
import unicodedata

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
_LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
_HEADING = re.compile(r"^#{1,6}[ \t]+(.*?)[ \t]*#*[ \t]*$", re.M)
_FENCE = re.compile(r"^[ \t]*```.*?^[ \t]*```", re.M | re.S)


def documents() -> list[str]:
    """The README and every Markdown page under docs/, as paths relative to the checkout."""
    pages = ["README.md"]
    for folder, _, files in os.walk(os.path.join(ROOT, "docs")):
        pages += [os.path.relpath(os.path.join(folder, f), ROOT) for f in sorted(files) if f.endswith(".md")]
    return pages


def _text(path: str) -> str:
    """A page's text without its fenced code blocks (whose ``#`` lines are not headings)."""
    with open(path, encoding="utf-8") as f:
        return _FENCE.sub("", f.read())


def slug(heading: str) -> str:
    """The anchor GitHub gives a heading: lower case, code marks and link
    targets dropped, spaces as hyphens, punctuation and symbols removed."""
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.replace("`", "")).strip().lower()
    return "".join("-" if ch == " " else ch for ch in text if ch in "-_ " or unicodedata.category(ch)[0] in "LN")


@functools.cache
def anchors(path: str) -> frozenset[str]:
    """Every heading anchor of a page (a repeated heading's later ones get ``-1``, ``-2``, ...);
    read once per page, however many links point into it."""
    seen: dict[str, int] = {}
    out = set()
    for match in _HEADING.finditer(_text(path)):
        base = slug(match.group(1))
        count = seen.get(base, 0)
        seen[base] = count + 1
        out.add(base if count == 0 else f"{base}-{count}")
    return frozenset(out)


def test_the_anchor_rule_follows_github():
    assert slug("Torch's threads for the update") == "torchs-threads-for-the-update"
    assert slug("The asynchronous API: overlap the policy with physics") == (
        "the-asynchronous-api-overlap-the-policy-with-physics"
    )
    assert slug("Measuring: `python -m remoteenv bench --batched`") == "measuring-python--m-remoteenv-bench---batched"
    assert slug("remoteenv ÷ EnvPool, N = 16") == "remoteenv--envpool-n--16"


@pytest.mark.parametrize("document", documents())
def test_every_relative_link_resolves(document):
    path = os.path.join(ROOT, document)
    broken = []
    for match in _LINK.finditer(_text(path)):
        url = match.group(1)
        if re.match(r"[A-Za-z][A-Za-z0-9+.-]*:", url):
            continue
        target_part, _, anchor = url.partition("#")
        target = os.path.normpath(os.path.join(os.path.dirname(path), target_part)) if target_part else path
        if not os.path.exists(target):
            broken.append(f"{url}: no such file")
        elif anchor and target.endswith(".md") and anchor not in anchors(target):
            broken.append(f"{url}: no heading with that anchor in {os.path.relpath(target, ROOT)}")
    assert not broken, f"{document} has broken links (fix the link or the heading): " + "; ".join(broken)
