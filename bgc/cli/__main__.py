"""``python -m bgc.cli ARGS``: the ``bgc`` command."""

from bgc.cli.app import entry

entry()
