"""The three ways of handling a blocked joint direction (paper 11.2.5): parasitic, lagrange,
zcp; and the run-time side of constraints (consistent initial conditions, drift, rank)."""
