"""``parsolve post --summary``'s contact table against the states and forces in the file: the
block on a rough plane (pressure 10 on a unit length, μ = 0.3) slides once the friction
reaches μ N = 3."""

import re

import numpy as np

from conftest import CONFIGS
from parsolve.post.cli import main
from parsolve.post.result import Result
from parsolve.post.summary import contacts


def test_contact_totals_and_counts_per_step(run, capsys):
    run(CONFIGS / "contact_block_friction.toml", name="block_summary")
    with Result(run.last) as res:
        c = contacts(res)["base"]
        state = res.file["fields/base_state"][()][..., 0]
        rn = res.file["relations/base_normal/normal_force"][()][:, 0]
        rt = res.file["relations/base_normal/tangential_force"][()]
        nodal_rn = res.file["fields/base_normal_reaction"][()][..., 0].sum(axis=1)
    # nine slave nodes, each open, stick or slip at every step
    assert (c["open"] + c["stick"] + c["slip"] == 9).all()
    for k, name in enumerate(("open", "stick", "slip")):
        np.testing.assert_array_equal(c[name], (state == k).sum(axis=1))
    np.testing.assert_allclose(c["normal"], 10.0, rtol=1e-10)        # the pressure's total
    np.testing.assert_allclose(nodal_rn, rn, rtol=1e-10)             # the nodes' reactions add up
    np.testing.assert_allclose(c["ratio"], np.abs(rt[:, 0]) / rn, rtol=1e-12)
    np.testing.assert_allclose(c["ratio"][-1], 0.3, rtol=1e-10)      # at the cone: μ
    assert (c["ratio"] <= 0.3 * (1 + 1e-10)).all() and c["stick"][0] > 0 and c["slip"][-1] > 0
    assert main([str(run.last), "--summary"]) == 0
    text = capsys.readouterr().out
    assert "contact base per step: ΣRn, ΣRt (tangent basis), |ΣRt|/ΣRn, rows open / stick / slip" in text
    last = re.search(r"^\s+10\s+t\s+1\s+ΣRn\s+(\S+)\s+ΣRt\s+(\S+)\s+ratio\s+(\S+)\s+open (\d+) "
                     r"stick (\d+) slip (\d+)$", text, re.M)
    assert last, text
    np.testing.assert_allclose([float(v) for v in last.groups()[:3]], [10, abs(rt[-1, 0]), 0.3],
                               rtol=1e-5)
    assert [int(v) for v in last.groups()[3:]] == [c["open"][-1], c["stick"][-1], c["slip"][-1]]
