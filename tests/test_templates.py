"""Lattice templates, in the plane and in space: counts, spacing, compactness, determinism
and errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial import cKDTree

from formationlab.errors import FormationError
from formationlab.formation.templates import LATTICE_DIM, LATTICES, lattice

#: neighbours of an interior point: triangular 6, square 4, honeycomb 3; in space simple
#: cubic 6, face-centred cubic 12, body-centred cubic 8
COORDINATION = {"triangular": 6, "square": 4, "hexagonal": 3, "cubic": 6, "fcc": 12, "bcc": 8}


@pytest.mark.parametrize("kind", sorted(LATTICES))
@pytest.mark.parametrize("count", [2, 3, 7, 19, 100, 1000])
@pytest.mark.parametrize("spacing", [1.0, 0.35])
def test_count_and_nearest_neighbour_distance(kind: str, count: int, spacing: float) -> None:
    pts = lattice(kind, count, spacing)
    assert pts.shape == (count, LATTICE_DIM.get(kind, 2))
    assert len(np.unique(np.round(pts / spacing, 9), axis=0)) == count
    dist, _ = cKDTree(pts).query(pts, k=2)
    np.testing.assert_allclose(dist[:, 1], spacing, rtol=1e-12)  # every point has one at s


@pytest.mark.parametrize("kind", sorted(LATTICES))
def test_interior_points_have_the_lattice_coordination(kind: str) -> None:
    pts = lattice(kind, 2000, 1.0)
    tree = cKDTree(pts)
    # well inside a patch of radius ~25 (in space ~7)
    centre = np.linalg.norm(pts, axis=1) < (10.0 if pts.shape[1] == 2 else 4.0)
    counts = np.array([len(tree.query_ball_point(p, 1.0 + 1e-9)) - 1 for p in pts[centre]])
    assert np.all(counts == COORDINATION[kind])
    # nothing closer than the spacing anywhere
    assert len(tree.query_pairs(1.0 - 1e-9)) == 0


@pytest.mark.parametrize("kind", sorted(LATTICES))
def test_patch_is_round_and_dense(kind: str) -> None:
    count = 5000
    pts = lattice(kind, count, 1.0)
    r = np.linalg.norm(pts, axis=1)
    # the count nearest points of a lattice fill a disc of area count * (area per point),
    # in space a ball of volume count * (volume per point)
    if pts.shape[1] == 2:
        radius = math.sqrt(count * LATTICES[kind] / math.pi)
    else:
        radius = (3.0 * count * LATTICES[kind] / (4.0 * math.pi)) ** (1.0 / 3.0)
    assert abs(r.max() - radius) < 1.5
    assert np.all(np.diff(r) >= -1e-9)  # ordered by distance from the centre
    assert np.linalg.norm(pts.mean(axis=0)) < 0.1


def test_known_small_patches() -> None:
    tri = lattice("triangular", 7, 2.0)  # the centre and its hexagon
    np.testing.assert_allclose(tri[0], [0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(np.linalg.norm(tri[1:], axis=1), 2.0)
    ang = np.sort(np.degrees(np.arctan2(tri[1:, 1], tri[1:, 0])))
    np.testing.assert_allclose(ang, [-120.0, -60.0, 0.0, 60.0, 120.0, 180.0], atol=1e-12)
    sq = lattice("square", 5, 1.0)
    np.testing.assert_allclose(sq, [[0, 0], [0, -1], [1, 0], [0, 1], [-1, 0]], atol=1e-15)
    hexa = lattice("hexagonal", 6, 1.0)  # one hexagon around the origin, circumradius = side
    np.testing.assert_allclose(np.linalg.norm(hexa, axis=1), 1.0)
    np.testing.assert_allclose(hexa.mean(axis=0), 0.0, atol=1e-15)


def test_deterministic_and_nested() -> None:
    a = lattice("triangular", 500, 1.0)
    np.testing.assert_array_equal(a, lattice("triangular", 500, 1.0))
    np.testing.assert_array_equal(a[:200], lattice("triangular", 200, 1.0))
    np.testing.assert_allclose(lattice("square", 50, 3.0), 3.0 * lattice("square", 50, 1.0))
    for kind in ("cubic", "fcc", "bcc"):  # in space too: a patch is the start of a bigger one
        np.testing.assert_array_equal(lattice(kind, 200), lattice(kind, 400)[:200])


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (("triangle", 10, 1.0), "did you mean 'triangular'"),
        (("cube", 10, 1.0), r"Known: triangular, square, hexagonal, cubic, fcc, bcc"),
        (("square", 1, 1.0), "count >= 2"),
        (("square", 2.5, 1.0), "count >= 2"),
        (("square", 10, 0.0), "positive finite"),
        (("square", 10, float("nan")), "positive finite"),
    ],
)
def test_errors(args: tuple, match: str) -> None:
    with pytest.raises(FormationError, match=match) as info:
        lattice(*args)
    assert info.value.key == "template"
