"""The ``safety`` extra (qpsolvers, Clarabel, shapely), checked before the package uses it.

Without it, importing :mod:`formationlab.safety` raises
:class:`~formationlab.errors.MissingExtraError` naming ``pip install "formationlab[safety]"``
instead of a ``ModuleNotFoundError`` from deep inside.
"""

from ..errors import require_extra

require_extra("safety", ("qpsolvers", "clarabel", "shapely"), "safety filters and obstacles")
