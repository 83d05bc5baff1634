"""The smallest complete run the CLI and loader tests vary: one config text, read as TOML or written to a file."""

#: A small but complete chemotaxis run: 8 x 8 squares of (0, 4)^2, five steps, no pictures.
SMALL_CONFIG = """\
[model]
name = "small"
physics = ["chemotaxis"]

[kinetics]
name = "painter2018"

[parameters]
m0 = 0.75
D_m = 0.03

[mesh]
type = "rectangle"
upper = [4.0, 4.0]
cells = [8, 8]

[time]
dt = 0.2
t_final = 1.0

[output]
pictures = false
"""
