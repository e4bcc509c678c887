"""Contact and friction building blocks: pairing, obstacles, relation rows, Coulomb logic,
analytic references (pure numpy); the surfaces as every rank holds them and the rows' values
on a replicated or distributed mesh (``surfaces``, ``part_values``). The contact/friction
effects assemble relations from them."""
