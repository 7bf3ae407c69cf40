"""Rigid-body mechanics of the paper (11.2): Cardan angles, joint models, exact geometry."""
