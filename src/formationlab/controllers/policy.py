"""A learned decentralized law: every robot runs one small network on its own measurements.

The law (``law = "policy"``, docs/learning.md) is a sum over the ordered pairs ``(j, k)``
of robot ``i``'s neighbours (the triples of eq. 13, a deep-sets form over them), each
term a small network (:mod:`.network`) of quantities robot ``i`` measures in its own frame:

    u_i = sum_{j != k in N_i} w_i [a_ijk g_ij + s_ijk b_ijk (k x g_ij)],
    (a, b)_ijk = N(x_ijk) - N(x0_ijk),

with ``g_ij = r_ij / |r_ij|`` the measured unit vector to neighbour ``j``, ``w_i = 1 /
(deg_i - 1)`` (1 for a robot with one neighbour, whose only pair is ``(j, j)``),
``s_ijk`` the desired sign of ``c_ijk`` (:attr:`Formation.restricted_sign`, 0 for a triple
whose orientation is free), and the features

    x_ijk = (log(r_ij / d_ij), log(r_ik / d_ik), max(0, -s sin_jk), cos_jk, s sin_jk, |s|),

``sin_jk = c_ijk / (r_ij r_ik)`` and ``cos_jk`` of the angle from ``r_ij`` to ``r_ik``.
``x0_ijk`` is ``x_ijk`` with its first three features set to zero: every term vanishes
where the distances are met and the triangle turns the desired way, so the desired
formation is an equilibrium whatever the weights (and a trained law comes to rest there),
while the mirror image (``max(0, -s sin) > 0``) need not be one.

What the form guarantees: the command of each robot depends only on what it measures
(relative positions in its own frame and its desired distances and signs), it turns with
the robot's frame (rotating a robot's measurements rotates its command: the law is
rotation-equivariant, like the paper's), a mirror image with the desired signs reversed
gets the mirror command, and relabelling neighbours changes nothing (a sum over them), so
one network runs on any graph. The law has no Lyapunov function; :meth:`PolicyLaw.potential`
is the half sum of squared distance errors, a measure of progress only.

The network's parameters come from a ``.npz`` file (``parameters`` in ``[controller]``; a
relative path is relative to the scenario file), written by ``formationlab train``
(:mod:`formationlab.learning`).
"""

from __future__ import annotations

import hashlib
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..errors import ParameterError
from ..formation.geometry import cross, perp, row_norms, scatter_rows
from ..formation.orientation import neighbour_triples
from ..formation.spec import Formation
from ..outcomes.analysis import distance_errors
from .base import Law, register
from .network import Network, forward, network_arrays, network_from_arrays

__all__ = [
    "FEATURES",
    "OUTPUTS",
    "Neighbourhoods",
    "PolicyLaw",
    "neighbourhoods",
    "policy_control",
    "triple_commands",
    "triple_features",
]

#: inputs of the network per triple (the features ``x_ijk``) and its outputs ``(a, b)``
FEATURES = 6
OUTPUTS = 2


class Neighbourhoods(NamedTuple):
    """The triples every robot sums over, as lists (``t`` triples).

    Attributes
    ----------
    i, j, k : ndarray of int, shape (t,)
        The robot and its ordered pair of neighbours (``j == k`` for a robot with one).
    sign : ndarray, shape (t,)
        Desired sign of ``c_ijk`` (0 where the orientation is free).
    d_ij, d_ik : ndarray, shape (t,)
        Desired distances.
    weight : ndarray, shape (t,)
        ``1 / max(deg_i - 1, 1)``.
    """

    i: NDArray[np.int64]
    j: NDArray[np.int64]
    k: NDArray[np.int64]
    sign: NDArray[np.float64]
    d_ij: NDArray[np.float64]
    d_ik: NDArray[np.float64]
    weight: NDArray[np.float64]


def neighbourhoods(formation: Formation) -> Neighbourhoods:
    """The triples of ``formation`` that its robots sum over (:class:`Neighbourhoods`)."""
    n, edges = formation.n, formation.edges
    deg = np.bincount(edges.ravel(), minlength=n)
    t = neighbour_triples(edges, n)
    half = np.concatenate([edges, edges[:, ::-1]])
    single = half[deg[half[:, 0]] == 1]  # a robot with one neighbour: its pair (j, j)
    t = np.concatenate([t, np.stack([single[:, 0], single[:, 1], single[:, 1]], axis=1)])
    desired = {tuple(map(int, r)): float(s)
               for r, s in zip(formation.restricted_triples, formation.restricted_sign,
                               strict=True)}  # fmt: skip
    sign = np.array([desired.get(tuple(map(int, r)), 0.0) for r in t])
    d = {**{(int(a), int(b)): float(x) for (a, b), x in zip(edges, formation.distances,
                                                              strict=True)},
         **{(int(b), int(a)): float(x) for (a, b), x in zip(edges, formation.distances,
                                                              strict=True)}}  # fmt: skip
    d_ij = np.array([d[int(a), int(b)] for a, b in t[:, :2]])
    d_ik = np.array([d[int(a), int(c)] for a, c in t[:, [0, 2]]])
    weight = 1.0 / np.maximum(deg[t[:, 0]] - 1, 1)
    return Neighbourhoods(t[:, 0], t[:, 1], t[:, 2], sign, d_ij, d_ik, weight)


def triple_features(
    r_ij: NDArray[np.float64],
    r_ik: NDArray[np.float64],
    sign: NDArray[np.float64],
    d_ij: NDArray[np.float64],
    d_ik: NDArray[np.float64],
) -> NDArray[np.float64]:
    """The network's inputs ``x_ijk`` from robot ``i``'s measurements (module docstring).

    Parameters
    ----------
    r_ij, r_ik : ndarray, shape (..., t, 2)
        Measured relative positions of the two neighbours, in robot ``i``'s frame.
    sign, d_ij, d_ik : ndarray, shape (t,)
        Desired sign of ``c_ijk`` and desired distances.

    Returns
    -------
    ndarray, shape (..., t, FEATURES)
    """
    l_ij, l_ik = row_norms(r_ij), row_norms(r_ik)
    norm = l_ij * l_ik
    sin = cross(r_ij, r_ik) / norm  # c_ijk / (r_ij r_ik), eq. (14)'s triple product
    cos = (r_ij[..., 0] * r_ik[..., 0] + r_ij[..., 1] * r_ik[..., 1]) / norm
    agree = sign * sin
    ones = np.broadcast_to(np.abs(sign), agree.shape)
    return np.stack(
        [np.log(l_ij / d_ij), np.log(l_ik / d_ik), np.maximum(-agree, 0.0), cos, agree, ones],
        axis=-1,
    )


def triple_commands(
    network: Network,
    r_ij: NDArray[np.float64],
    r_ik: NDArray[np.float64],
    sign: NDArray[np.float64],
    d_ij: NDArray[np.float64],
    d_ik: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Each triple's term ``a g_ij + s b (k x g_ij)`` in robot ``i``'s frame; ``(..., t, 2)``.

    The one formula of the learned law: its arguments are what robot ``i`` measures
    (:func:`triple_features`), so the term turns with the robot's frame.
    """
    x = triple_features(r_ij, r_ik, sign, d_ij, d_ik)
    x0 = x.copy()
    x0[..., :3] = 0.0  # the same angles with the distances met and no wrong turn
    ab = forward(network, x) - forward(network, x0)
    g = r_ij / row_norms(r_ij)[..., None]
    return ab[..., 0:1] * g + (sign * ab[..., 1])[..., None] * perp(g)


def policy_control(
    network: Network, hoods: Neighbourhoods, q: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Every robot's command from its own measurements; ``(..., n, 2) -> (..., n, 2)``.

    Robots measure in frames parallel to the world's here; a robot's turned frame turns
    its measurements and its command alike (:func:`triple_commands`).
    """
    q = np.asarray(q, dtype=float)
    r_ij = q[..., hoods.j, :] - q[..., hoods.i, :]
    r_ik = q[..., hoods.k, :] - q[..., hoods.i, :]
    terms = triple_commands(network, r_ij, r_ik, hoods.sign, hoods.d_ij, hoods.d_ik)
    return scatter_rows(terms * hoods.weight[:, None], hoods.i, q.shape[-2])


def read_network(path: str | Path) -> Network:
    """The network in the parameters file ``path`` (``.npz``, :func:`.network_arrays`).

    The law reads its own file, as the scenario names it: the file is part of the law's
    configuration, like its gains.

    Raises
    ------
    ParameterError
        A missing, unreadable or malformed file, with key ``parameters``.
    """
    p = Path(path)
    if not p.is_file():
        what = "is a folder" if p.is_dir() else "does not exist"
        raise ParameterError(
            f"the parameters file {p} {what}; give the .npz that `formationlab train` wrote",
            key="parameters",
        )
    try:
        with np.load(p, allow_pickle=False) as data:
            arrays = {name: data[name] for name in data.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as exc:
        raise ParameterError(
            f"the parameters file {p} is not a .npz of arrays ({exc}); give the file that "
            "`formationlab train` wrote",
            key="parameters",
        ) from None
    try:
        network = network_from_arrays(arrays)
    except ParameterError as exc:
        raise ParameterError(f"the parameters file {p}: {exc}", key="parameters") from None
    sizes = network.sizes
    if sizes[0] != FEATURES or sizes[-1] != OUTPUTS:
        raise ParameterError(
            f"the parameters file {p} holds a network of {sizes[0]} inputs and {sizes[-1]} "
            f"outputs; the policy law's takes {FEATURES} and gives {OUTPUTS}",
            key="parameters",
        )
    return network


def network_digest(network: Network) -> str:
    """A short SHA-256 of the network's arrays (which weights a result was made with)."""
    h = hashlib.sha256()
    for name, a in network_arrays(network).items():
        h.update(name.encode() + np.ascontiguousarray(a, dtype="<f8").tobytes())
    return h.hexdigest()[:16]


@register
@dataclass(frozen=True, kw_only=True)
class PolicyLaw(Law):
    """The learned decentralized law (module docstring), its network read from a file.

    Parameters
    ----------
    parameters : str
        The ``.npz`` file of the network (``formationlab train``); in a scenario a relative
        path is relative to the scenario file.

    Attributes
    ----------
    digest : str
        A short hash of the network's weights (in results, which weights made them).
    network : Network or None
        The network read from ``parameters`` (or given to :meth:`from_network`); ``None``
        without a file, and then :meth:`control` refuses to run.
    """

    name = "policy"
    dims = (2,)
    from_gains = False
    elsewhere = "the learned law is trained and run in the plane"

    parameters: str = field(default="", metadata={"path": True})
    digest: str = field(default="", init=False)

    def __post_init__(self) -> None:
        # without a file the law is built (registries list every law's defaults) but
        # refuses to run (:meth:`control`)
        self._set_network(read_network(self.parameters) if self.parameters else None)

    def _set_network(self, network: Network | None) -> None:
        # not a dataclass field: results and identities hold the file and the digest
        object.__setattr__(self, "network", network)
        object.__setattr__(self, "_hoods", {})
        object.__setattr__(self, "digest", "" if network is None else network_digest(network))

    @classmethod
    def from_network(cls, network: Network, *, parameters: str = "<memory>") -> PolicyLaw:
        """The law of a network held in memory (training's evaluation, tests)."""
        sizes = network.sizes
        if sizes[0] != FEATURES or sizes[-1] != OUTPUTS:
            raise ParameterError(
                f"the policy law's network takes {FEATURES} inputs and gives {OUTPUTS} "
                f"outputs, got {sizes[0]} and {sizes[-1]}"
            )
        law = object.__new__(cls)
        object.__setattr__(law, "parameters", parameters)
        law._set_network(network)
        return law

    def hoods(self, formation: Formation) -> Neighbourhoods:
        """The formation's :class:`Neighbourhoods`, built once per formation."""
        cache: dict[int, tuple[Formation, Neighbourhoods]] = self._hoods  # type: ignore[attr-defined]
        held = cache.get(id(formation))
        if held is None or held[0] is not formation:
            held = (formation, neighbourhoods(formation))
            cache[id(formation)] = held
        return held[1]

    def control(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """Every robot's command from its own measurements (:func:`policy_control`)."""
        network: Network | None = self.network  # type: ignore[attr-defined]
        if network is None:
            raise ParameterError(
                'the policy law needs its parameters file: parameters = "policy.npz" in '
                "[controller] (written by `formationlab train`)",
                key="parameters",
            )
        return policy_control(network, self.hoods(formation), q)

    def potential(self, formation: Formation, q: NDArray[np.float64]) -> NDArray[np.float64]:
        """``1/2 sum_edges (r_ij - d_ij)^2``: a measure of progress, not a Lyapunov function
        (the learned law descends none)."""
        e = distance_errors(formation, q)
        return 0.5 * np.sum(e * e, axis=-1)
