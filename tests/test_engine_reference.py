"""Every example and seeded study ends where it ended before the engine became one loop.

The references were recorded by ``tests/engine_reference.py`` (its docstring says how and
at which commit), on one machine. A recorded last bit is not a property of the code: numpy,
OpenBLAS and Clarabel choose their SIMD kernels by processor (numpy's ``sin`` and ``cos``
and the barrier QP end one unit in the last place apart on an AVX2 processor and an
AVX-512 one). So every comparison with the recording has a tolerance that another processor
meets and a real change does not; bit-for-bit comparisons are kept for two paths computed
in the same run (tests/test_compiled.py, tests/test_engine_sensing.py and the like).

* under a smooth law the trajectory depends continuously on the arithmetic, and a rounding
  difference stays a rounding difference: positions within ``1e-12`` of their scale
  (measured with numpy's AVX-512 kernels switched off: at most 3e-16 of it);
* under a switching law (``Law.smooth`` false: the angle-restricted law) a trajectory that
  reaches a switching surface chatters across it under explicit Euler with an amplitude of
  order ``k_a dt`` (docs/integrators.md), and a change in the last bit re-draws the chatter:
  there the run must end the same way (status, time, outcome, steps) and its positions
  within ``1e-7`` of their scale (measured with numpy's AVX-512 kernels switched off: at most
  6.5e-10 of it, on the ten-robot example). Study trials under a switching law that chatter
  on a Filippov equilibrium for the whole run (``not-converged``) end up to 3e-2 apart
  between the paths, so there only the outcome is compared;
* under the learned law (``law = "policy"``, docs/learning.md) the field is a network of
  tanh units, steep where training made it so (peak speeds near 15 m/s at ``dt = 1e-3``):
  numpy's ``tanh`` also ends a unit in the last place apart between SIMD kernels, and the
  steep field carries that difference to the end of the run: positions within ``1e-9`` of
  their scale (measured with numpy's SIMD dispatch off: 3.8e-12 of it on the triangle's
  policy); another set of weights or another formula moves them by far more;
* under the centralized safety filter (``filter = "barrier"``) the numpy driver solves each
  step's QP with Clarabel, to its tolerances (about 1e-8), and the compiled loop by its
  exact active-set method (Clarabel only when rounding defeats it): a run of one path
  against a recording of the other ends within ``1e-9`` of the scale (measured: 1.5e-11 on
  the head-on deadlock, whose filter binds at every step; recorded when its default path
  was the numpy driver).

``.ci/run`` runs this file a second time with numpy's dispatch narrowed to AVX2
(``NPY_DISABLE_CPU_FEATURES``) and OpenBLAS's Haswell kernels (``OPENBLAS_CORETYPE``).
"""

from __future__ import annotations

import json

import engine_reference as ref
import numpy as np
import pytest

from formationlab.controllers import LAWS

#: compared again on another processor's numpy and OpenBLAS kernels (.ci/run)
pytestmark = pytest.mark.narrowed

RECORDED = json.loads(ref.DATA.read_text())
#: the recorded runs; a default-backend run recorded with the same numbers as its numpy run
#: took the same path (an integrator or a formation the compiled loop does not step: implicit
#: Euler, Filippov, a formation in space), so it is compared once, as the numpy run
RUNS = sorted(
    name
    for name, run in RECORDED["runs"].items()
    if not (name.endswith("|auto") and run == RECORDED["runs"].get(name[:-5] + "|numpy"))
)

#: positions' tolerance, relative to their scale, under a smooth and a switching law, and
#: under the centralized filter's QP (module docstring)
SMOOTH, SWITCHING, QP = 1e-12, 1e-7, 1e-9
#: and under the learned law (its network's tanh, module docstring)
NETWORK = 1e-9


def _smooth(law: str) -> bool:
    return LAWS[law].smooth


@pytest.mark.parametrize("name", RUNS)
def test_example_ends_where_it_ended(name: str) -> None:
    example, backend = name.split("|")
    want = RECORDED["runs"][name]
    got = ref.run_example(ref.EXAMPLES / example, backend)
    assert got["status"] == want["status"]
    assert got["t"] == want["t"]
    x, x_ref = np.asarray(got["x"]), np.asarray(want["x"])
    assert x.shape == x_ref.shape
    scale = max(1.0, float(np.abs(x_ref).max()))
    # rounding differences of another processor's kernels (see the module's docstring)
    tolerance = SMOOTH if _smooth(got["law"]) else SWITCHING
    if got["qp"] and backend != "numpy":
        tolerance = max(tolerance, QP)
    if got["law"] == "policy":
        tolerance = max(tolerance, NETWORK)
    np.testing.assert_allclose(x, x_ref, rtol=0, atol=tolerance * scale)


@pytest.mark.parametrize("study", [s[0] for s in ref.STUDIES])
def test_seeded_study_has_the_same_trials(study: str) -> None:
    _, trials, seed = next(s for s in ref.STUDIES if s[0] == study)
    want = RECORDED["studies"][study]
    got = ref.run_seeded_study(study, trials, seed)
    assert got["law"] == want["law"]
    assert got["outcome"] == want["outcome"]
    assert got["steps"] == want["steps"]
    final, final_ref = np.asarray(got["final"]), np.asarray(want["final"])
    smooth = np.array([_smooth(law) for law in want["law"]])
    scale = max(1.0, float(np.abs(final_ref).max()))
    np.testing.assert_allclose(final[smooth], final_ref[smooth], rtol=0, atol=SMOOTH * scale)


def test_the_reference_covers_every_example() -> None:
    """A new example file joins the comparison once it is recorded (``record``)."""
    have = {name.split("|")[0] for name in RUNS}
    assert {ref.key(p) for p in ref.example_files()} == have
