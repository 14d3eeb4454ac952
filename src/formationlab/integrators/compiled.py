"""Compiled explicit-Euler runs of one formation, from three robots to a hundred thousand.

:func:`run_compiled` is the fast path of ``simulate`` for explicit Euler on
single integrators with a law that gives its data (``Law.kernel_terms``): the
whole time loop in numba, with the stepping driver's semantics (the same step
rule, saving every ``save_every`` steps and the last state, the velocity each
saved state was left with). Nothing in it is ``n x n``:

* **edges** as a neighbour list (CSR), each robot gathering its own terms, so
  the loop over robots runs in parallel without write conflicts;
* **non-neighbour repulsion and contact** through a cell grid rebuilt at every
  step, with cells of the largest interaction range: Khatib's ``gamma_ij`` acts
  only within clearance ``s0`` (pairs closer than ``a_ij + s0``), contact needs
  pairs closer than ``a_ij``, and a step can only have carried two robots
  through each other if they end closer than ``a_ij`` plus twice the step's
  largest move, so the grid's cells are at least that wide;
* **switching surfaces** decided once per step with the arithmetic of
  :func:`formationlab.potentials.triangle_products`, then gathered per robot.

Memory is ``O(n + edges + restricted triples)`` plus the saved states. The
numpy driver (:func:`formationlab.integrators.drive`) is the specification it
is tested against, to rounding.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numba import njit
from numpy.typing import NDArray

from ..controllers.terms import LOG_BARRIER, KernelTerms
from ..dynamics import System
from ..errors import ParameterError
from ..status import Status
from .base import RawSolution, steps_for
from .diagnostics import switching_diagnostics

__all__ = ["CompiledRun", "compiled_terms", "run_compiled", "run_euler_compiled"]

_COLLISION = Status.COLLISION.code
_TOO_LARGE = Status.STEP_TOO_LARGE.code
_NON_FINITE = Status.NON_FINITE.code


class CompiledRun:
    """Saved steps ``k``, states ``x`` ``(T, n, 2)``, velocities ``v``, status, steps, clearance."""

    def __init__(self, k, x, v, status, steps, min_clearance, wall):
        self.k, self.x, self.v = k, x, v
        self.status, self.steps, self.min_clearance, self.wall = status, steps, min_clearance, wall


def _csr(owner: NDArray[np.int64], n: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """Row pointers and the order that groups items by ``owner``."""
    order = np.argsort(owner, kind="stable").astype(np.int64)
    ptr = np.concatenate([[0], np.cumsum(np.bincount(owner, minlength=n))]).astype(np.int64)
    return ptr, order


def run_compiled(
    terms: KernelTerms,
    q0: NDArray[np.float64],
    *,
    dt: float,
    n_steps: int,
    save_every: int,
    progress: Callable[[float], None] | None = None,
    interruptible: bool = False,
) -> CompiledRun:
    """Step one state ``q0`` ``(n, 2)`` with explicit Euler (module docstring).

    The loop runs in compiled segments of about a quarter of a second, between which
    ``progress`` is called with the simulated time and Ctrl-C is seen: with
    ``interruptible`` the run so far is returned with status ``"interrupted"``.
    """
    n = q0.shape[0]
    ei, ej = terms.edge_i, terms.edge_j
    # each edge seen from both ends, grouped by the robot that gathers it
    nbr_ptr, order = _csr(np.concatenate([ei, ej]), n)
    nbr = np.concatenate([ej, ei])[order]
    nbr_d = np.concatenate([terms.edge_distance] * 2)[order]
    nbr_a = np.concatenate([terms.edge_contact] * 2)[order]
    term_ptr, torder = _csr(terms.term_i, n)
    m = terms.area_a.size
    area_ptr, aorder = _csr(np.concatenate([terms.area_a, terms.area_b, terms.area_c]), n)
    area_item = np.concatenate([np.arange(m)] * 3)[aorder]
    area_role = np.repeat(np.arange(3), m)[aorder]
    reach = 2.0 * float(terms.radius.max()) + terms.repulsion_influence
    rows = n_steps // save_every + 3
    k_out = np.zeros(rows, np.int64)
    x_out = np.zeros((rows, n, 2))
    v_out = np.zeros((rows, n, 2))
    info = np.zeros(3)  # status, last accepted step, saved rows
    clear = np.full(1, np.inf)
    q = np.ascontiguousarray(q0, dtype=float).copy()
    k0, status = 0, Status.SUCCESS
    step_cap = max(1, n_steps // 100)  # progress at least every 1 % of the run, as the driver
    chunk = min(256, step_cap)
    start = time.perf_counter()
    try:
        while True:
            k_end = min(n_steps, k0 + chunk)
            began = time.perf_counter()
            _run(
                q, terms, nbr_ptr, nbr, nbr_d, nbr_a, term_ptr, torder, area_ptr, area_item,
                area_role, reach, dt, k0, k_end, n_steps, save_every, k_out, x_out, v_out,
                info, clear,
            )  # fmt: skip
            status = Status.from_code(int(info[0]))
            k0 = int(info[1])
            if status is not Status.SUCCESS or k0 >= n_steps:
                break
            if progress is not None:
                progress(k0 * dt)
            spent = time.perf_counter() - began
            chunk = int(min(max(chunk * 0.25 / max(spent, 1e-6), 16), 1 << 20, step_cap))
    except KeyboardInterrupt:
        if not interruptible:
            raise
        status = Status.INTERRUPTED
        k0 = int(info[1])  # the loop's own count (it may have returned just before Ctrl-C)
        if int(info[2]) == 0:  # stopped before the first state was kept: keep it
            info[:] = 0
            _run(
                q, terms, nbr_ptr, nbr, nbr_d, nbr_a, term_ptr, torder, area_ptr, area_item,
                area_role, reach, dt, 0, 0, n_steps, save_every, k_out, x_out, v_out,
                info, clear,
            )  # fmt: skip
            k0 = 0
    wall = time.perf_counter() - start
    saved = int(info[2])
    return CompiledRun(
        k_out[:saved], x_out[:saved], v_out[:saved], status, k0, float(clear[0]), wall
    )


@njit(cache=True, fastmath=False, error_model="numpy")
def _grid(q, h, cell_of, cell_ptr_buf):
    """Counting sort of the robots into square cells of side ``h`` (doubled while there
    would be more than ``4 n`` cells); returns the shape, the side, the origin and the
    cell pointers into ``cell_ptr_buf``."""
    n = q.shape[0]
    xmin, ymin, xmax, ymax = np.inf, np.inf, -np.inf, -np.inf
    for i in range(n):
        xmin, xmax = min(xmin, q[i, 0]), max(xmax, q[i, 0])
        ymin, ymax = min(ymin, q[i, 1]), max(ymax, q[i, 1])
    # at most 4 n cells: wider cells still hold every pair within h
    while (int((xmax - xmin) / h) + 1) * (int((ymax - ymin) / h) + 1) > 4 * n + 16:
        h *= 2.0
    nx = int((xmax - xmin) / h) + 1
    ny = int((ymax - ymin) / h) + 1
    count = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        cell_of[i] = int((q[i, 0] - xmin) / h) * ny + int((q[i, 1] - ymin) / h)
    for i in range(n):
        count[cell_of[i] + 1] += 1
    for c in range(nx * ny):
        count[c + 1] += count[c]
    fill = count.copy()
    for i in range(n):
        c = cell_of[i]
        cell_ptr_buf[fill[c]] = i
        fill[c] += 1
    return nx, ny, h, xmin, ymin, count


@njit(cache=True, fastmath=False, error_model="numpy", inline="always")
def _swept(q, qp, i, j, a):
    """Least ``r_ij - a`` along the straight step ``qp -> q`` (``System.swept_clearance``)."""
    x0 = qp[j, 0] - qp[i, 0]
    y0 = qp[j, 1] - qp[i, 1]
    ex = (q[j, 0] - q[i, 0]) - x0
    ey = (q[j, 1] - q[i, 1]) - y0
    dd = ex * ex + ey * ey
    s = min(max(-(x0 * ex + y0 * ey) / (dd if dd > 0 else 1.0), 0.0), 1.0)
    mx = x0 + s * ex
    my = y0 + s * ey
    return math.sqrt(mx * mx + my * my) - a


@njit(cache=True, fastmath=False, error_model="numpy")
def _field(
    q, qp, disp, t, nbr_ptr, nbr, nbr_d, nbr_a, term_ptr, torder, area_ptr, area_item,
    area_role, reach, u, gap, swept, sigma, area_g, cell_of, items,
):  # fmt: skip
    """``u = f(q)``; per robot: least clearance ``gap`` and least swept clearance ``swept``."""
    n = q.shape[0]
    for s in range(t.surface_a.shape[0]):  # eq. (14), decided as triangle_products does
        ia, ib, ic = t.surface_a[s], t.surface_b[s], t.surface_c[s]
        cab = (q[ib, 0] - q[ia, 0]) * (q[ic, 1] - q[ia, 1]) - (q[ib, 1] - q[ia, 1]) * (
            q[ic, 0] - q[ia, 0]
        )
        sigma[s] = t.surface_beta[s] * cab + t.theta
    for mm in range(t.area_a.shape[0]):
        ia, ib, ic = t.area_a[mm], t.area_b[mm], t.area_c[mm]
        area = 0.5 * (
            (q[ib, 0] - q[ia, 0]) * (q[ic, 1] - q[ia, 1])
            - (q[ib, 1] - q[ia, 1]) * (q[ic, 0] - q[ia, 0])
        )
        area_g[mm] = t.area_gain * 0.5 * (area - t.area_target[mm])
    h = max(reach, 2.0 * t.radius.max() + 2.01 * disp)
    nx, ny, side, xmin, ymin, cell_ptr = _grid(q, h, cell_of, items)
    s0 = t.repulsion_influence
    rep = -t.repulsion_gain * t.repulsion_eta / s0
    log_barrier = t.kind == LOG_BARRIER
    for i in range(n):
        ux = 0.0
        uy = 0.0
        g_min = np.inf
        w_min = np.inf
        for p in range(nbr_ptr[i], nbr_ptr[i + 1]):  # edges, from robot i's side
            j = nbr[p]
            a = nbr_a[p]
            dx = q[j, 0] - q[i, 0]
            dy = q[j, 1] - q[i, 1]
            r2 = dx * dx + dy * dy
            r = math.sqrt(r2)
            clr = r - a
            g_min = min(g_min, clr)
            if clr <= 2.01 * disp:
                w_min = min(w_min, _swept(q, qp, i, j, a))
            if log_barrier:  # k_c phi'(r) / r, eqs. (7), (8)
                g = t.edge_gain * (clr / (nbr_d[p] - a) - 1.0) / (clr * r)
            else:  # Krick et al. 2009
                g = t.edge_gain * (r2 - nbr_d[p] * nbr_d[p])
            ux += g * dx
            uy += g * dy
        cx = int((q[i, 0] - xmin) / side)
        cy = int((q[i, 1] - ymin) / side)
        for gx in range(max(cx - 1, 0), min(cx + 2, nx)):
            for gy in range(max(cy - 1, 0), min(cy + 2, ny)):
                c = gx * ny + gy
                for pos in range(cell_ptr[c], cell_ptr[c + 1]):
                    j = items[pos]
                    if j == i:
                        continue
                    is_edge = False
                    for p in range(nbr_ptr[i], nbr_ptr[i + 1]):
                        if nbr[p] == j:
                            is_edge = True
                            break
                    if is_edge:
                        continue
                    a = t.radius[i] + t.radius[j]
                    dx = q[j, 0] - q[i, 0]
                    dy = q[j, 1] - q[i, 1]
                    r = math.sqrt(dx * dx + dy * dy)
                    clr = r - a
                    if clr > h:
                        continue
                    g_min = min(g_min, clr)
                    if clr <= 2.01 * disp:
                        w_min = min(w_min, _swept(q, qp, i, j, a))
                    if clr < s0:  # k_r gamma'(s) / r, Khatib
                        g = rep * (s0 - clr) / (clr * clr * clr * r)
                        ux += g * dx
                        uy += g * dy
        for p in range(term_ptr[i], term_ptr[i + 1]):  # eqs. (11), (13), (23)
            v = torder[p]
            if sigma[t.term_surface[v]] >= 0.0:  # Upsilon(0) = 1
                w = t.term_weight[v]
                j, k = t.term_j[v], t.term_k[v]
                ux += w * (q[k, 1] - q[j, 1])
                uy -= w * (q[k, 0] - q[j, 0])
        for p in range(area_ptr[i], area_ptr[i + 1]):  # signed-area penalty
            mm = area_item[p]
            role = area_role[p]
            ia, ib, ic = t.area_a[mm], t.area_b[mm], t.area_c[mm]
            if role == 0:
                ux += area_g[mm] * (q[ic, 1] - q[ib, 1])
                uy -= area_g[mm] * (q[ic, 0] - q[ib, 0])
            elif role == 1:
                ux += area_g[mm] * (q[ia, 1] - q[ic, 1])
                uy -= area_g[mm] * (q[ia, 0] - q[ic, 0])
            else:
                ux += area_g[mm] * (q[ib, 1] - q[ia, 1])
                uy -= area_g[mm] * (q[ib, 0] - q[ia, 0])
        u[i, 0] = ux
        u[i, 1] = uy
        gap[i] = g_min
        swept[i] = w_min


@njit(cache=True, fastmath=False, error_model="numpy")
def _run(
    q0, t, nbr_ptr, nbr, nbr_d, nbr_a, term_ptr, torder, area_ptr, area_item, area_role,
    reach, dt, k0, k_end, n_steps, save_every, k_out, x_out, v_out, info, clear,
):  # fmt: skip
    """The time loop from step ``k0`` (an accepted state) to ``k_end`` of ``n_steps``.

    At each step: the field at ``x_k``, the verdict on the step that led there,
    saving (every ``save_every`` steps, the last step, and a trial's last state),
    then the Euler step. ``info`` returns status, last accepted step and rows
    saved (appended after ``info[2]`` rows); ``clear`` the least clearance so far.
    """
    n = q0.shape[0]
    q = q0  # advanced in place: on return it holds the state of step info[1]
    qp = q0.copy()
    u = np.zeros((n, 2))
    up = np.zeros((n, 2))
    gap = np.empty(n)
    swept = np.empty(n)
    sigma = np.empty(t.surface_a.shape[0])
    area_g = np.empty(t.area_a.shape[0])
    cell_of = np.empty(n, np.int64)
    items = np.empty(n, np.int64)
    disp = 0.0
    saved = int(info[2])
    status = 0
    least = clear[0]
    k = k0
    while True:
        _field(
            q, qp, disp, t, nbr_ptr, nbr, nbr_d, nbr_a, term_ptr, torder, area_ptr, area_item,
            area_role, reach, u, gap, swept, sigma, area_g, cell_of, items,
        )  # fmt: skip
        if k > k0:  # the step rule of System.step_verdict
            g = gap.min()
            if not g > 0.0:
                status = _COLLISION
            elif not swept.min() > 0.0:
                status = _TOO_LARGE
            if status:  # end at the last accepted state, with the velocity it was left with
                if saved == 0 or k_out[saved - 1] != k - 1:
                    k_out[saved] = k - 1
                    x_out[saved] = qp
                    v_out[saved] = up
                    saved += 1
                q[:] = qp
                k -= 1
                break
            least = min(least, g)
        elif k == 0:
            least = gap.min()
        if (k % save_every == 0 or k == n_steps) and (k > k0 or k == 0):
            k_out[saved] = k
            x_out[saved] = q
            v_out[saved] = u
            saved += 1
        if k == n_steps or k == k_end:
            break
        largest = 0.0
        for i in range(n):
            for d in range(2):
                qp[i, d] = q[i, d]
                up[i, d] = u[i, d]
                q[i, d] = q[i, d] + dt * u[i, d]  # explicit Euler
            ex = q[i, 0] - qp[i, 0]
            ey = q[i, 1] - qp[i, 1]
            largest = max(largest, ex * ex + ey * ey)
        k += 1
        if not math.isfinite(largest):  # not finite: judged before the grid sees it
            status = _NON_FINITE
            if saved == 0 or k_out[saved - 1] != k - 1:
                k_out[saved] = k - 1
                x_out[saved] = qp
                v_out[saved] = up
                saved += 1
            q[:] = qp
            k -= 1
            break
        disp = math.sqrt(largest)
    info[0] = status
    info[1] = k
    info[2] = saved
    clear[0] = least


def compiled_terms(system: System, integrator: object) -> KernelTerms | None:
    """The law's kernel data when ``system`` under ``integrator`` can run compiled, else None.

    Explicit Euler (exactly, not a subclass) on the paper's single integrators
    (no speed limit) without marching, with a law whose ``kernel_terms`` describe
    its control.
    """
    from ..models import SingleIntegrator
    from .explicit import Euler

    if type(integrator) is not Euler or system.model != SingleIntegrator():  # no limits
        return None
    if system.marching is not None or system.obstacles or system.filtered:
        return None
    if system.sensed or (system.faults is not None and system.faults.any):
        return None
    try:
        return system.law.compiled_terms(system.formation)
    except ParameterError:
        return None


def run_euler_compiled(
    terms: KernelTerms,
    system: System,
    x0: NDArray[np.float64],
    *,
    dt: float,
    duration: float,
    save_every: int,
    progress: Callable[[float], None] | None = None,
    interruptible: bool = False,
) -> RawSolution:
    """:meth:`Euler.run` on the compiled path: the same :class:`RawSolution`.

    The switching diagnostics are computed from the saved states (exact with
    ``save_every = 1``, as the driver records them; from the saved states only
    otherwise, which ``stats["diagnostics_from"]`` says).
    """
    n_steps = steps_for(duration, dt)
    out = run_compiled(
        terms, x0, dt=dt, n_steps=n_steps, save_every=save_every, progress=progress,
        interruptible=interruptible,
    )  # fmt: skip
    t = out.k * dt
    if out.status is Status.SUCCESS:
        message = f"integrated {out.steps} steps of dt = {dt:g} s"
    elif out.status is Status.INTERRUPTED:
        message = f"interrupted by the user at t = {out.steps * dt:g} s"
    else:  # the rejected step: from the last accepted state, once more in numpy for the words
        x_last = out.x[-1]
        x_next = x_last + dt * out.v[-1]
        message = system.step_message(x_last, x_next, out.status, (out.steps + 1) * dt, dt)
    sigma = system.sigma(out.x)
    stats: dict[str, Any] = {
        "steps": int(out.steps),
        "rhs_evaluations": int(out.steps) + 1,
        "wall_time_s": out.wall,
        "step_cost_s": out.wall / max(out.steps, 1),
        **switching_diagnostics(t, sigma),
        "diagnostics_from": "every step" if save_every == 1 else f"every {save_every} steps",
        "backend": "numba",
    }
    return RawSolution(t=t, x=out.x, v=out.v, status=out.status, message=message, stats=stats)
