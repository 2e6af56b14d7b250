"""
The extended Kalman filter core: a tight sequential loop, compiled with numba.

(Over 400 lines on purpose: the filter's prediction and updates are one compiled loop over one
state layout, declared once.)

State (7): ``x, y`` (metres east/north of the track origin), ``yaw`` (radians counter-clockwise
from east), ``v`` (speed along the heading, m/s), ``bg`` (gyro bias, rad/s), ``so`` (odometer
scale: odometer reading / true distance), ``sg`` (gyro scale error: true rate =
``(gyro - bg) * (1 + sg)``).

The motion model is the 2-D unicycle of a car: the velocity points along the heading, so the
non-holonomic constraint (no sideways or vertical velocity) is built in rather than added as a
pseudo-measurement. Each sensor epoch ``k``:

1. Stopped (odometer at zero for ``zupt_window_s``): speed is updated to zero (ZUPT), the gyro
   reading is a direct measurement of its bias (zero angular rate update), heading and position
   are not propagated and gain no process noise, and updates made while standing correct only
   their own states (GNSS: position; gyro: bias): no heading drift at red lights.
2. Moving: speed random walk; odometer update ``z = so * v``; pose propagated with the midpoint
   heading over the interval (exact on circular arcs) with the full Jacobian.
3. GNSS position update, chi-square gated; receiver speed/course update when fast enough.
4. Road pseudo-measurement (position with along/cross-road covariance and road heading) when
   given and GNSS has been absent for a while.

Covariance updates use the Joseph form. Small-matrix products are written out as loops:
in numba that beats calling BLAS for 7x7 matrices and needs no contiguous copies.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, cast

import numpy as np

if TYPE_CHECKING:
    import numpy.typing as npt

    FloatArray = npt.NDArray[np.float64]

__all__ = ["NSTATE", "PARAM_NAMES", "run_filter"]

NSTATE = 7
PARAM_NAMES = (
    "q_pos",  # m^2/s
    "q_yaw",  # rad^2/s (gyro angle random walk squared)
    "q_speed",  # m^2/s^3
    "q_bias",  # rad^2/s^3
    "q_odo_scale",  # 1/s
    "q_gyro_scale",  # 1/s
    "r_odo",  # m^2/s^2 per sample
    "r_zupt",  # m^2/s^2
    "chi2_pos",
    "max_rejects",
    "sigma_gnss_speed",  # m/s
    "course_floor",  # rad
    "min_course_speed",  # m/s
    "chi2_vel",
    "sigma_road_yaw",  # rad
    "road_min_gap",  # s
    "chi2_road",
)
(
    _Q_POS,
    _Q_YAW,
    _Q_SPEED,
    _Q_BIAS,
    _Q_SO,
    _Q_SG,
    _R_ODO,
    _R_ZUPT,
    _CHI2_POS,
    _MAX_REJ,
    _SIG_GSPEED,
    _COURSE_FLOOR,
    _MIN_COURSE_SPEED,
    _CHI2_VEL,
    _SIG_ROAD_YAW,
    _ROAD_MIN_GAP,
    _CHI2_ROAD,
) = range(len(PARAM_NAMES))

# gnss status codes per epoch
NO_FIX, FIX_USED, FIX_GATED, FIX_REJECTED = 0, 1, 2, 3


def _wrap(a: float) -> float:
    return (a + math.pi) % (2.0 * math.pi) - math.pi


def _mm(a: FloatArray, b: FloatArray) -> FloatArray:
    n, m = a.shape
    p = b.shape[1]
    c = np.zeros((n, p))
    for i in range(n):
        for k in range(m):
            aik = a[i, k]
            if aik != 0.0:
                for j in range(p):
                    c[i, j] += aik * b[k, j]
    return c


def _mmt(a: FloatArray, b: FloatArray) -> FloatArray:
    """Return ``a @ b.T``."""
    n, m = a.shape
    p = b.shape[0]
    c = np.zeros((n, p))
    for i in range(n):
        for j in range(p):
            s = 0.0
            for k in range(m):
                s += a[i, k] * b[j, k]
            c[i, j] = s
    return c


def _inv(s: FloatArray) -> FloatArray:
    """Gauss-Jordan inverse with partial pivoting (for the 1x1..3x3 innovation covariances)."""
    n = s.shape[0]
    a = s.copy()
    inv = np.eye(n)
    for col in range(n):
        piv = col
        for r in range(col + 1, n):
            if abs(a[r, col]) > abs(a[piv, col]):
                piv = r
        if piv != col:
            for j in range(n):
                a[col, j], a[piv, j] = a[piv, j], a[col, j]
                inv[col, j], inv[piv, j] = inv[piv, j], inv[col, j]
        d = a[col, col]
        for j in range(n):
            a[col, j] /= d
            inv[col, j] /= d
        for r in range(n):
            if r != col:
                f = a[r, col]
                if f != 0.0:
                    for j in range(n):
                        a[r, j] -= f * a[col, j]
                        inv[r, j] -= f * inv[col, j]
    return inv


def _update(
    x: FloatArray,
    p: FloatArray,
    nu: FloatArray,
    h: FloatArray,
    r: FloatArray,
    gate: float,
    mask: FloatArray,
) -> tuple[bool, float]:
    """
    EKF measurement update in place; returns (accepted, normalised innovation squared).

    ``mask`` (0/1 per state) zeroes gain rows: states outside it are not corrected (a
    "consider" update). The Joseph form keeps the covariance right for such a gain.
    """
    n = x.shape[0]
    m = nu.shape[0]
    pht = _mmt(p, h)
    s = _mm(h, pht) + r
    si = _inv(s)
    d2 = 0.0
    for i in range(m):
        for j in range(m):
            d2 += nu[i] * si[i, j] * nu[j]
    if gate > 0.0 and d2 > gate:
        return False, d2
    k = _mm(pht, si)
    for i in range(n):
        for j in range(m):
            k[i, j] *= mask[i]
            x[i] += k[i, j] * nu[j]
    a = np.eye(n) - _mm(k, h)
    p_new = _mmt(_mm(a, p), a) + _mmt(_mm(k, r), k)
    for i in range(n):
        for j in range(n):
            p[i, j] = 0.5 * (p_new[i, j] + p_new[j, i])
    return True, d2


def _kernel(
    t: FloatArray,
    odo: FloatArray,
    gyro: FloatArray,
    stopped: npt.NDArray[np.bool_],
    fix_state: npt.NDArray[np.int8],
    fx: FloatArray,
    fy: FloatArray,
    fsig: FloatArray,
    gspeed: FloatArray,
    gyaw: FloatArray,
    fb_has: npt.NDArray[np.bool_],
    fbx: FloatArray,
    fby: FloatArray,
    fbyaw: FloatArray,
    fb_along: FloatArray,
    fb_cross: FloatArray,
    i0: int,
    x0: FloatArray,
    p0: FloatArray,
    prm: FloatArray,
) -> tuple[
    FloatArray,
    FloatArray,
    FloatArray,
    npt.NDArray[np.int8],
    npt.NDArray[np.bool_],
    FloatArray,
]:
    n = t.shape[0]
    ns = x0.shape[0]
    states = np.full((n, ns), np.nan)
    pdiag = np.full((n, ns), np.nan)
    ppos = np.full((n, 3), np.nan)
    status = np.zeros(n, dtype=np.int8)
    fb_used = np.zeros(n, dtype=np.bool_)
    dist = np.full(n, np.nan)
    x = x0.copy()
    p = p0.copy()
    h1 = np.zeros((1, ns))
    r1 = np.zeros((1, 1))
    nu1 = np.zeros(1)
    h2 = np.zeros((2, ns))
    r2 = np.zeros((2, 2))
    nu2 = np.zeros(2)
    h3 = np.zeros((3, ns))
    r3 = np.zeros((3, 3))
    nu3 = np.zeros(3)
    f = np.eye(ns)
    m_all = np.ones(ns)
    m_pos = np.zeros(ns)  # standing still: fixes correct position only ...
    m_pos[0] = 1.0
    m_pos[1] = 1.0
    m_speed = np.zeros(ns)
    m_speed[3] = 1.0
    m_bias = np.zeros(ns)  # ... and the gyro reading only its bias: heading is held
    m_bias[4] = 1.0
    for i in range(ns):
        states[i0, i] = x[i]
        pdiag[i0, i] = p[i, i]
    ppos[i0, 0], ppos[i0, 1], ppos[i0, 2] = p[0, 0], p[0, 1], p[1, 1]
    status[i0] = FIX_USED
    dist[i0] = 0.0
    rejects = 0
    last_gnss_t = t[i0]
    max_rej = int(prm[_MAX_REJ])
    for k in range(i0 + 1, n):
        dt = t[k] - t[k - 1]
        moved = 0.0
        if stopped[k]:
            p[4, 4] += prm[_Q_BIAS] * dt
            p[5, 5] += prm[_Q_SO] * dt
            p[6, 6] += prm[_Q_SG] * dt
            h1[0, :] = 0.0
            h1[0, 3] = 1.0
            nu1[0] = -x[3]
            r1[0, 0] = prm[_R_ZUPT]
            _update(x, p, nu1, h1, r1, 0.0, m_speed)
            h1[0, 3] = 0.0
            h1[0, 4] = 1.0
            nu1[0] = gyro[k] - x[4]
            r1[0, 0] = prm[_Q_YAW] / dt  # per-sample variance of the gyro white noise
            _update(x, p, nu1, h1, r1, 0.0, m_bias)
        else:
            p[3, 3] += prm[_Q_SPEED] * dt
            h1[0, :] = 0.0
            h1[0, 3] = x[5]
            h1[0, 5] = x[3]
            nu1[0] = odo[k] - x[5] * x[3]
            r1[0, 0] = prm[_R_ODO]
            _update(x, p, nu1, h1, r1, 0.0, m_all)
            g = gyro[k]
            sc = 1.0 + x[6]
            rate = g - x[4]
            dyaw = rate * sc * dt
            ym = x[2] + 0.5 * dyaw
            c = math.cos(ym)
            s = math.sin(ym)
            v = x[3]
            f[:, :] = 0.0
            for i in range(ns):
                f[i, i] = 1.0
            f[0, 2] = -v * s * dt
            f[0, 3] = c * dt
            f[0, 4] = v * s * dt * sc * 0.5 * dt
            f[0, 6] = -v * s * dt * rate * 0.5 * dt
            f[1, 2] = v * c * dt
            f[1, 3] = s * dt
            f[1, 4] = -v * c * dt * sc * 0.5 * dt
            f[1, 6] = v * c * dt * rate * 0.5 * dt
            f[2, 4] = -sc * dt
            f[2, 6] = rate * dt
            x[0] += v * c * dt
            x[1] += v * s * dt
            x[2] += dyaw
            moved = v * dt
            p_new = _mmt(_mm(f, p), f)
            for i in range(ns):
                for j in range(ns):
                    p[i, j] = 0.5 * (p_new[i, j] + p_new[j, i])
            p[0, 0] += prm[_Q_POS] * dt
            p[1, 1] += prm[_Q_POS] * dt
            p[2, 2] += prm[_Q_YAW] * sc * sc * dt
            p[4, 4] += prm[_Q_BIAS] * dt
            p[5, 5] += prm[_Q_SO] * dt
            p[6, 6] += prm[_Q_SG] * dt
        dist[k] = dist[k - 1] + abs(moved)
        fs = fix_state[k]
        if fs == FIX_GATED:
            status[k] = FIX_GATED
        elif fs == FIX_USED:
            h2[:, :] = 0.0
            h2[0, 0] = 1.0
            h2[1, 1] = 1.0
            nu2[0] = fx[k] - x[0]
            nu2[1] = fy[k] - x[1]
            r2[0, 0] = fsig[k] * fsig[k]
            r2[1, 1] = r2[0, 0]
            r2[0, 1] = 0.0
            r2[1, 0] = 0.0
            gate = prm[_CHI2_POS]
            if rejects >= max_rej:
                # the filter has lost the fixes: admit the error and start over from GNSS
                p[0, 0] += nu2[0] * nu2[0]
                p[1, 1] += nu2[1] * nu2[1]
                gate = 0.0
            ok, _ = _update(x, p, nu2, h2, r2, gate, m_pos if stopped[k] else m_all)
            if ok:
                status[k] = FIX_USED
                rejects = 0
                last_gnss_t = t[k]
                gs = gspeed[k]
                if (not stopped[k]) and gs == gs and gs >= prm[_MIN_COURSE_SPEED]:
                    sv = prm[_SIG_GSPEED]
                    sc_yaw = max(sv / gs, prm[_COURSE_FLOOR])
                    h2[:, :] = 0.0
                    h2[0, 3] = 1.0
                    h2[1, 2] = 1.0
                    nu2[0] = gs - x[3]
                    nu2[1] = _wrap(gyaw[k] - x[2])
                    r2[0, 0] = sv * sv
                    r2[1, 1] = sc_yaw * sc_yaw
                    _update(x, p, nu2, h2, r2, prm[_CHI2_VEL], m_all)
            else:
                status[k] = FIX_REJECTED
                rejects += 1
        if fb_has[k] and (not stopped[k]) and t[k] - last_gnss_t >= prm[_ROAD_MIN_GAP]:
            cy = math.cos(fbyaw[k])
            sy = math.sin(fbyaw[k])
            a2 = fb_along[k] * fb_along[k]
            c2 = fb_cross[k] * fb_cross[k]
            h3[:, :] = 0.0
            h3[0, 0] = 1.0
            h3[1, 1] = 1.0
            h3[2, 2] = 1.0
            nu3[0] = fbx[k] - x[0]
            nu3[1] = fby[k] - x[1]
            nu3[2] = _wrap(fbyaw[k] - x[2])
            r3[:, :] = 0.0
            r3[0, 0] = a2 * cy * cy + c2 * sy * sy
            r3[1, 1] = a2 * sy * sy + c2 * cy * cy
            r3[0, 1] = (a2 - c2) * cy * sy
            r3[1, 0] = r3[0, 1]
            r3[2, 2] = prm[_SIG_ROAD_YAW] * prm[_SIG_ROAD_YAW]
            ok, _ = _update(x, p, nu3, h3, r3, prm[_CHI2_ROAD], m_all)
            fb_used[k] = ok
        for i in range(ns):
            states[k, i] = x[i]
            pdiag[k, i] = p[i, i]
        ppos[k, 0], ppos[k, 1], ppos[k, 2] = p[0, 0], p[0, 1], p[1, 1]
    return states, pdiag, ppos, status, fb_used, dist


_KernelFn = Callable[
    ...,
    tuple[
        "FloatArray",
        "FloatArray",
        "FloatArray",
        "npt.NDArray[np.int8]",
        "npt.NDArray[np.bool_]",
        "FloatArray",
    ],
]


def _compile() -> _KernelFn:
    if os.environ.get("MAPMATCH_FUSION_NO_NUMBA"):
        return cast("_KernelFn", _kernel)
    import numba  # imported lazily: plain-Python runs need no JIT

    # numba resolves the helpers through the module globals when it compiles the kernel
    global _wrap, _mm, _mmt, _inv, _update
    jit = numba.njit(cache=True, nogil=True)
    _wrap = jit(_wrap)
    _mm = jit(_mm)
    _mmt = jit(_mmt)
    _inv = jit(_inv)
    _update = jit(_update)
    return cast("_KernelFn", jit(_kernel))


_compiled: list[_KernelFn] = []


def run_filter(
    t: FloatArray,
    odo: FloatArray,
    gyro: FloatArray,
    stopped: npt.NDArray[np.bool_],
    fix_state: npt.NDArray[np.int8],
    fx: FloatArray,
    fy: FloatArray,
    fsig: FloatArray,
    gspeed: FloatArray,
    gyaw: FloatArray,
    fb_has: npt.NDArray[np.bool_],
    fbx: FloatArray,
    fby: FloatArray,
    fbyaw: FloatArray,
    fb_along: FloatArray,
    fb_cross: FloatArray,
    i0: int,
    x0: FloatArray,
    p0: FloatArray,
    prm: FloatArray,
) -> tuple[
    FloatArray,
    FloatArray,
    FloatArray,
    npt.NDArray[np.int8],
    npt.NDArray[np.bool_],
    FloatArray,
]:
    """
    Run the filter from epoch ``i0`` to the end (arrays as prepared by :func:`fuse`).

    Returns
    -------
    tuple
        ``states`` (n, 7), ``pdiag`` (n, 7) state variances, ``ppos`` (n, 3) position
        covariance ``(xx, xy, yy)``, GNSS ``status`` per epoch (0 no fix, 1 used, 2 failed the
        quality gate, 3 failed the innovation test), ``fb_used`` per epoch and fused cumulative
        distance ``dist`` (m). Rows before ``i0`` are NaN.

    Notes
    -----
    The loop is compiled with numba on first use (cached on disk); set the environment
    variable ``MAPMATCH_FUSION_NO_NUMBA=1`` to run it as plain Python (about 100x slower).
    """
    if not _compiled:
        _compiled.append(_compile())
    return _compiled[0](
        t, odo, gyro, stopped, fix_state, fx, fy, fsig, gspeed, gyaw,
        fb_has, fbx, fby, fbyaw, fb_along, fb_cross, i0, x0, p0, prm,
    )  # fmt: skip
