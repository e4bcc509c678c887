"""Newton on the distributed mesh against the one rank alone where a prescribed, eliminated
DOF sits in a multiplied relation's row: the displacement-controlled softening bar (its right
edge kept straight by an `equal` relation that names the controlled node)."""

import numpy as np
from mpi4py import MPI

from helpers.control import displacement_control


def test_prescribed_dof_in_a_relation_row_on_the_parts(run, comm):
    """The elastic steps before the peak: the same forces and displacements on both meshes
    (the lifting of the `equal` rows needs the prescribed node's value on every rank)."""
    text = displacement_control().replace("count = 24", f"count = 5\nend = {5 / 24!r}")
    assert "count = 5" in text
    whole = run(text, name="whole", comm=MPI.COMM_SELF)
    parts = run(text, name="parts")
    force = -parts["relations/end_displacement/multiplier"][:, 0]
    np.testing.assert_allclose(force, 1e3 * np.arange(1, 6), rtol=1e-9)
    for key in ("fields/displacement", "relations/right_rigid/multiplier",
                "relations/left_x/multiplier", "cell_fields/stress"):
        scale = np.abs(whole[key]).max()
        assert np.abs(parts[key] - whole[key]).max() <= 1e-10 * scale, key
