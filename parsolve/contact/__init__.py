"""Contact and friction building blocks: pairing, obstacles, relation rows, Coulomb logic,
analytic references. Pure numpy; the contact/friction effects assemble relations from them."""
