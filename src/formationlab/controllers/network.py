"""A small multilayer perceptron in numpy: the network of the learned law.

One forward pass (:func:`forward`), used by the law (:mod:`.policy`) and by its training
(:mod:`formationlab.learning`): hidden layers ``h = tanh(h W + b)``, a linear output layer.
The parameters are a :class:`Network` (weights and biases, shapes checked when built); a
flat vector of them (:meth:`Network.flat`, :meth:`Network.from_flat`) is what evolution
strategies search over, and a mapping of named arrays (:func:`network_arrays`,
:func:`network_from_arrays`) is what a parameters file holds.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import ParameterError

__all__ = ["Network", "forward", "network_arrays", "network_from_arrays", "parameter_count"]


def parameter_count(sizes: Sequence[int]) -> int:
    """Number of weights and biases of a network with layer widths ``sizes``
    (inputs first, outputs last)."""
    return sum((a + 1) * b for a, b in itertools.pairwise(sizes))


@dataclass(frozen=True, kw_only=True)
class Network:
    """Weights and biases of a multilayer perceptron.

    Parameters
    ----------
    weights : tuple of ndarray
        ``W_l`` of shape ``(sizes[l], sizes[l + 1])``, finite; or ``(P, sizes[l],
        sizes[l + 1])``: a stack of ``P`` networks of the same widths (a generation of
        candidates, run in one batch by :func:`forward`).
    biases : tuple of ndarray
        ``b_l`` of shape ``(sizes[l + 1],)`` (``(P, sizes[l + 1])`` for a stack), finite.
    """

    weights: tuple[NDArray[np.float64], ...]
    biases: tuple[NDArray[np.float64], ...]

    def __post_init__(self) -> None:
        w = tuple(np.array(x, dtype=float) for x in self.weights)
        b = tuple(np.array(x, dtype=float) for x in self.biases)
        if not w or len(w) != len(b):
            raise ParameterError(
                f"a network needs as many weight matrices as bias vectors (at least one), "
                f"got {len(w)} and {len(b)}"
            )
        stack = w[0].shape[:-2] if w else ()
        for layer, (wl, bl) in enumerate(zip(w, b, strict=True), start=1):
            if (
                wl.ndim not in (2, 3)
                or wl.shape[:-2] != stack
                or bl.shape != (*stack, wl.shape[-1])
            ):
                raise ParameterError(
                    f"layer {layer}: weights must be (inputs, outputs) and biases (outputs,), "
                    f"got {wl.shape} and {bl.shape}"
                )
            if layer > 1 and wl.shape[-2] != w[layer - 2].shape[-1]:
                raise ParameterError(
                    f"layer {layer} takes {wl.shape[-2]} inputs but layer {layer - 1} gives "
                    f"{w[layer - 2].shape[-1]}"
                )
            if not (np.isfinite(wl).all() and np.isfinite(bl).all()):
                raise ParameterError(f"layer {layer}: weights and biases must be finite")
            wl.setflags(write=False)
            bl.setflags(write=False)
        object.__setattr__(self, "weights", w)
        object.__setattr__(self, "biases", b)

    @property
    def sizes(self) -> tuple[int, ...]:
        """Layer widths, inputs first and outputs last."""
        return (self.weights[0].shape[-2], *(wl.shape[-1] for wl in self.weights))

    def flat(self) -> NDArray[np.float64]:
        """Every parameter in one vector, layer by layer (weights row-major, then biases);
        length :func:`parameter_count` of :attr:`sizes`."""
        return np.concatenate([p.ravel() for wl, bl in zip(self.weights, self.biases, strict=True)
                               for p in (wl, bl)])  # fmt: skip

    @classmethod
    def from_flat(cls, sizes: Sequence[int], flat: ArrayLike) -> Network:
        """The network of layer widths ``sizes`` whose :meth:`flat` vector is ``flat``; a
        ``(P, count)`` array of ``P`` vectors gives a stack of ``P`` networks."""
        v = np.asarray(flat, dtype=float)
        stack = v.shape[:-1] if v.ndim == 2 else ()
        v = v.reshape(*stack, -1)
        if v.shape[-1] != parameter_count(sizes):
            raise ParameterError(
                f"a network of layer widths {list(sizes)} has {parameter_count(sizes)} "
                f"parameters, got {v.shape[-1]}"
            )
        weights, biases, at = [], [], 0
        for a, b in itertools.pairwise(sizes):
            weights.append(v[..., at : at + a * b].reshape(*stack, a, b))
            biases.append(v[..., at + a * b : at + (a + 1) * b])
            at += (a + 1) * b
        return cls(weights=tuple(weights), biases=tuple(biases))


def forward(network: Network, x: NDArray[np.float64]) -> NDArray[np.float64]:
    """The network's output at inputs ``x``; ``(..., sizes[0]) -> (..., sizes[-1])``.

    Hidden layers ``tanh(h W_l + b_l)``, the last layer linear (``h W + b``). A stack of
    ``P`` networks takes ``x`` of shape ``(P, ..., sizes[0])``, network ``p`` on ``x[p]``.
    """
    stacked = network.weights[0].ndim == 3
    shape = np.shape(x)
    h = np.reshape(x, (shape[0], -1, shape[-1])) if stacked else x
    last = len(network.weights) - 1
    for layer, (w, b) in enumerate(zip(network.weights, network.biases, strict=True)):
        h = h @ w + (b[:, None, :] if stacked else b)
        if layer < last:
            h = np.tanh(h)
    return np.reshape(h, (*shape[:-1], h.shape[-1])) if stacked else h


def network_arrays(network: Network) -> dict[str, NDArray[np.float64]]:
    """The named arrays of a parameters file: ``W1, b1, W2, b2, ...`` (1-based layers)."""
    out: dict[str, NDArray[np.float64]] = {}
    for layer, (w, b) in enumerate(zip(network.weights, network.biases, strict=True), start=1):
        out[f"W{layer}"] = np.asarray(w)
        out[f"b{layer}"] = np.asarray(b)
    return out


def network_from_arrays(arrays: Mapping[str, Any]) -> Network:
    """The network of the arrays ``W1, b1, W2, b2, ...`` of a parameters file
    (:func:`network_arrays`); other names are ignored.

    Raises
    ------
    ParameterError
        No ``W1``, a layer without its bias, or shapes that do not chain.
    """
    weights, biases, layer = [], [], 1
    while f"W{layer}" in arrays:
        if f"b{layer}" not in arrays:
            raise ParameterError(f"the array W{layer} has no bias b{layer}")
        weights.append(np.asarray(arrays[f"W{layer}"]))
        biases.append(np.asarray(arrays[f"b{layer}"]))
        layer += 1
    if not weights:
        raise ParameterError(
            f"no network in it: expected arrays W1, b1, W2, b2, ..., found {sorted(arrays)}"
        )
    if any(np.asarray(a).dtype.kind not in "fi" for a in (*weights, *biases)):
        raise ParameterError("the network's arrays must hold numbers")
    return Network(weights=tuple(weights), biases=tuple(biases))
