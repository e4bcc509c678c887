"""A bar pulled at its end, clamped at the other, with an optional stop on the end's mean
displacement whose reaction is a load pattern ("stop_force"): the non-associated relation of
tests/solvers/test_orientation.py and tests/solvers/test_problem.py."""

BAR = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.1
nx = 10
ny = 2
cell = "quad"
[model]
hypothesis = "plane_stress"
[regions]
corner = {{ point = [0.0, 0.0] }}
[[materials]]
E = 1e3
nu = 0.0
[[loads]]
name = "pull"
region = "right"
traction = [{pull}, 0.0]
[[loads]]
name = "stop_force"
region = "right"
traction = [{dual}, 0.0]
[[relations]]
name = "clamp"
type = "dirichlet"
region = "left"
components = ["x"]
[[relations]]
name = "corner"
type = "dirichlet"
region = "corner"
components = ["y"]
{stop}
[steps]
count = 4
"""

STOP = """[[relations]]
name = "stop"
type = "mean"
region = "right"
component = "x"
value = {value}
sense = "{sense}"
evolution = "constant"
dual = "stop_force"
"""


def stop_bar(pull: float = 0.3, dual: float = 0.0, value: float | None = None,
             sense: str = "<=") -> str:
    """The bar's scene; with ``value``, the stop u_end (sense) value."""
    stop = "" if value is None else STOP.format(value=value, sense=sense)
    return BAR.format(pull=pull, dual=dual, stop=stop)
