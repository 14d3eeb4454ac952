"""The scenario fuzzer's parts: scenario files drawn by hypothesis, and a worker to run them.

A drawn scenario is a valid base (a triangle with some of the optional tables: obstacles,
a safety filter, sensing, faults, asynchronous robots, marching, a study, equilibria,
another robot model, a template or an alpha table), then at most one change: one key of
it set to a value drawn from extreme numbers, wrong types, deep nesting, huge counts,
unicode and NUL, or a key that no table has. The file is written with one key per line
(nested tables inline), so the line of every key is known: a refusal must name the key
that was changed and that line (or a key it is tied to, :data:`TIED`).

The commands run in :class:`Worker`, a process of its own under a memory limit
(``resource.setrlimit`` before it starts) and a timeout, which imports the command line
once and runs each command in-process (``tests/_fuzz_worker.py``): an abort, an
out-of-memory death or a hang ends the worker and is reported as the finding.
"""

from __future__ import annotations

import copy
import json
import math
import os
import re
import resource
import select
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from hypothesis import strategies as st

from formationlab.cli._app import printable

#: exit statuses a command may end with: done, stopped early, refused, interrupted
ALLOWED_EXITS = {0, 1, 2, 130}
#: the worker's address space (bytes): the command line takes about 2 GB of it once loaded
MEMORY_LIMIT = 4 << 30
#: longest a command may take on a drawn scenario (seconds; a few steps, a few trials)
COMMAND_SECONDS = 60.0

# ------------------------------------------------------------------------------ writing


def toml_value(v: Any) -> str:
    """``v`` as an inline TOML value (tables inline, so a key and its value are one line)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):  # JSON's escapes are TOML's, but for DEL
        return json.dumps(v, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(v, list):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        inner = ", ".join(f"{json.dumps(str(k))} = {toml_value(x)}" for k, x in v.items())
        return "{ " + inner + " }" if inner else "{}"
    raise TypeError(f"no TOML for {v!r}")


def toml_text(scenario: dict[str, Any]) -> tuple[str, dict[str, int]]:
    """The scenario's TOML text and the line of each ``table.key`` (and top-level key).

    Top-level values first, then each table (``[[obstacles]]`` for a list of tables), one key
    per line."""
    lines: list[str] = ["# drawn by the scenario fuzzer (tests/test_fuzz_scenarios.py)"]
    where: dict[str, int] = {}
    tables = {k: v for k, v in scenario.items() if isinstance(v, dict | list) and _table(k, v)}
    for k, v in scenario.items():
        if k not in tables:
            lines.append(f"{_key(k)} = {toml_value(v)}")
            where[k] = len(lines)
    for name, table in tables.items():
        rows = table if isinstance(table, list) else [table]
        for row in rows:
            lines.append(f"[[{name}]]" if isinstance(table, list) else f"[{name}]")
            where.setdefault(name, len(lines))
            for k, v in row.items():
                lines.append(f"{_key(k)} = {toml_value(v)}")
                where.setdefault(f"{name}.{k}", len(lines))
    return "\n".join(lines) + "\n", where


def _table(name: str, v: Any) -> bool:
    if isinstance(v, dict):
        return name in TABLES
    return name == "obstacles" and bool(v) and all(isinstance(x, dict) for x in v)


def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


# -------------------------------------------------------------------------- scenarios

TABLES = (
    "robots", "formation", "controller", "simulation", "marching", "safety", "sensing",
    "faults", "asynchronous", "study", "equilibria",
)  # fmt: skip

BASE: dict[str, Any] = {
    "name": "fuzz",
    "description": "a scenario drawn by the fuzzer",
    "robots": {"positions": [[-1.0, -1.0], [1.0, -1.0], [0.0, 1.0]], "diameters": 0.2},
    "formation": {"edges": "complete", "distances": 1.0},
    "controller": {
        "law": "angle-restricted", "k_c": 2.0, "k_a": 3.0, "theta": 0.5,
        "repulsion": {"eta": 1.0, "influence": 0.5},
    },
    "simulation": {"integrator": "euler", "dt": 0.01, "duration": 0.05},
}  # fmt: skip

#: optional parts of a valid scenario: (table or key, value); asynchronous robots take no
#: obstacles, filter or marching (their runner's rule), studies and equilibria no marching
OPTIONAL: dict[str, Any] = {
    "obstacles": [{"circle": {"center": [5.0, 5.0], "radius": 0.5}}],
    "safety": {
        "filter": "barrier-decentralized", "distance": 0.25, "gamma": 100.0, "max_speed": 2.0,
        "speed_sides": 8, "sensing_radius": 3.0, "obstacle_distance": 0.2,
    },
    "sensing": {
        "frames": "global", "frame_error": 0.01, "noise": 0.01, "range": 10.0, "delay": 0.02,
        "drop": 0.1, "mismatch": 0.01, "seed": 1,
    },
    "faults": {"stop": [{"robot": 2, "at": 0.02}]},
    "asynchronous": {"periods": [0.01, 0.02, 0.01], "jitter": 0.1},
    "marching": {"velocity": [0.1, 0.0], "leader": 1},
    "study": {
        "trials": 2, "initial": {"kind": "box", "half_width": 3.0},
        "laws": ["distance", "angle-restricted"], "sweep": {"k_c": [1.0, 2.0]},
        "tolerances": {"distance": 0.01, "speed": 0.001}, "chunk_size": 2, "dt": 0.01,
        "duration": 0.05, "backend": "numba",
        "settle": {"enabled": False, "duration": 1.0, "dt": 0.01},
    },
    "equilibria": {
        "starts": 2, "seed": 1, "duration": 0.1, "collinear": 0.5, "integrator": "rk4",
        "dt": 0.01, "follow_steps": 2, "law": "distance",
    },
}  # fmt: skip

#: other robots and formations, each valid with every optional table
VARIANTS: dict[str, dict[str, dict[str, Any]]] = {
    "unicycle": {"robots": {"model": "unicycle", "mapping": "near-identity", "offset": 0.05,
                            "headings": [0.0, 1.5, 3.0]}},
    "double-integrator": {"robots": {"model": "double-integrator", "damping": 2.0,
                                     "max_speed": 1.0}},
    "template": {"formation": {"edges": "complete", "distances": None,
                               "template": [[0.0, 0.0], [1.0, 0.0], [0.5, 0.8]],
                               "orientation": "template"}},
    "alpha": {"formation": {"orientation": "table",
                            "alpha": [[1, 2, 3, -1.0], [3, 1, 2, -1.0], [2, 1, 3, 1.0]]}},
    "lattice": {"formation": {"edges": "delaunay", "distances": None, "orientation": "free",
                              "template": {"lattice": "triangular", "count": 7,
                                           "spacing": 1.0}},
                "robots": {"positions": {"around": "template", "sigma": 0.01, "seed": 1}}},
}  # fmt: skip

#: keys whose refusal may be reported at another key they are tied to (a rule between two
#: keys is one decision, placed at one of them): changed key -> keys it may name
TIED: dict[str, tuple[str, ...]] = {
    "simulation.duration": ("simulation.dt", "sensing.delay", "asynchronous.periods"),
    "simulation.dt": ("sensing.delay", "asynchronous.periods"),
    "study.duration": ("study.dt",),  # the steps of a trial: duration / dt
    "equilibria.duration": ("equilibria.dt",),
    "simulation.integrator": ("sensing", "asynchronous", "faults"),
    "robots.positions": ("robots.headings", "formation", "obstacles", "faults.stop",
                         "marching.leader", "asynchronous.periods", "study", "robots.diameters"),
    "robots.diameters": ("formation.distances", "safety.distance", "safety.obstacle_distance",
                         "obstacles", "robots.positions", "formation.template"),
    "robots.model": ("safety", "robots"),
    "formation.template": ("robots.positions", "formation"),
    "formation.distances": ("formation",),
    "formation.edges": ("formation",),
    "controller.law": ("formation", "controller", "equilibria"),
    "safety.filter": ("safety",),
    "safety.distance": ("safety",),
}  # fmt: skip


def _number_values() -> st.SearchStrategy[Any]:
    extreme = [0, -1, 1, 3, 10**6, 10**9, 10**15, 2**63 - 1, -(2**63), 0.0, -0.0, -1.0,
               1e-300, 5e-324, 1e-9, 1e6, 1e9, 1e15, 1e150, 1e300, 1.7976931348623157e308,
               -1e300, math.inf, -math.inf, math.nan]  # fmt: skip
    return st.one_of(
        st.sampled_from(extreme),
        st.floats(allow_nan=True, allow_infinity=True),
        st.integers(min_value=-(2**63), max_value=2**63 - 1),
    )


def _odd_values() -> st.SearchStrategy[Any]:
    """Wrong types, unicode and NUL, deep nesting, huge lists."""
    words = st.text(
        alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=12
    )  # fmt: skip
    nested = st.integers(min_value=2, max_value=60).map(lambda d: _deep(d))
    return st.one_of(
        st.sampled_from(["", "x", "ü名\u202e", "a\x00b", "\x00", "🤖", "euler", "template",
                         True, False, [], {}, [1], [[1, 2]], [[1.0, 2.0, 3.0, 4.0]],
                         {"a": 1}, {"kind": "gaussian"}, [None.__class__.__name__]]),
        words,
        nested,
        st.sampled_from([300, 5000, 20000]).map(_row),  # a huge list (a complete graph of 5000
        # robots is refused by its estimate; between, thousands of robots take seconds each)
        st.lists(st.floats(allow_nan=False, width=32), max_size=5),
    )  # fmt: skip


def _row(n: int) -> list[list[float]]:
    return [[0.5 * i, 0.0] for i in range(n)]


def _deep(depth: int) -> Any:
    v: Any = 1.0
    for _ in range(depth):
        v = [v]
    return v


@dataclass(frozen=True)
class Drawn:
    """A drawn scenario: its text, the dotted key changed (None: a valid scenario, or a key
    added), its line, and what was done (for the report)."""

    text: str
    key: str | None
    line: int | None
    change: str


@st.composite
def scenarios(draw: Any, *, change: bool | None = None) -> Drawn:
    """A scenario file: a valid base with some optional tables and at most one change."""
    sc = copy.deepcopy(BASE)
    variant = draw(st.sampled_from([None, *VARIANTS]))
    for table, keys in (VARIANTS[variant] if variant else {}).items():
        for k, v in keys.items():
            if v is None:
                sc[table].pop(k, None)
            else:
                sc[table][k] = copy.deepcopy(v)
    parts = draw(st.sets(st.sampled_from(sorted(OPTIONAL)), max_size=4))
    if "asynchronous" in parts:
        parts -= {"obstacles", "safety", "marching"}
    if variant == "double-integrator":
        parts.discard("safety")  # the filter certifies velocities, not forces
    if parts & {"study", "equilibria"}:
        parts.discard("marching")  # they classify formations that come to rest
    if "asynchronous" in parts and variant == "lattice":
        parts.discard("asynchronous")  # one period per robot: three of them
    for part in sorted(parts):
        sc[part] = copy.deepcopy(OPTIONAL[part])
    if change is None:
        change = draw(st.booleans()) or draw(st.booleans())
    if not change:
        text, _ = toml_text(sc)
        return Drawn(text, None, None, f"valid ({variant or 'base'}, {sorted(parts)})")
    how = draw(st.sampled_from(["value", "value", "value", "unknown-key"]))
    keys = [(t, k) for t, v in sc.items() if isinstance(v, dict) for k in v]
    keys += [(None, k) for k, v in sc.items() if not isinstance(v, dict | list)]
    keys += [("obstacles", None)] if "obstacles" in sc else []
    table, key = draw(st.sampled_from(keys))
    if how == "unknown-key":
        name = draw(st.sampled_from(["k_cc", "dtt", "durration", "ü", "a b", "\x00", "seed2"]))
        target = sc if table is None else sc[table]
        if table == "obstacles" or name in target:
            return Drawn(toml_text(sc)[0], None, None, "unchanged")
        target[name] = 1.0
        dotted = name if table is None else f"{table}.{name}"
    else:
        value = draw(st.one_of(_number_values(), _odd_values()))
        if table == "obstacles":
            sc["obstacles"] = [{"circle": {"center": [5.0, 5.0], "radius": value}}]
            dotted = "obstacles"
        elif table is None:
            sc[key] = value
            dotted = key
        else:
            sub = draw(st.sampled_from([None, *sorted(sc[table][key])]))\
                if isinstance(sc[table][key], dict) and sc[table][key] else None  # fmt: skip
            if sub is None:
                sc[table][key] = value
                dotted = f"{table}.{key}"
            else:
                sc[table][key][sub] = value
                dotted = f"{table}.{key}.{sub}"
        how = f"{dotted} = {toml_value(value)[:80]}"
    text, lines = toml_text(sc)
    top = ".".join(dotted.split(".")[:2]) if not dotted.startswith("obstacles") else "obstacles"
    return Drawn(text, dotted, lines.get(top), f"{how} ({variant or 'base'}, {sorted(parts)})")


# ----------------------------------------------------------------------------- checks


def named_keys(output: str) -> list[tuple[str, int | None]]:
    """The ``(key, line)`` pairs an ``error:`` message places itself at (``KEY (line N)``,
    ``KEY, item 2 (line N)`` after the file's name or a ``;``)."""
    found = []
    pattern = (r"(?:\.toml: (?:\d+ problems: )?|; )([^:;(]+?)(?:, (?:item|row|robot)[^(:;]*)?"
               r"(?: \(line (\d+)\))?(?=:)")  # fmt: skip
    for m in re.finditer(pattern, output):
        found.append((m.group(1), int(m.group(2)) if m.group(2) else None))
    return found


def refusal_problem(drawn: Drawn, output: str) -> str | None:
    """Why the refusal ``output`` of ``drawn`` does not name its changed key and line."""
    if drawn.key is None:
        return None
    changed = printable(drawn.key)  # as messages write it (a NUL as \\x00)
    top = ".".join(changed.split(".")[:2])
    allowed = (top, *TIED.get(top, ()))
    named = named_keys(output)
    for key, line in named:
        ours = key == top or key.startswith(top + ".") or key.startswith(changed)
        if ours and line == drawn.line:
            return None
        if not ours and any(key == a or key.startswith(a + ".") for a in allowed[1:]):
            return None
        if top in ("name", "description") and key == top:
            return None
    return (
        f"the refusal does not name {top} (line {drawn.line}); it names "
        f"{named or 'no key'}:\n{output}"
    )


# ----------------------------------------------------------------------------- worker

_WORKER = Path(__file__).with_name("_fuzz_worker.py")


def _limit_memory() -> None:  # runs in the child, before it starts
    resource.setrlimit(resource.RLIMIT_AS, (MEMORY_LIMIT, MEMORY_LIMIT))


class Worker:
    """A process that runs formationlab's commands in-process (``tests/_fuzz_worker.py``)
    under :data:`MEMORY_LIMIT`; started again after it dies or hangs."""

    def __init__(self) -> None:
        self.proc: subprocess.Popen[str] | None = None

    def _start(self) -> None:
        read, write = os.pipe()
        src = str(Path(__file__).resolve().parents[1] / "src")
        env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join([src, *filter(None, [os.environ.get("PYTHONPATH")])]),
            "COLUMNS": "10000",
        }
        self.proc = subprocess.Popen(
            [sys.executable, str(_WORKER), str(write)], stdin=subprocess.PIPE,
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, pass_fds=(write,),
            preexec_fn=_limit_memory, env=env,
        )  # fmt: skip
        os.close(write)
        self.reply = os.fdopen(read, encoding="utf-8")
        self._answer(120.0, "starting")

    def _answer(self, timeout: float, what: str) -> dict[str, Any]:
        assert self.proc is not None
        ready, _, _ = select.select([self.reply], [], [], timeout)
        line = self.reply.readline() if ready else ""
        if line:
            return json.loads(line)  # type: ignore[no-any-return]
        if not ready:
            self.proc.kill()
        status = self.proc.wait()
        err = self.proc.stderr.read()[-3000:] if self.proc.stderr else ""
        self.close()
        died = f"died with status {status}" if ready else f"took more than {timeout:g} s"
        return {"exit": None, "output": "", "error": f"the worker {died} {what}\n{err}",
                "warnings": [], "seconds": timeout}  # fmt: skip

    def invoke(self, args: list[str], timeout: float = COMMAND_SECONDS) -> dict[str, Any]:
        """Run ``formationlab ARGS`` in the worker: its reply (``tests/_fuzz_worker.py``)."""
        if self.proc is None:
            self._start()
            if self.proc is None:
                raise RuntimeError("the fuzzer's worker does not start")
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps({"args": args}) + "\n")
        self.proc.stdin.flush()
        return self._answer(timeout, f"running {' '.join(args)}")

    def close(self) -> None:
        if self.proc is not None:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
            for f in (self.proc.stdin, self.proc.stderr):
                if f is not None:
                    f.close()
            self.reply.close()
            self.proc = None


def outcome_problem(answer: dict[str, Any]) -> str | None:
    """What is wrong with a command's ending: a status outside :data:`ALLOWED_EXITS`, a
    traceback, a stray warning, or a worker that died or hung."""
    if answer["error"]:
        return f"exception:\n{answer['error']}"
    if answer["exit"] not in ALLOWED_EXITS:
        return f"exit status {answer['exit']}:\n{answer['output']}"
    if "Traceback" in answer["output"]:
        return f"a traceback in the output:\n{answer['output']}"
    if answer["warnings"]:
        return "stray warnings:\n" + "\n".join(answer["warnings"])
    return None
