"""Frozen pre-split reference of the physics kernel (benchmark and test reference only).

A verbatim copy of ``valve_gym.core._kernel`` as it was before the kernel was split into one
small inlined helper per block (git commit f103afd). It is never used by valve_gym itself: the
speed benchmark ``benchmarks/bench_kernel.py`` times it side by side with the current kernel, and
``tests/test_core.py`` checks that the current kernel gives bit-for-bit the same results for the
blocks this reference knows (Riihilahti valve, slip-jump, characteristic, dead time, processes,
overflow, leak, sensor lag, oscillating disturbance). Do not edit.
"""
import numpy as np
from numba import njit

# parameter rows and flag slots of the pre-split layout (rows 0..22 are unchanged in the current core)
TAU, VMAX, EDEAD, ZMAX, SJ_S, SJ_J, SJ_TAU, CH_R, CH_H0, P_A, P_Q, P_OUT, A2, K2, \
    LMAX, L2MAX, SPILL, QLEAK, DELAY, TAU_S, DIST_A, DIST_P, DIST_PHI = range(23)
NP = 23
F_FRIC, F_CHAR, F_ACT, F_PROC, F_DEAD, F_OVER, F_LEAK, F_SENS, F_DIST = range(9)
NF = 9
S_Z, S_H, S_X, S_US, S_STUCK, S_SDIR, S_UPREV, S_L1, S_L2, S_Y, S_T, S_BIDX = range(12)
NS = 12


@njit(nogil=True)  # not cached: loaded from a path by tests and benchmarks
def reference_kernel(S, P, U, D, flags, buf, n_sub, dt, Y, H, LV):  # noqa: C901  # pragma: no cover
    T = U.shape[0]
    n = S.shape[1]
    pb = P.shape[1] > 1
    ub = U.shape[1] > 1
    db = D.shape[1] > 1
    fric = flags[F_FRIC]
    char = flags[F_CHAR]
    act = flags[F_ACT]
    proc = flags[F_PROC]
    dead = flags[F_DEAD]
    over = flags[F_OVER]
    leak = flags[F_LEAK]
    sens = flags[F_SENS]
    dist = flags[F_DIST]
    B = buf.shape[1]
    for i in range(n):
        j = i if pb else 0
        tau = P[TAU, j]
        vmax = P[VMAX, j]
        ed = P[EDEAD, j]
        zmax = P[ZMAX, j]
        sjS = P[SJ_S, j]
        sjJ = P[SJ_J, j]
        taup = P[SJ_TAU, j]
        R = P[CH_R, j]
        h0 = P[CH_H0, j]
        pa = P[P_A, j]
        pq = P[P_Q, j]
        pout = P[P_OUT, j]
        a2 = P[A2, j]
        k2 = P[K2, j]
        lmax = P[LMAX, j]
        l2max = P[L2MAX, j]
        spill_f = P[SPILL, j]
        qleak = P[QLEAK, j] if leak == 1 else 0.0
        kdel = int(P[DELAY, j])
        taus = P[TAU_S, j]
        da = P[DIST_A, j]
        dw = 2.0 * np.pi / P[DIST_P, j]
        dphi = P[DIST_PHI, j]
        z = S[S_Z, i]
        h = S[S_H, i]
        x = S[S_X, i]
        us = S[S_US, i]
        stuck = S[S_STUCK, i]
        sdir = S[S_SDIR, i]
        uprev = S[S_UPREV, i]
        L1 = S[S_L1, i]
        L2 = S[S_L2, i]
        y = S[S_Y, i]
        t = S[S_T, i]
        bidx = int(S[S_BIDX, i])
        for k in range(T):
            u = U[k, i if ub else 0]
            if u < 0.0:
                u = 0.0
            elif u > 1.0:
                u = 1.0
            dk = D[k, i if db else 0]
            if act == 0 and fric == 1:
                # Choudhury slip-jump block, once per controller sample
                du = u - uprev
                dsg = 0.0
                if du > 0.0:
                    dsg = 1.0
                elif du < 0.0:
                    dsg = -1.0
                if dsg == 0.0:
                    if stuck == 0.0:
                        stuck = 1.0
                        us = uprev
                else:
                    # sdir: direction of the last *motion* of the valve, kept
                    # while it is stuck, so a reversal is remembered until it slips
                    reversed_ = (sdir != 0.0) and (dsg != sdir)
                    if stuck == 0.0 and reversed_:
                        stuck = 1.0
                        us = uprev
                    if stuck == 1.0:
                        thr = sjS if reversed_ else sjJ
                        if abs(u - us) > thr:
                            stuck = 0.0
                            x = u - dsg * (sjS - sjJ) / 2.0
                            sdir = dsg
                    else:
                        x = u - dsg * (sjS - sjJ) / 2.0
                        sdir = dsg
                if x < 0.0:
                    x = 0.0
                elif x > 1.0:
                    x = 1.0
            uprev = u
            for s in range(n_sub):
                # ---- actuator
                if act == 1:
                    hc = u
                    f = u
                else:
                    if fric == 0:
                        e = u - h
                        if e > ed:
                            e = e - ed
                        elif e < -ed:
                            e = e + ed
                        else:
                            e = 0.0
                        # z is held at the edge of its band while outside it
                        # (continuous-time dz/dt = 0 there): the stem slips while z
                        # is at an edge and e pushes outwards, else it is stuck.
                        v = 0.0
                        if (z >= zmax and e > 0.0) or (z <= -zmax and e < 0.0):
                            v = abs(e) / tau
                            if v > vmax:
                                v = vmax
                            if e < 0.0:
                                v = -v
                        else:
                            z += dt * e
                            if z > zmax:
                                z = zmax
                            elif z < -zmax:
                                z = -zmax
                        h += dt * v
                    else:
                        h += dt * (x - h) / taup
                    hc = h
                    if hc < 0.0:
                        hc = 0.0
                    elif hc > 1.0:
                        hc = 1.0
                    # ---- installed characteristic
                    if char == 0 and h0 == 0.0:
                        f = hc
                    else:
                        if hc <= h0:
                            f = 0.0
                        else:
                            r = (hc - h0) / (1.0 - h0)
                            if char == 0:
                                f = r
                            elif char == 1:
                                f = R ** (r - 1.0)
                            else:
                                f = np.sqrt(r)
                # ---- dead time
                if dead == 1:
                    buf[i, bidx] = f
                    f = buf[i, (bidx - kdel) % B]
                    bidx = (bidx + 1) % B
                qin = f * pq + dk
                if dist == 1:
                    qin += da * np.sin(dw * t + dphi)
                # ---- process
                if proc == 0 or proc == 3:
                    q1 = pout * np.sqrt(L1) if L1 > 0.0 else 0.0
                    if proc == 0:
                        L1 = L1 + dt * (qin - q1 - qleak) / pa
                    else:
                        L1 = L1 + dt * (qin - q1) / pa
                    if L1 < 0.0:
                        L1 = 0.0
                    spill = 0.0
                    if over == 1 and L1 > lmax:
                        spill = (L1 - lmax) * pa / dt
                        L1 = lmax
                    if proc == 3:
                        q2 = k2 * np.sqrt(L2) if L2 > 0.0 else 0.0
                        L2 = L2 + dt * (q1 + spill_f * spill - q2 - qleak) / a2
                        if L2 < 0.0:
                            L2 = 0.0
                        if over == 1 and L2 > l2max:
                            L2 = l2max
                        lm = L2
                    else:
                        lm = L1
                elif proc == 1:
                    L1 = L1 + dt * (qin - pout - qleak) / pa
                    if over == 1 and L1 > lmax:
                        L1 = lmax
                    lm = L1
                else:
                    L1 = L1 + dt * (qin + pout - qleak - L1) / pa
                    if over == 1 and L1 > lmax:
                        L1 = lmax
                    lm = L1
                # ---- sensor
                if sens == 1:
                    y = y + dt * (lm - y) / taus
                else:
                    y = lm
                t += dt
            Y[k, i] = y
            H[k, i] = hc if act == 0 else u
            LV[k, i] = lm
        S[S_Z, i] = z
        S[S_H, i] = h
        S[S_X, i] = x
        S[S_US, i] = us
        S[S_STUCK, i] = stuck
        S[S_SDIR, i] = sdir
        S[S_UPREV, i] = uprev
        S[S_L1, i] = L1
        S[S_L2, i] = L2
        S[S_Y, i] = y
        S[S_T, i] = t
        S[S_BIDX, i] = bidx
