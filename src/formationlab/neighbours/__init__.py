"""Neighbour search: which robots are close to each other, written once.

* :mod:`.cell_grid`: points binned into cells, squares in the plane and cubes in space (a
  counting sort, compiled), and each point's neighbours within a radius (the safety
  filter's sensing radius);
* :mod:`.close_list`: the close-pair (Verlet) list of the compiled loop on that grid
  (Khatib's repulsion and contact of large formations), rebuilt only when some robot has
  moved half its skin;
* :mod:`.kdtree`: one-off queries with scipy's k-d tree (close pairs of saved states, the
  pairs that are not edges), where a query is simpler than a grid.
"""
