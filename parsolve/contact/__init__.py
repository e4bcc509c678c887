"""Contact and friction building blocks: pairing, obstacles, relation rows, Coulomb logic,
analytic references (pure numpy); the surfaces as every rank holds them and the rows' values
on a rank's part of the mesh (``surfaces``; the values through ``parsolve.la.dofmap``). The contact/friction
effects assemble relations from them."""
