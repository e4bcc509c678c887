"""The small non-associated scene whose saddle system tests/la/ gathers and checks."""

SCENE = """
[mesh]
generator = "rectangle"
lx = 1.0
ly = 0.2
nx = 10
ny = 3
cell = "{cell}"
[model]
hypothesis = "plane_stress"
[regions]
corner = {{ point = [0.0, 0.0] }}
mid = "x == 0.5"
[[materials]]
E = 1e3
nu = 0.25
[[loads]]
name = "pull"
region = "right"
total_force = [1.0, 0.0]
[[loads]]
name = "weight"
body = [0.0, -0.3]
[[relations]]
name = "left_x"
type = "dirichlet"
region = "left"
components = ["x"]
[[relations]]
name = "corner_y"
type = "dirichlet"
region = "corner"
components = ["y"]
[[relations]]
name = "top_flat"
type = "equal"
region = "top"
component = "y"
[[relations]]
name = "opening"
type = "linear"
terms = [{{ region = "right", component = "x", mean = true }},
         {{ region = "mid", component = "x", coefficient = -1.0, mean = true }}]
value = 1e-3
dual = "pull"
[solver]
preset = "{preset}"
eliminate = {eliminate}
"""
