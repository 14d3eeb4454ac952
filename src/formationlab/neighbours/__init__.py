"""Neighbour search: which robots are close to each other.

* :mod:`.kdtree`: one-off queries with scipy's k-d tree (close pairs of saved states, the
  pairs that are not edges).

The compiled loop's searches, rebuilt as robots move, are beside it: the close-pair
(Verlet) list on a cell grid (:mod:`formationlab.engine.close_list`) and the safety
filter's grid of cells (:mod:`formationlab.safety.cell_grid`).
"""
