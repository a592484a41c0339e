"""mkdocs hooks (mkdocs.yml, ``hooks:``): the config reference page is generated at build
time from the pydantic schema, so the validator and the documentation cannot drift
(issue #68).

docs/reference/config.md is a placeholder (what a reader of the repository sees: where the
reference comes from, how to print it in a terminal) holding the line ``MARKER``; the hook
replaces the whole page with ``designopt.app.reference.markdown()``, which brings its own
title and introduction. A missing generator, a generator that fails or returns nothing,
or a placeholder without the marker fails the build: the site is never built with an
empty reference. The generated text is never committed.
"""

from __future__ import annotations

from typing import Any

from mkdocs.exceptions import PluginError

PAGE = "reference/config.md"
MARKER = "<!-- generated: designopt.app.reference.markdown() -->"


def generated() -> str:
    """The config reference as Markdown, from ``designopt.app.reference.markdown()``."""
    try:
        from designopt.app import reference
    except ImportError as e:
        raise PluginError(
            f"{PAGE}: cannot import designopt.app.reference to generate the config reference "
            f"({e}); install the package (pip install -e .) in the environment that runs mkdocs"
        ) from e
    try:
        text = reference.markdown()
    except Exception as e:  # the generator's own failure, named
        raise PluginError(f"{PAGE}: designopt.app.reference.markdown() failed: {e!r}") from e
    if not isinstance(text, str) or not text.strip():
        raise PluginError(f"{PAGE}: designopt.app.reference.markdown() returned no text")
    return text


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    if page.file.src_uri != PAGE:
        return markdown
    if MARKER not in markdown:
        raise PluginError(
            f"{PAGE}: the line {MARKER} that the generated reference replaces is missing"
        )
    text = generated().strip() + "\n"
    if not text.startswith("# "):  # a title for the page when the generator gives none
        text = markdown.split("\n", 1)[0] + "\n\n" + text
    return text
