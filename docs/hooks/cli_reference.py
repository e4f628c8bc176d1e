"""MkDocs hook: the command-line reference page (reference/cli.md), generated from the Typer app.

Typer's own documentation generator (``typer flexmm.cli utils docs``) walks ``flexmm.cli.app``
and writes every command's help text, usage, arguments and options — what ``flexmm COMMAND
--help`` prints — so the page cannot drift from the code.
"""

from __future__ import annotations

import subprocess
import sys

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File, Files

PAGE = "reference/cli.md"
INTRO = """\
Generated from the program at build time (`typer flexmm.cli utils docs`): each section is what
`flexmm COMMAND --help` prints. On a user error (a bad config, option or file) every command
prints one `error: ...` line and exits with status 2, never a traceback; a failed run exits
with 1.
"""


def cli_markdown() -> str:
    """The reference page's Markdown."""
    cmd = [sys.executable, "-m", "typer", "flexmm.cli", "utils", "docs", "--name", "flexmm",
           "--title", "Command-line reference"]
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise PluginError(f"cli_reference: {' '.join(cmd[2:])} failed:\n{done.stderr[-2000:]}")
    title, _, rest = done.stdout.partition("\n")
    return f"{title}\n\n{INTRO}{rest}"


def on_files(files: Files, config) -> Files:
    """Add the generated page to the site."""
    files.append(File.generated(config, PAGE, content=cli_markdown()))
    return files
