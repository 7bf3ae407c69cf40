"""bgc: a symbolic, code-generating bond-graph compiler.

Pipeline (see DESIGN.md): load -> expand -> causality -> equations -> emit -> simulate.
"""

__version__ = "0.1.0"
