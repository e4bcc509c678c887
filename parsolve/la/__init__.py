"""Linear algebra: the distributed saddle-point layout (numpy) and its PETSc operator."""
