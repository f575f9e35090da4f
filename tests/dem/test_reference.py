"""The compiled kernel against an independent, slow plain-numpy implementation.

The reference below is written from the contact law and integration scheme stated in
`kernel.py`'s docstring and in design.md, not from the kernel's data structures: all
pairs, minimum image over the 27 images of the *unwrapped* fractional positions (no
neighbour list), tangential history keyed by pair, everything vectorised over contacts.
Agreement therefore also shows that the Verlet lists never missed a contact.
"""

from __future__ import annotations

import itertools

import numpy as np
from dem_helpers import agitated_dense_state

from grainscale.dem import engine

IMAGES = np.array(list(itertools.product((-1, 0, 1), repeat=3)), float)  # (27, 3)


def reference_history(b):
    """{(i, j): ft} from the kernel's lists (only contacts carry a nonzero history)."""
    hist = {}
    for i in range(b.n_particles):
        for k in range(b.nbr_count[0, i]):
            f = b.ft[0, i, k]
            if np.any(f != 0.0):
                hist[(i, int(b.nbr_j[0, i, k]))] = f.copy()
    return hist


def reference_step(st, p, dt, lc):
    """One step of the documented scheme; st: dict of h, s, v, w, rot, radius, mass,
    inertia, ft (dict). Returns forces, torques and stress of the step and its number
    of contacts. With dt = 0 nothing moves and no history is added: the forces and
    stress of the state as it is, the history projected onto the contact planes."""
    h, s, v, w = st["h"], st["s"], st["v"], st["w"]
    r = st["radius"]
    n = len(r)
    hdot = lc @ h
    L = hdot @ np.linalg.inv(h)
    iu, ju = np.triu_indices(n, 1)
    ds = s[ju] - s[iu]
    base = -np.round(ds)
    cand = (ds + base)[:, None, :] + IMAGES[None, :, :]         # (P, 27, 3)
    dc = cand @ h.T
    dist2 = np.einsum("pkd,pkd->pk", dc, dc)
    best = np.argmin(dist2, axis=1)
    d = dc[np.arange(len(iu)), best]
    dist = np.sqrt(dist2[np.arange(len(iu)), best])
    touch = dist < r[iu] + r[ju]
    # history of pairs that are not touching is forgotten
    for a, c in zip(iu[~touch], ju[~touch], strict=True):
        st["ft"].pop((int(a), int(c)), None)
    i, j, d, dist = iu[touch], ju[touch], d[touch], dist[touch]
    ri, rj = r[i], r[j]
    nrm = d / dist[:, None]
    kn = p.young * 2 * ri * rj / (ri + rj)
    # lever arms to the contact point in the middle of the overlap (li + lj = |d|)
    li = ri - 0.5 * (ri + rj - dist)
    lj = rj - 0.5 * (ri + rj - dist)
    wa = li[:, None] * w[i] + lj[:, None] * w[j]
    # the mean field carries a pair rigidly with its spin W = skew L: only D = sym L
    # moves j relative to i; particle spins w are fluctuations about W
    D = 0.5 * (L + L.T)
    vr = v[j] - v[i] + d @ D.T - np.cross(wa, nrm)
    vn = np.einsum("cd,cd->c", vr, nrm)
    # linear spring and the normal dashpot of the restitution (p.gamma: 0 if elastic)
    mst = st["mass"][i] * st["mass"][j] / (st["mass"][i] + st["mass"][j])
    fn = kn * (ri + rj - dist) - 2 * p.gamma * np.sqrt(mst * kn) * vn
    f_old = np.array([st["ft"].get((int(a), int(c)), np.zeros(3)) for a, c in zip(i, j,
                                                                                  strict=True)])
    f_old = f_old.reshape(-1, 3)
    spin = 0.5 * np.array([L[2, 1] - L[1, 2], L[0, 2] - L[2, 0], L[1, 0] - L[0, 1]])
    twist = 0.5 * np.einsum("cd,cd->c", w[i] + w[j], nrm)
    omega = (spin[None, :] + twist[:, None] * nrm) * dt
    g = f_old + np.cross(omega, f_old)
    g -= np.einsum("cd,cd->c", g, nrm)[:, None] * nrm
    g += (p.stiffness_ratio * kn)[:, None] * (vr - vn[:, None] * nrm) * dt
    cap = p.friction * np.maximum(fn, 0.0)
    mag = np.linalg.norm(g, axis=1)
    over = mag > cap
    g[over] *= (cap[over] / mag[over])[:, None]
    st["capped"] = st.get("capped", 0) + int(over.sum())
    for a, c, f in zip(i, j, g, strict=True):
        st["ft"][(int(a), int(c))] = f.copy()
    fc = g - fn[:, None] * nrm                     # force on i
    force = np.zeros((n, 3))
    torque = np.zeros((n, 3))
    np.add.at(force, i, fc)
    np.add.at(force, j, -fc)
    tq = np.cross(nrm, g)
    np.add.at(torque, i, li[:, None] * tq)
    np.add.at(torque, j, lj[:, None] * tq)
    # Love-Weber plus the kinetic stress of the (pre-update) fluctuating velocities
    kinetic = np.einsum("p,pa,pb->ab", st["mass"], v, v)
    stress = (np.einsum("ca,cb->ab", d, fc) - kinetic) / np.linalg.det(h)
    # integration with the new cell
    h_new = h + dt * hdot
    alpha = p.damping
    # the pseudo-force -m L v' of the co-moving frame, from the pre-update velocities
    v += dt / st["mass"][:, None] * (force - alpha * np.abs(force) * np.sign(v)) \
        - dt * v @ L.T
    w += dt / st["inertia"][:, None] * (torque - alpha * np.abs(torque) * np.sign(w))
    s += (v * dt) @ np.linalg.inv(h_new).T
    st["rot"] += np.linalg.norm(w, axis=1) * dt
    st["h"] = h_new
    return force, torque, stress, len(i)


def test_kernel_matches_numpy_reference():
    """60 steps (one `advance` call) of a dense, agitated 48-sphere RVE with damping,
    friction (some contacts sliding), and a deforming, shearing, spinning cell.

    Tolerance 1e-10 relative to each quantity's scale: the two implementations differ
    only in summation order and fastmath contraction (ulp-level per step), amplified by
    the contact dynamics over 60 steps; measured ~3e-13. A wrong sign, factor or
    update order (e.g. the old instead of the new cell in s += h^-1 v dt, or velocities
    from after instead of before the force) shows at 1e-4 or more.
    """
    b, p, dt = agitated_dense_state(damping=0.0, friction=0.4)
    p = engine.ContactParams(young=p.young, stiffness_ratio=p.stiffness_ratio,
                             friction=p.friction, damping=0.15, skin=p.skin)
    lc = np.array([[-30.0, 8.0, 0.0], [-4.0, 20.0, 5.0], [3.0, 0.0, -10.0]])
    st = {"h": b.h[0].copy(), "s": b.s[0].copy(), "v": b.v[0].copy(), "w": b.w[0].copy(),
          "rot": b.rot[0].copy(), "radius": b.radius[0], "mass": b.mass[0],
          "inertia": b.inertia[0], "ft": reference_history(b)}
    nsteps = 60
    for _ in range(nsteps):
        reference_step(st, p, dt, lc)
    # the kernel's forces and stress are those of the state the steps reached: a step of
    # length 0 evaluates them (moving nothing) with the history projected, not stored
    history = {k: f.copy() for k, f in st["ft"].items()}
    force, torque, stress, nc = reference_step(st, p, 0.0, lc)
    st["ft"] = history
    engine.advance(b, nsteps, dt, p, engine.rate_control(1, l_ctrl=lc, max_rate=100.0))
    assert nc == b.ncontact[0] and nc > 10

    def close(a, ref, what, tol=1e-10):
        err = np.abs(a - ref).max() / np.abs(ref).max()
        assert err < tol, f"{what}: relative difference {err:.3g}"

    close(b.h[0], st["h"], "h", 1e-14)
    ds = b.s[0] - st["s"]  # the kernel wraps s at list builds: compare modulo 1
    ds -= np.round(ds)
    assert np.abs(ds @ b.h[0].T).max() < 1e-10 * b.radius.min()
    close(b.v[0], st["v"], "v")
    close(b.w[0], st["w"], "w")
    close(b.rot[0], st["rot"], "rot")
    close(b.force[0], force, "force")
    close(b.torque[0], torque, "torque")
    close(b.stress[0], stress, "stress")
    # tangential histories, pair by pair
    kern = reference_history(b)
    assert set(kern) == set(st["ft"]) - {k for k, f in st["ft"].items() if not f.any()}
    fscale = max(np.linalg.norm(f) for f in st["ft"].values())
    for key, f in kern.items():
        assert np.abs(f - st["ft"][key]).max() < 1e-10 * fscale, key
    # the run exercised what it claims to: the Coulomb cap was active on some contacts
    assert st["capped"] > 10
