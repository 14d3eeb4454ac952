"""The viewer as a Jupyter widget (anywidget): ``fl.Viewer(scenario)`` in a notebook cell.

The widget runs the same front end as the stand-alone page (the bundle of
:mod:`formationlab.viewer.assets`) and the same protocol: the front end sends
its messages as widget messages, the Python side answers through the shared
:class:`~formationlab.viewer.controller.Controller` (frames with their float32
buffers). The state a notebook user may read or set is mirrored in traitlets:
``t``, ``paused``, ``speed``, ``law``, ``law_params``, ``integrator``, ``dt``,
``status``; setting one from Python applies it to the run (and is validated
like a message from the page), and every message from the page updates them.
Without a browser: ``step(n)`` and ``run(seconds)`` step the run, ``t``, ``positions``
``(n, d)``, ``state`` ``(n, k)`` and ``history`` (times, positions, V and the per-edge
errors since the last reset) read it.
Works in JupyterLab, Jupyter Notebook 7 and VS Code notebooks (anywidget).
"""

from __future__ import annotations

import json
import os
from typing import Any

import anywidget
import numpy as np
import traitlets
from numpy.typing import NDArray

from ..errors import ParameterError
from ..scenario.parse import Scenario
from .assets import THREE_FILES, bundle, read_asset, three_module
from .controller import Controller, Reply
from .frames import History
from .session import LiveSession, SessionError
from .sources import open_session

__all__ = ["Viewer"]

_SETTABLE = ("paused", "speed", "law", "law_params", "integrator", "dt")


class Viewer(anywidget.AnyWidget):  # type: ignore[misc]
    """An interactive view of a scenario (or a replay of a run folder) in a notebook.

    Parameters
    ----------
    scenario : Scenario or path
        A scenario, a scenario file, or the output folder of ``formationlab run``.
    seed : int, optional
        Seed of the random perturbations (a whole number in ``[0, 2**63)``).
    **kwargs
        Settings applied to the session once it is open (``paused``, ``speed``, ``law``,
        ``law_params``, ``integrator``, ``dt``), or ipywidgets' own traits (``layout`` ...);
        any other name, or a trait read from the session (``t``, ``n`` ...), is an error.

    Examples
    --------
    >>> import formationlab as fl                                      # doctest: +SKIP
    >>> v = fl.Viewer("examples/paper-simulation-2.toml"); v           # doctest: +SKIP
    >>> v.law_params = {"k_a": 5.0}; v.positions                       # doctest: +SKIP
    >>> v.step(100); v.t, v.state.shape, v.history.positions.shape     # doctest: +SKIP
    >>> v.run(2.0); v.history.V[-1], v.history.errors.shape            # doctest: +SKIP
    """

    _esm = traitlets.Unicode(bundle()).tag(sync=True)
    _css = traitlets.Unicode(read_asset("viewer.css")).tag(sync=True)
    #: the three.js modules by file name, for a formation in space only (the front end
    #: loads them from blobs: a notebook has no server of the package's files)
    _three = traitlets.Dict().tag(sync=True)

    name = traitlets.Unicode("").tag(sync=True)
    mode = traitlets.Unicode("live").tag(sync=True)
    n = traitlets.Int(0).tag(sync=True)
    t = traitlets.Float(0.0).tag(sync=True)
    paused = traitlets.Bool(False).tag(sync=True)
    speed = traitlets.Float(1.0).tag(sync=True)
    law = traitlets.Unicode("").tag(sync=True)
    law_params = traitlets.Dict().tag(sync=True)
    integrator = traitlets.Unicode("").tag(sync=True)
    dt = traitlets.Float(0.0).tag(sync=True)
    status = traitlets.Unicode("").tag(sync=True)

    def __init__(
        self, scenario: Scenario | str | os.PathLike[str], *, seed: int | None = None, **kwargs: Any
    ) -> None:
        own = set(self.class_trait_names(sync=True)) - set(anywidget.AnyWidget.class_trait_names())
        unknown = sorted(set(kwargs) - set(self.class_trait_names()))
        unknown += sorted(k for k in kwargs if k in own and k not in _SETTABLE)  # read-only
        if unknown:
            raise ParameterError(
                f"Viewer() takes no argument {', '.join(map(repr, unknown))}: give the "
                f"scenario, seed=, the settings {', '.join(_SETTABLE)}, or ipywidgets' "
                "layout traits",
                key=unknown[0],
            )
        settings = {k: kwargs.pop(k) for k in _SETTABLE if k in kwargs}
        session = open_session(scenario, seed=seed)
        self._syncing = True
        super().__init__(**kwargs)
        self.controller = Controller(session)
        if session.info()["dim"] == 3:
            self._three = {name: three_module(name) for name in THREE_FILES}
        self.controller.listeners.append(self._sync)
        self.on_msg(self._on_front_end)
        self._sync()
        self.observe(self._on_python_change, names=list(_SETTABLE))
        for name, value in settings.items():  # through the session, as a change from Python
            setattr(self, name, value)

    @property
    def session(self) -> Any:
        """The :class:`LiveSession` or :class:`ReplaySession` behind the widget."""
        return self.controller.session

    @property
    def positions(self) -> NDArray[np.float64]:
        """Positions now, shape ``(n, d)`` (robot 1 is row 0; ``d = 3`` in space), in float64."""
        s = self.session
        if isinstance(s, LiveSession):
            return np.array(s.positions)
        return np.array(s.q[s.index])

    @property
    def state(self) -> NDArray[np.float64]:
        """The robot model's state now, shape ``(n, k)`` (``state_names``: positions first)."""
        s = self.session
        return np.array(s.state if isinstance(s, LiveSession) else s.x[s.index])

    @property
    def history(self) -> History:
        """What the run went through: times ``(T,)``, positions ``(T, n, d)``, ``V``
        ``(T,)`` and the per-edge errors ``(T, m)`` (:class:`History`), stepped since the
        last reset (live: :meth:`LiveSession.trajectory`) or saved (replay)."""
        s = self.session
        if isinstance(s, LiveSession):
            return s.trajectory()
        return History(t=np.array(s.t), positions=np.array(s.q), V=np.array(s.V),
                       errors=np.array(s.err))  # fmt: skip

    def step(self, count: int = 1) -> int:
        """Take ``count`` steps of the live run now (paused or not); returns how many.

        Fewer when the contact rule refuses a step or the state stops being finite
        (:attr:`status` then says which, and the run pauses).

        Raises
        ------
        SessionError
            For a replay (it plays a saved run; move its cursor with the slider).
        """
        if isinstance(count, bool) or not isinstance(count, int | np.integer) or count < 0:
            raise SessionError(f"step takes a whole number of steps >= 0, got {count!r}")
        done = self._live("step").step(int(count))
        self._sync()
        return done

    def run(self, seconds: float) -> int:
        """Run ``seconds`` of simulated time now (``round(seconds / dt)`` steps, at least
        one), as fast as the machine can; returns the steps taken (fewer as for :meth:`step`).

        Raises
        ------
        SessionError
            For a replay, or a duration that is not a positive number of seconds.
        """
        if isinstance(seconds, bool) or not isinstance(seconds, int | float | np.floating):
            raise SessionError(f"run takes a duration in seconds, got {seconds!r}")
        if not 0 < seconds < float("inf"):
            raise SessionError(f"run takes a positive, finite duration in seconds, got {seconds!r}")
        done = self._live("run").run_for(float(seconds))
        self._sync()
        return done

    def _live(self, what: str) -> LiveSession:
        s = self.session
        if not isinstance(s, LiveSession):
            raise SessionError(f"a replay cannot {what}; it plays the saved run (use the slider)")
        return s

    # ------------------------------------------------------------------ front end -> Python

    def _on_front_end(self, _widget: Any, content: Any, buffers: list[bytes]) -> None:
        """A message from the front end: answer it like the server does."""
        text = content if isinstance(content, str) else json.dumps(content)
        self._reply(self.controller.handle(text))

    def _reply(self, replies: list[Reply]) -> None:
        for reply in replies:
            self.send(reply.header, reply.buffers or None)

    # ------------------------------------------------------------------ Python -> run

    def _on_python_change(self, change: dict[str, Any]) -> None:
        if self._syncing:
            return
        name, value = change["name"], change["new"]
        if name == "paused":
            msg: dict[str, Any] = {"type": "pause", "paused": bool(value)}
        elif name == "speed":
            msg = {"type": "speed", "value": float(value)}
        elif name == "law":
            msg = {"type": "set_law", "name": value}
        elif name == "law_params":
            msg = {"type": "set_params", "params": {k: float(v) for k, v in value.items()}}
        else:  # integrator, dt
            msg = {"type": "set_integrator", "name": self.integrator, "dt": float(self.dt)}
        replies = self.controller.handle(json.dumps(msg))
        errors = [r.header["message"] for r in replies if r.header.get("type") == "error"]
        if errors:
            self._sync()  # back to the values in force
            raise SessionError(errors[0])
        self._reply(replies)

    def _sync(self) -> None:
        """Copy the run's state into the traitlets (without acting on the change)."""
        s = self.session
        self._syncing = True
        try:
            with self.hold_trait_notifications():
                self.mode = s.mode
                self.n = int(s.frame().positions.shape[0])
                self.paused = bool(s.paused)
                self.speed = float(s.speed)
                if isinstance(s, LiveSession):
                    self.name = s.scenario.name
                    self.t = float(s.t)
                    self.law = s.law.name
                    self.law_params = dict(s.info()["law"]["params"])
                    self.integrator = s.integrator.name
                    self.dt = float(s.integrator.dt)
                    self.status = s.status
                else:
                    self.name = s.name
                    self.t = float(s.t[s.index])
                    self.status = "replay"
        finally:
            self._syncing = False
