"""The integrators behind one interface (``base.Solver``): native Radau IIA and RK4 step
loops, SUNDIALS; the sparse LU of Radau's Newton matrices."""
