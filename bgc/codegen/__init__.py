"""Stages **equations**, **Jacobian**, **emit**, **kernels**: CausalGraph -> EquationSystem
-> the source of a generated module (Jinja template, LLVM IR kernels)."""
