"""``python -m bgc.cli ARGS``: the ``bgc`` command."""

from bgc.cli import main

main()
