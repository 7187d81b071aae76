"""MkDocs hook: links from a docs page to a repository file outside ``docs/``.

The pages are read on GitHub too, where ``[text](../valve_gym/data/README.md)``
opens the file. The site holds only ``docs/``, so such a link would be broken
there (and ``mkdocs build --strict`` fails on it). This hook turns each into
the link text followed by the file's repository path in code, e.g.
``text (`valve_gym/data/README.md` in the repository)``. Links inside
``docs/`` are left to MkDocs, which checks them.

It also drops the Sphinx roles (``:func:``, ``:class:``, ...) that the API
reference would otherwise print in front of each name, and the ``~`` that
shortens a name in Sphinx.
"""
from __future__ import annotations

import posixpath
import re

_LINK = re.compile(r"(?<!!)\[([^\]]*)\]\(([^)\s]+)\)")
#: a Sphinx cross-reference role left in front of the code it marks (the docstrings are numpydoc, written
#: for Sphinx too): ``:func:`~valve_gym.metrics.travel``` renders as ``:func:<code>~valve_gym...</code>``
_ROLE = re.compile(r":(?:py:)?(?:func|mod|class|meth|data|attr|exc|obj|const|term|ref):(<code[^>]*>)~?")
_FENCE = re.compile(r"^(```|~~~)")


def _outside(page_path: str, target: str) -> str | None:
    """The repository path of ``target`` if it leaves ``docs/``, else None."""
    if re.match(r"[a-z]+:", target) or target.startswith("#"):
        return None
    path = target.partition("#")[0]
    joined = posixpath.normpath(posixpath.join("docs", posixpath.dirname(page_path), path))
    if joined == "docs" or joined.startswith("docs/"):
        return None
    return joined


def on_page_markdown(markdown: str, page, config, files):
    """Rewrite the page's links that leave ``docs/`` (outside code blocks)."""
    out, code = [], False
    src = page.file.src_uri
    for line in markdown.split("\n"):
        if _FENCE.match(line.lstrip()):
            code = not code
        if not code:
            def repl(m: re.Match) -> str:
                repo = _outside(src, m.group(2))
                if repo is None:
                    return m.group(0)
                text = m.group(1)
                return f"{text} (`{repo}` in the repository)" if text.strip("`") != repo else f"`{repo}`"
            line = _LINK.sub(repl, line)
        out.append(line)
    return "\n".join(out)


def on_page_content(html: str, page, config, files):
    """Drop Sphinx roles printed in front of inline code (the API reference)."""
    return _ROLE.sub(r"\1", html)
