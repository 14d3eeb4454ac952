"""The paper's triangle as scenario text, shared by the command-line tests.

``triangle(name, duration, extra)`` is the section-4 formation (robots, distances, the
simulation-2 alpha table and the paper's gains) with explicit Euler at dt = 1e-3, the
given ``duration`` (a number or a placeholder the test replaces) and ``extra`` tables.
"""

TABLES = """\
[robots]
positions = [[-3.0, -3.0], [3.0, -3.0], [0.0, 3.0]]
diameters = 0.2
[formation]
edges = "complete"
distances = 1.0
orientation = "table"
alpha = [[1, 2, 3, 1.0], [3, 1, 2, 1.0], [2, 1, 3, -1.0]]
[controller]
law = "angle-restricted"
k_c = 2.0
k_a = 3.0
theta = 0.5
[simulation]
integrator = "euler"
dt = 1e-3
"""


def triangle(name: str, duration: str, extra: str = "") -> str:
    """Scenario text of the paper's triangle named ``name``."""
    return f'name = "{name}"\n{TABLES}duration = {duration}\n{extra}'
