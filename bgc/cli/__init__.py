"""The ``bgc`` command line: check, compile, simulate, report, frf, modes, tune, sweep, run,
bench, draw, export, library, energy.

One module per command (``check``, ``compile``, ``simulate``, ``report``, ``frf``,
``modes``, ``tune``, ``sweep``, ``run``, ``bench``, ``draw``, ``export``, ``library``,
``energy``), each
registering itself on the group ``app.main``; ``app``
holds the group and the error policy (user mistakes as one line, exit 2; Ctrl-C, exit 130),
``options`` what several commands share. The long stages report their progress on stderr
(``bgc.progress``: a live display on a terminal, else one ``bgc: ...`` line per stage;
nothing with ``--quiet``); stdout holds only the command's own output.

A command module imports at its top only what is light: sympy, the loader and the code
generator are imported where a command needs them, so that ``bgc simulate`` on a fresh
module loads none of them (tests/cli/test_warm_start.py).
"""

from bgc.cli import (  # noqa: F401
    bench,
    energy,
    check,
    compile,
    draw,
    export,
    frf,
    library,
    modes,
    report,
    run,
    simulate,
    sweep,
    tune,
)
from bgc.cli.app import entry, main

__all__ = ["entry", "main"]
