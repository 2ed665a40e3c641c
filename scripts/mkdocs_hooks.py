"""MkDocs hooks (mkdocs.yml, `hooks:`). The pages' code fences carry words after the language for
the suite's snippet runner (```` ```python fixture:fxis_service ````, ```` ```json request ````;
tests/docsnippets.py); Markdown's fences take the language alone, so the site sees the language
alone."""

from __future__ import annotations

import re

_FENCE_WORDS = re.compile(r"^(?P<fence>[ \t]*`{3,})(?P<lang>[\w#.+-]+)[ \t]+[^`{\n]*$", re.MULTILINE)


def on_page_markdown(markdown: str, **kwargs: object) -> str:
    return _FENCE_WORDS.sub(r"\g<fence>\g<lang>", markdown)
