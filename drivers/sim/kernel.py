"""The simulator's compiled inner loop (numba): per-wheel speed loop, motors, contact, body.

One call advances ``N`` robots through ``n`` sensor periods. Python builds the
per-period inputs (commands, fault schedule, pre-drawn noise) in
:mod:`drivers.sim.simulator`; this module only integrates. It is written as explicit
scalar loops because the dynamics are sequential in time and branch on
saturation, traction and contact; numba compiles them once and caches the
machine code beside the source.

Model, per wheel ``i`` (left 0, right 1), all at the wheel rim:

- transport delay: the command sent at ``t_k`` takes effect at
  ``t_k + (d + extra + jitter) T``, never before an earlier command;
- speed loop (every controller step): measured speed ``m`` is the wheel's
  rotation times its *nominal* radius (the firmware does not know the true
  one, nor a change of it during the drive: a ``wheel_diameter`` fault, hair
  wound on the wheel, scales the true diameter by the period's factor; the rim
  speed is continuous at the change, the rotation per rim travel is not)
  through a first-order filter; ``V = kff sp + kp (sp - m) + I - kd dm/dt``,
  clipped to the supply, with conditional integration (anti-windup: the
  integrator holds while the output saturates in the direction of the error);
- DC motor, quasi-static armature: ``i = clip((V - g k u) / R, +-i_max)``,
  force ``g k i``, where ``g`` is the motor's health (1 = nominal): the
  armature current from the applied voltage less the back-EMF ``g k u``
  (Franklin, Powell & Emami-Naeini, "Feedback Control of Dynamic Systems",
  section 2.3, DC motor with negligible inductance). A frame reports each
  motor's mean current over the period and the Open Interface's wheel
  overcurrent flag (packet 14), set once the current has stayed at the
  driver's limit for :data:`OVERCURRENT_S` (a blocked wheel; a start from
  rest reaches the limit only briefly);
- wheel: ``m_w du/dt = F_motor - F_gear(u) - (1 - c) F_trac + F_rough``;
- contact: slip speed ``s = (1 - c) u - v_c`` with the contact point's speed
  ``v_c = v -+ w b / 2``, slip ratio ``kappa = s / max(|(1 - c) u|, |v_c|, 0.05)``
  and traction ``F_trac = mu N tanh(kappa / kappa0)`` (a smooth traction limit;
  Pacejka, "Tire and Vehicle Dynamics", 2012, ch. 1: force grows with slip
  ratio up to a peak), with tyre compression ``c`` shrinking the rolling radius;
  rolling resistance ``c_rr N`` opposes each wheel's contact motion;
- body: ``M dv/dt = sum(F_trac - F_roll) - F_caster,x`` and
  ``I dw/dt = sum(+-b / 2 (F_trac - F_roll)) - x_c F_caster,y - M_twist``, where the
  front caster at ``x_c`` ahead of the axle rolls against ``c_rr N_caster`` along
  its own contact velocity ``(v, w x_c)``, and ``M_twist = scrub M g (b / 2)
  tanh(w / 0.05)`` is the tyres' resistance to twisting in place;
- pose: the exact constant-speed arc over each mechanical sub-step;
- encoders count wheel rotation in the commanded direction (up when the
  command is zero), as the Roomba's non-quadrature encoders do
  (spec §6.2, :mod:`drivers.roomba.oi`), so slip is invisible to them.

The mechanics is integrated with semi-implicit Euler at a quarter of the
controller step; each wheel's update is implicit in its own slip (the traction
force linearised about the current slip), which keeps the stiff, light wheel
mode stable at low speed, where the slip-ratio contact is stiffest.

The paper: ``docs/architecture.md``, "The paper".
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["N_NOISE", "N_PARAMS", "N_PERIOD", "N_STATE", "OVERCURRENT_S", "QUEUE_LEN",
           "run_periods"]

GRAVITY = 9.81

# --- state columns -----------------------------------------------------------
X, Y, TH, V, W = 0, 1, 2, 3, 4
U0 = 5          # wheel rim speeds 5, 6 [m/s]
INT0 = 7        # PID integrators 7, 8 [V]
MEAS0 = 9       # filtered measured speeds 9, 10 [m/s]
TICK0 = 11      # encoder accumulators (continuous, signed) 11, 12 [ticks]
SP0 = 13        # setpoints in effect 13, 14 [m/s]
OFF0 = 15       # ticks lost while an encoder was stuck 15, 16
T_NOW = 17      # simulation time [s]
LAST_EFF = 18   # effective time of the newest queued command [s]
LIMIT0 = 19     # time each motor's current has stayed at the limit 19, 20 [s]
N_STATE = 21

# --- parameter columns (one row per robot) -------------------------------------
(P_B, P_DIAM, P_TPR, P_MASS, P_I0, P_RPAY, P_FRAC, P_MW, P_K, P_R, P_ILIM, P_VSUP,
 P_BG, P_FC, P_BAL, P_KP, P_KI, P_KD, P_KFF, P_TAU, P_DELAY, P_JITTER, P_T, P_NSUB,
 P_RADIUS, P_IRR, P_IRREF, P_IRNOISE, P_FLOOR0) = range(29)
P_IRANG = 29    # 29..34: light-bump sensor angles [rad]
P_DERR0 = 35    # 35, 36: relative wheel-diameter errors (left, right)
P_CASTER = 37   # caster offset ahead of the axle [m]
N_PARAMS = 38

# --- per-period inputs (fault schedule) ----------------------------------------
PP_FLOOR, PP_PAYLOAD, PP_GAIN0, PP_DELAY, PP_STUCK0, PP_STALL0, PP_DIAM0 = 0, 1, 2, 4, 5, 7, 9
N_PERIOD = 11   # floor override, payload, gain L/R, extra delay, stuck L/R, stall L/R,
                # diameter factor L/R (1 = the wheel's own diameter; a wheel_diameter fault)

# --- per-period noise (standard draws) ------------------------------------------
NZ_JITTER, NZ_ROUGH0, NZ_IR0 = 0, 1, 3
N_NOISE = 9     # jitter U(-1/2, 1/2), roughness N(0,1) L/R, IR N(0,1) x 6

# --- floor table columns -------------------------------------------------------
F_MU, F_KAPPA, F_CRR, F_COMP, F_ROUGH, F_SCRUB = range(6)

QUEUE_LEN = 32
#: Time at the current limit after which a wheel's overcurrent flag is set [s].
OVERCURRENT_S = 0.5
N_MECH = 4
V_SLIP_REF = 0.05     # speed below which slip is measured against this speed [m/s]


@njit(cache=True)
def _floor_at(x, y, default, regions):
    idx = default
    for g in range(regions.shape[0]):
        if regions[g, 0] <= x < regions[g, 1] and regions[g, 2] <= y < regions[g, 3]:
            idx = int(regions[g, 4])
    return idx


@njit(cache=True)
def _sinc_half(phi):
    # sin(phi / 2) / (phi / 2), stable at phi = 0
    h = 0.5 * phi
    if abs(h) < 1e-4:
        return 1.0 - h * h / 6.0
    return math.sin(h) / h


@njit(cache=True)
def _light_bumps(st, p, walls, noise_row, out):
    x, y, th = st[X], st[Y], st[TH]
    for j in range(6):
        a = th + p[P_IRANG + j]
        dx, dy = math.cos(a), math.sin(a)
        ox, oy = x + p[P_IRR] * dx, y + p[P_IRR] * dy
        best = 1e9
        gain = 0.0
        for s in range(walls.shape[0]):
            ex, ey = walls[s, 2] - walls[s, 0], walls[s, 3] - walls[s, 1]
            den = dx * ey - dy * ex
            if abs(den) < 1e-12:
                continue
            px, py = walls[s, 0] - ox, walls[s, 1] - oy
            t = (px * ey - py * ex) / den
            u = (px * dy - py * dx) / den
            if t > 0.0 and 0.0 <= u <= 1.0 and t < best:
                best = t
                # reflectivity times cos(incidence) = |sin(ray, wall)|
                gain = walls[s, 4] * abs(den) / math.sqrt(ex * ex + ey * ey)
        sig = 0.0
        if best < 1e8:
            r = max(best, p[P_IRREF])
            sig = 4095.0 * gain * (p[P_IRREF] / r) ** 2
        sig += p[P_IRNOISE] * noise_row[NZ_IR0 + j]
        out[j] = min(4095, max(0, round(sig)))


@njit(cache=True)
def _contacts(st, p, walls, bumps):
    """Push the body out of walls, stop motion into them, set bump flags."""
    bumps[0] = False
    bumps[1] = False
    rad = p[P_RADIUS]
    for s in range(walls.shape[0]):
        x1, y1 = walls[s, 0], walls[s, 1]
        ex, ey = walls[s, 2] - x1, walls[s, 3] - y1
        ll = ex * ex + ey * ey
        u = 0.0
        if ll > 0.0:
            u = min(1.0, max(0.0, ((st[X] - x1) * ex + (st[Y] - y1) * ey) / ll))
        qx, qy = x1 + u * ex, y1 + u * ey
        nx, ny = st[X] - qx, st[Y] - qy
        d = math.sqrt(nx * nx + ny * ny)
        if d >= rad + 0.002 or d < 1e-9:
            continue
        nx, ny = nx / d, ny / d
        if d < rad:
            st[X] += (rad - d) * nx
            st[Y] += (rad - d) * ny
        if st[V] * (math.cos(st[TH]) * nx + math.sin(st[TH]) * ny) < 0.0:
            st[V] = 0.0
        phi = math.atan2(-ny, -nx) - st[TH]
        phi = math.atan2(math.sin(phi), math.cos(phi))
        if -0.17 <= phi <= 1.75:
            bumps[0] = True
        if -1.75 <= phi <= 0.17:
            bumps[1] = True


@njit(cache=True)
def run_periods(state, queue, qinfo, params, floors, regions, walls, cmd, per_period,
                noise, out_ticks, out_light, out_bumps, out_pose, out_body, out_current,
                out_overcurrent):
    """Advance every robot through ``cmd.shape[1]`` sensor periods, in place.

    Parameters
    ----------
    state : (N, N_STATE) float64, queue : (N, QUEUE_LEN, 3) float64,
    qinfo : (N, 2) int64
        Robot state, pending-command queue (effective time, left, right) and
        its (head, count); updated in place.
    params : (N, N_PARAMS) float64
    floors : (F, 6) float64
    regions : (G, 5) float64
        Floor-map rectangles (xmin, xmax, ymin, ymax, floor index).
    walls : (S, 5) float64
        Wall segments (x1, y1, x2, y2, reflectivity).
    cmd : (N, n, 2) float64
        Wheel-speed commands sent at the start of each period [m/s].
    per_period : (N, n, N_PERIOD) float64
    noise : (N, n, N_NOISE) float64
    out_ticks : (N, n, 2) int64, out_light : (N, n, 6) int64,
    out_bumps : (N, n, 2) bool, out_pose : (N, n, 3), out_body : (N, n, 2),
    out_current : (N, n, 2), out_overcurrent : (N, n, 2) bool
        Filled with the frame taken at the end of each period (the motor
        currents [A] are means over the period; the counts unwrapped, the
        caller wraps them at the robot's ``counter_bits``).
    """
    n_rob, n_per = cmd.shape[0], cmd.shape[1]
    for i in range(n_rob):
        st = state[i]
        p = params[i]
        period = p[P_T]
        nsub = int(p[P_NSUB])
        dt = period / nsub
        h = dt / N_MECH
        half_b = 0.5 * p[P_B]
        circ = math.pi * p[P_DIAM]
        alpha = 1.0 - math.exp(-dt / p[P_TAU])
        for k in range(n_per):
            pp = per_period[i, k]
            nz = noise[i, k]
            t_k = st[T_NOW]
            # transport delay with jitter; commands never overtake each other
            delay = (p[P_DELAY] + pp[PP_DELAY] + p[P_JITTER] * nz[NZ_JITTER]) * period
            eff = max(t_k + delay, st[LAST_EFF])
            st[LAST_EFF] = eff
            head, count = qinfo[i, 0], qinfo[i, 1]
            if count == QUEUE_LEN:          # full: drop the oldest
                head = (head + 1) % QUEUE_LEN
                count -= 1
            slot = (head + count) % QUEUE_LEN
            queue[i, slot, 0] = eff
            queue[i, slot, 1] = cmd[i, k, 0]
            queue[i, slot, 2] = cmd[i, k, 1]
            count += 1
            # surface, load and motor health for this period
            fidx = int(pp[PP_FLOOR])
            if fidx < 0:
                fidx = _floor_at(st[X], st[Y], int(p[P_FLOOR0]), regions)
            fl = floors[fidx]
            mass = p[P_MASS] + pp[PP_PAYLOAD]
            inertia = p[P_I0] + pp[PP_PAYLOAD] * p[P_RPAY] ** 2
            normal = 0.5 * p[P_FRAC] * mass * GRAVITY
            keep = 1.0 - fl[F_COMP]
            trac_max = fl[F_MU] * normal
            roll_wheel = fl[F_CRR] * normal
            roll_caster = fl[F_CRR] * (1.0 - p[P_FRAC]) * mass * GRAVITY
            t_scrub = fl[F_SCRUB] * mass * GRAVITY * half_b
            out_current[i, k, 0] = 0.0
            out_current[i, k, 1] = 0.0
            for s in range(nsub):
                t = t_k + s * dt
                while count > 0 and queue[i, head, 0] <= t + 1e-12:
                    st[SP0] = queue[i, head, 1]
                    st[SP0 + 1] = queue[i, head, 2]
                    head = (head + 1) % QUEUE_LEN
                    count -= 1
                volt0 = 0.0
                volt1 = 0.0
                for wh in range(2):
                    # the firmware converts rotation to speed with the nominal diameter
                    meas_old = st[MEAS0 + wh]
                    nominal = st[U0 + wh] / ((1.0 + p[P_DERR0 + wh]) * pp[PP_DIAM0 + wh])
                    meas = meas_old + alpha * (nominal - meas_old)
                    st[MEAS0 + wh] = meas
                    sp = st[SP0 + wh]
                    err = sp - meas
                    vraw = (p[P_KFF] * sp + p[P_KP] * err + st[INT0 + wh]
                            - p[P_KD] * (meas - meas_old) / dt)
                    vsat = min(p[P_VSUP], max(-p[P_VSUP], vraw))
                    if vsat == vraw or err * vraw < 0.0:   # conditional integration
                        integ = st[INT0 + wh] + p[P_KI] * err * dt
                        st[INT0 + wh] = min(p[P_VSUP], max(-p[P_VSUP], integ))
                    if wh == 0:
                        volt0 = vsat
                    else:
                        volt1 = vsat
                for _ in range(N_MECH):
                    f_body = 0.0
                    torque = 0.0
                    for wh in range(2):
                        u = st[U0 + wh]
                        stalled = pp[PP_STALL0 + wh] > 0.5
                        if stalled:
                            st[U0 + wh] = 0.0
                            u = 0.0
                        kmot = p[P_K] * pp[PP_GAIN0 + wh] * (1.0 if wh == 0 else p[P_BAL])
                        volt = volt0 if wh == 0 else volt1
                        cur = min(p[P_ILIM], max(-p[P_ILIM], (volt - kmot * u) / p[P_R]))
                        out_current[i, k, wh] += cur * h / period
                        if abs(cur) >= p[P_ILIM] * (1.0 - 1e-9):
                            st[LIMIT0 + wh] += h
                        else:
                            st[LIMIT0 + wh] = 0.0
                        f_gear = p[P_BG] * u + p[P_FC] * math.tanh(u / 0.005)
                        side = -1.0 if wh == 0 else 1.0
                        contact = st[V] + side * half_b * st[W]
                        # traction from the slip ratio, regularised at low speed
                        slip = keep * u - contact
                        vref = max(abs(keep * u), abs(contact), V_SLIP_REF)
                        th = math.tanh(slip / (fl[F_KAPPA] * vref))
                        f_trac = trac_max * th
                        stiff = trac_max * (1.0 - th * th) / (fl[F_KAPPA] * vref)
                        f_rough = fl[F_ROUGH] * nz[NZ_ROUGH0 + wh]
                        if not stalled:
                            # implicit in the wheel's own slip: stable for stiff contacts
                            du = (h * (kmot * cur - f_gear - keep * f_trac + f_rough)
                                  / (p[P_MW] + h * keep * keep * stiff))
                            st[U0 + wh] = u + du
                            f_trac += stiff * keep * du
                        # rolling resistance where this wheel meets the floor
                        f_roll = roll_wheel * math.tanh(contact / 0.01)
                        f_body += f_trac - f_roll
                        torque += side * half_b * (f_trac - f_roll)
                        # encoder: rotation counted in the commanded direction
                        direction = -1.0 if st[SP0 + wh] < 0.0 else 1.0
                        diam = (1.0 + p[P_DERR0 + wh]) * pp[PP_DIAM0 + wh]
                        dtick = abs(st[U0 + wh]) * h / (circ * diam) * p[P_TPR] * direction
                        st[TICK0 + wh] += dtick
                        if pp[PP_STUCK0 + wh] > 0.5:
                            st[OFF0 + wh] += dtick
                    # front caster: rolling resistance against its contact velocity
                    cy = st[W] * p[P_CASTER]
                    cspeed = max(math.sqrt(st[V] * st[V] + cy * cy), 0.01)
                    f_body -= roll_caster * st[V] / cspeed
                    torque -= p[P_CASTER] * roll_caster * cy / cspeed
                    torque -= t_scrub * math.tanh(st[W] / 0.05)
                    st[V] += h * f_body / mass
                    st[W] += h * torque / inertia
                    # exact arc for constant (v, w) over the sub-step (paper eq. 11)
                    phi = st[W] * h
                    chord = st[V] * h * _sinc_half(phi)
                    mid = st[TH] + 0.5 * phi
                    st[X] += chord * math.cos(mid)
                    st[Y] += chord * math.sin(mid)
                    st[TH] += phi
                _contacts(st, p, walls, out_bumps[i, k])
            qinfo[i, 0], qinfo[i, 1] = head, count
            st[T_NOW] = t_k + period
            for wh in range(2):
                raw = math.floor(st[TICK0 + wh] - st[OFF0 + wh])
                out_ticks[i, k, wh] = int(raw)      # the caller wraps (counter_bits)
                out_overcurrent[i, k, wh] = st[LIMIT0 + wh] >= OVERCURRENT_S - 1e-9
            _light_bumps(st, p, walls, nz, out_light[i, k])
            out_pose[i, k, 0] = st[X]
            out_pose[i, k, 1] = st[Y]
            out_pose[i, k, 2] = st[TH]
            out_body[i, k, 0] = st[V]
            out_body[i, k, 1] = st[W]


def empty_outputs(n_robots: int, n_periods: int) -> tuple[np.ndarray, ...]:
    """Output buffers for :func:`run_periods`."""
    return (
        np.zeros((n_robots, n_periods, 2), np.int64),
        np.zeros((n_robots, n_periods, 6), np.int64),
        np.zeros((n_robots, n_periods, 2), np.bool_),
        np.zeros((n_robots, n_periods, 3)),
        np.zeros((n_robots, n_periods, 2)),
        np.zeros((n_robots, n_periods, 2)),
        np.zeros((n_robots, n_periods, 2), np.bool_),
    )
