"""MkDocs hook: the quick build, which checks the site without running anything.

With ``FLEXMM_DOCS_QUICK=1`` in the environment, ``mkdocs build --strict`` still renders every
page, the command-line and API references, and checks every link and anchor, but

- the tutorials' code blocks are shown, not executed (a fence ```` ```python exec="on" ... ````
  becomes a plain ```` ```python ````);
- the gallery uses the entries already made (``runs/docs/gallery``) and, for a scene without a
  current one, writes a page that says so instead of running the scene (``docs/hooks/gallery.py``).

The test suite builds the site this way (tests/test_docs_site.py); ``make docs`` builds it in full.
"""

from __future__ import annotations

import os
import re

#: the environment switch
QUICK = "FLEXMM_DOCS_QUICK"
#: the extra config key the other hooks read (set by ``on_config``)
KEY = "quick_build"
#: the opening line of an executed fence: its indent and backticks, its language, its options
_EXEC_FENCE = re.compile(r'^(?P<open>[ \t]*`{3,})[ \t]*(?P<lang>[\w-]+)[^\n]*\bexec="on"[^\n]*$', re.M)


def on_config(config):
    """Record whether this is a quick build for the other hooks."""
    config.extra[KEY] = os.environ.get(QUICK, "") not in ("", "0")
    return config


def on_page_markdown(markdown: str, page, config, files) -> str:
    """In a quick build, show the executable code blocks without executing them."""
    return _EXEC_FENCE.sub(r"\g<open>\g<lang>", markdown) if config.extra.get(KEY) else markdown
