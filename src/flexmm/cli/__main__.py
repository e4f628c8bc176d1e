"""``python -m flexmm.cli``: the ``flexmm`` command."""

from flexmm.cli import main

main()
