"""The paper's triangle as scenario text, shared by the command-line tests.

``triangle(name, duration, extra)`` is the section-4 formation (robots, distances, the
simulation-2 alpha table and the paper's gains) with explicit Euler at dt = 1e-3, the
given ``duration`` (a number or a placeholder the test replaces) and ``extra`` tables.
``clear_starts(n, batch, seed)`` draws random positions of ``n`` robots clear of contact.
``lattice(n, law, duration)`` is a round patch of ``n`` robots of the triangular lattice
(Delaunay edges, a start drawn around the template), as ``examples/lattice-1000.toml``.
"""

import numpy as np

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


LATTICE = """
name = "lattice-{n}"
[robots]
positions = {{ around = "template", sigma = 0.05, seed = 1 }}
diameters = 0.2
[formation]
template = {{ lattice = "triangular", count = {n}, spacing = 1.0 }}
edges = "delaunay"
orientation = "{orientation}"
[controller]
law = "{law}"
repulsion = {{ eta = 1.0, influence = 0.3 }}
[simulation]
integrator = "euler"
dt = 1e-3
duration = {duration}
"""


def lattice(n: int, *, law: str = "distance", duration: float = 0.01) -> str:
    """Scenario text of ``n`` robots of the triangular lattice under ``law`` (the template's
    orientation for the angle-restricted law)."""
    orientation = "template" if law == "angle-restricted" else "free"
    return LATTICE.format(n=n, law=law, orientation=orientation, duration=duration)


def triangle(name: str, duration: str, extra: str = "") -> str:
    """Scenario text of the paper's triangle named ``name``."""
    return f'name = "{name}"\n{TABLES}duration = {duration}\n{extra}'


def clear_starts(n: int, batch: int, seed: int) -> np.ndarray:
    """``batch`` draws ``(batch, n, 2)`` of ``n`` robots in [-2, 2]^2, at least 0.3 m apart."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < batch:
        q = rng.uniform(-2, 2, (n, 2))
        r = np.linalg.norm(q[:, None] - q[None], axis=-1) + np.eye(n) * 9
        if r.min() > 0.3:
            out.append(q)
    return np.array(out)
