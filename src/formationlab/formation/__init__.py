"""The formation: robots, graph, desired distances and orientation, and what they allow.

* :mod:`.spec`: :class:`~.spec.Formation`, the specification every law, run and study
  takes (robots, edges, distances, diameters, the restricted triples and their alpha);
* :mod:`.graph`, :mod:`.graphs`, :mod:`.templates`: graphs (Delaunay, k nearest,
  within a radius, Henneberg) and lattice templates;
* :mod:`.orientation`: the desired orientation of triangles (alpha tables);
* :mod:`.rigidity` (with :mod:`.pebble`) and :mod:`.realisability`: generic rigidity at
  any size, and whether any shape meets the distances;
* :mod:`.geometry`: plane geometry shared by the laws and the models.
"""
