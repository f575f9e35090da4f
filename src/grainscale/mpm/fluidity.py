"""The granular fluidity's equation, solved on the grid (the point side, the stress
relaxation, is materials/fluidity.py, which states the model):

    t_0 dg/dt = A^2 d^2 lap(g) + (mu - mu_s) g - c(mu, p) g^2.

Each step, before the stress update, with the step's shape functions:
1. nodal fields, volume-weighted: V_I = sum_p S_Ip V_p, g_I = sum_p S_Ip V_p g_p / V_I;
   mu_I and sqrt(p/rho_s)_I over the loaded points only (a separated point, p = 0, has
   no stress ratio; nodes that hold none keep their g but for diffusion);
2. the Laplacian in weak form with lumped volume, lap_I = -sum_p V_p grad S_Ip . grad g_p
   / V_I, grad g_p = sum_J g_J grad S_Jp: the Galerkin form, whose boundary term vanishes,
   so free surfaces and walls are zero-flux (natural); g_I = 0 on no-slip (`fixed`)
   nodes, the rough base of Kamrin & Henann 2015;
3. g_I advances: the diffusion explicitly (stable for dt <= t_0 h^2 / (6 A^2 d^2), which
   the material's `max_dt` adds to the CFL limit), the seed where mu_I > mu_s, then the
   local terms exactly (`logistic`);
4. the points take the nodal change, FLIP-like: g_p <- max(0, g_p + sum_I S_Ip dg_I).
   Solving on the grid, not at the points, matters: a point field whose variation inside
   a cell the grid cannot see (the null space of the P2G average) would feel no
   diffusion and grow unchecked wherever mu > mu_s; here such a variation is carried but
   never amplified.

The nodal sums go through the deterministic fixed-point transfers of transfer.py, so
the result is the same on any number of threads or ranks.
"""

from __future__ import annotations

import numpy as np

from grainscale.mpm.materials.fluidity import SEED
from grainscale.mpm.transfer import gradient_kernel, interpolate_kernel

MU_CAP = 0.999  # nodal mu at most mu_s + 0.999 (mu_2 - mu_s): I = 999 I_0 at steady state


def logistic(g: np.ndarray, r: np.ndarray, c: np.ndarray, dt: float) -> np.ndarray:
    """g after dt of dg/dt = r g - c g^2 (r of any sign, c > 0, g >= 0), exactly:
    g E / (1 + c g (E - 1) / r), E = exp(r dt) ((E - 1)/r -> dt as r -> 0); for r > 0
    divided through by E, so that a large r dt cannot overflow."""
    x = r * dt
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        grow = x > 0.0
        em1 = np.expm1(np.where(grow, -x, x))  # E - 1, or 1/E - 1 where r > 0
        f = np.where(np.abs(x) > 1e-12, np.where(grow, -em1, em1) / r, dt)  # (E-1)/r or (1-1/E)/r
        return np.where(grow, g / (1.0 + em1 + c * g * f), g * (1.0 + em1) / (1.0 + c * g * f))


def _scratch(s):
    P = s.points.n
    if getattr(s, "_fluidity_scratch", None) is None or s._fluidity_scratch[0].shape[0] != P:
        s._fluidity_scratch = (np.zeros((P, 3)), np.zeros((P, 3, 3)), np.zeros((P, 3, 3)),
                               np.zeros(P))
    return s._fluidity_scratch


def advance_fluidity(s, mat, ids, dt: float) -> None:
    """One step of the fluidity of the nonlocal material `mat` (points `ids`, None for
    all) of MPMState s, after its P2G; g = 0 on the nodes of active `fixed` constraints."""
    pts = s.points
    vec, C0, grad, dg_p = _scratch(s)
    sel = slice(None) if ids is None else ids
    # stress ratio and pressure at the step's start, of the loaded points of the material
    sig = pts.stress[sel]
    p = -np.trace(sig, axis1=1, axis2=2) / 3.0
    dev = sig + p[:, None, None] * np.eye(3)
    loaded = p > 0.0
    mu = np.where(loaded, np.sqrt(0.5 * np.einsum("pij,pij->p", dev, dev))
                  / np.where(loaded, p, 1.0), 0.0)
    root_p = np.sqrt(np.maximum(p, 0.0) / mat.rho_s)  # m/s
    args = (pts.x, s.grid, s.base, s.w, s.ns)
    # 1. nodal g, volume-weighted (other materials' points count as g = 0)
    vec[:] = 0.0
    vec[sel, 0] = mat.fluidity
    V, gV, ok = s.transfer.mass_momentum(pts.vol, vec, C0, *args)
    if not ok:
        raise FloatingPointError("non-finite granular fluidity")
    a = s.active & (V > 0.0)
    g = np.zeros(len(V))
    g[a] = gV[a, 0] / V[a]
    held = [c.nodes for c in s.constraints if c.active(s.time) and c.mask.all()]
    for nodes in held:
        g[nodes] = 0.0
    # mu and sqrt(p/rho_s) over the loaded points
    w_load = np.zeros(pts.n)
    w_load[sel] = np.where(loaded, pts.vol[sel], 0.0)
    vec[:] = 0.0
    vec[sel, 0] = mu
    vec[sel, 1] = root_p
    W, muW, _ = s.transfer.mass_momentum(w_load, vec, C0, *args)
    # 2. weak Laplacian: the internal-force transfer with the 'stress' row 0 = grad g
    field = np.zeros((len(V), 3))
    field[:, 0] = g
    gradient_kernel(field, s.base, s.w, s.dw, s.grid.nodes, s.ns, grad)  # rows 1, 2: 0
    zero3 = np.zeros(3)
    f, ok = s.transfer.force(pts.m, pts.vol, grad, np.zeros((pts.n, 3)), zero3,
                             s.grid.cell_size, s.base, s.w, s.dw, s.grid.nodes, s.ns)
    if not ok:
        raise FloatingPointError("non-finite fluidity gradient")
    lap = np.zeros(len(V))
    lap[a] = f[a, 0] / V[a]
    # 3. the nodal update
    new = g.copy()
    new[a] = np.maximum(0.0, g[a] + dt * (mat.A * mat.d) ** 2 / mat.t_0 * lap[a])
    ld = a & (W > 0.0)
    # beyond mu_2 no rate balances the stress (c = 0): g then grows to where it relaxes
    # the stress back within a step; the cap keeps the local steady state finite
    mu_I = np.minimum(muW[ld, 0] / W[ld], MU_CAP * mat.mu_2 + (1.0 - MU_CAP) * mat.mu_s)
    rp_I = muW[ld, 1] / W[ld]
    gl = new[ld]
    gl = np.where(mu_I > mat.mu_s, np.maximum(gl, SEED * rp_I / mat.d), gl)
    with np.errstate(divide="ignore"):
        c = mu_I * (mat.mu_2 - mu_I) * mat.d / (np.maximum(rp_I, 1e-300) * mat.I_0)
    new[ld] = logistic(gl, (mu_I - mat.mu_s) / mat.t_0, c / mat.t_0, dt)
    for nodes in held:  # after the seed, which would otherwise lift them off zero
        new[nodes] = 0.0
    # 4. the points take the nodal change
    interpolate_kernel(new - g, s.base, s.w, s.grid.nodes, s.ns, dg_p)
    mat.fluidity[:] = np.maximum(0.0, mat.fluidity + dg_p[sel])
