"""``python -m dbtool.cli``: the ``dbtool`` command."""

from dbtool.cli.app import main

main()
