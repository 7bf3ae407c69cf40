"""bgc: a symbolic, code-generating bond-graph compiler.

Pipeline (see DESIGN.md): load -> expand -> causality -> equations -> emit -> simulate.
"""

import os

__version__ = "0.1.0"

# numba formats a message for every typing template a call does not match; with colorama
# installed it colours each one, which cost 6 % of a large module's cold compile. Read
# when numba is first imported, so it is set before any of bgc's modules import numba.
os.environ.setdefault("NUMBA_DISABLE_ERROR_MESSAGE_HIGHLIGHTING", "1")
