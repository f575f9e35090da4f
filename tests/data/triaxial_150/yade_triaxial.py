"""Drained triaxial test of a stored packing in YADE, set up as grainscale's
element_tests.triaxial; writes the reference curves of tests/dem/test_triaxial.py.

    yade -n -x yade_triaxial.py PACKING OUT [SEED [AXIAL [RATE [ALPHA_R ETA_R]]]] [hertz=E,NU]

SEED >= 0 perturbs the grain velocities by ~1e-9 m/s (another realisation of the same
RVE); -1 (default) starts at rest. Same grains and contact law (FrictMat: kn = 2 E r1 r2 /
(r1 + r2), ks/kn = poisson = 0.8, mu = tan(frictionAngle) = 0.5, E = 100 MPa, density
2650), Cundall local damping 0.2, dt = 0.3 sqrt(m_min/(E r_max)); the axial (z) edge
shortened at a constant engineering rate RATE (default 0.1 /s: L_zz = -rate/(1 - rate t));
lateral stresses held at -100 kPa by grainscale's proportional servo, sampled every 4
steps: L_kk = gain (sigma* - sigma_kk)/(C_kk dt), C_kk = (1/V) sum kn |d|^2 n_k^4 (updated
every 40 steps), gain 0.05, clipped to 10 x rate. A row every 0.002 axial strain to AXIAL
(default 0.15): axial strain, q/p, eps_v = ln(V/V0), sigma_xx, yy, zz (compression
positive), p, q; the first row (before any step, no contacts yet) is all zero.

ALPHA_R > 0 adds rolling resistance as grainscale's `[rve] rolling_stiffness` and
`rolling_friction` define it: CohFrictMat without cohesion (alphaKr = ALPHA_R, etaRoll =
ETA_R, no twisting stiffness) and Law2_ScGeom6D_CohFrictPhys_CohesionMoment with
useIncrementalForm and always_use_moment_law, so k_r = ALPHA_R ks r1 r2 and |M| <=
ETA_R min(r1, r2) |f_n|; the time step is then divided by sqrt(1 + ALPHA_R r_max / r_min)
as grainscale's engine.critical_dt does.

hertz=E,NU (anywhere among the arguments) takes grainscale's `contact_law =
"hertz_mindlin"` instead: FrictMat(young=E, poisson=NU), Ip2_FrictMat_FrictMat_MindlinPhys
without restitution (no dashpot) and Law2_ScGeom_MindlinPhys_Mindlin, so f_n = (4/3) E*
sqrt(R*) delta^(3/2) and k_s = 8 G* a (E* = E/(2 (1 - NU^2)), G* = E/(4 (1 + NU)(2 - NU)));
dt = 0.3 sqrt(m_min / (E* r_max sqrt(0.01))) (engine.critical_dt at the default
rve.numerics.max_overlap); the servo's C_kk reads each contact's tangent kn, as the
linear law's reads its kn.

A packing of clumps (a fifth column, the clump of each member: io/packing.py) is built
with O.bodies.appendClumped, one clump per id; YADE integrates each clump's union of
spheres on a grid (discretization=DISCRETIZATION cells along the smallest member
diameter) for its mass and inertia, independently of grainscale's voxels. Contacts
inside a clump are not made (YADE's rule). utils.getStress() sums the Love-Weber branch
between the clumps' positions (their centres of mass), as grainscale's clump kernel
does: on tests/data/triaxial_clumps/tetrahedral.txt after one step it gives sigma_xx =
-95168 Pa where grainscale's refreshed packing has -95175 Pa and the sum between member
centres would be -63012 Pa. The servo's C_kk = (1/V) sum kn (b_k n_k)^2 takes that
branch b too. dt = 0.3 sqrt(m/(E r_max)) with m the least over clumps of min(M,
J_min/l^2), l a clump's largest reach from its centre (engine.critical_dt for clumps).
"""
import math
import sys

import numpy as np
from yade import O, utils
from yade.minieigenHP import Matrix3, Vector3
from yade.wrapper import (
    Bo1_Sphere_Aabb,
    CohFrictMat,
    ForceResetter,
    FrictMat,
    Ig2_Sphere_Sphere_ScGeom,
    Ig2_Sphere_Sphere_ScGeom6D,
    InsertionSortCollider,
    InteractionLoop,
    Ip2_CohFrictMat_CohFrictMat_CohFrictPhys,
    Ip2_FrictMat_FrictMat_FrictPhys,
    Ip2_FrictMat_FrictMat_MindlinPhys,
    Law2_ScGeom6D_CohFrictPhys_CohesionMoment,
    Law2_ScGeom_FrictPhys_CundallStrack,
    Law2_ScGeom_MindlinPhys_Mindlin,
    NewtonIntegrator,
    PyRunner,
)

HERTZ = [a for a in sys.argv[1:] if a.startswith("hertz=")]
sys.argv = [a for a in sys.argv if not a.startswith("hertz=")]
packing, out = sys.argv[1], sys.argv[2]
seed = int(sys.argv[3]) if len(sys.argv) > 3 else -1
E, RATIO, MU, RHO, DAMP = 100e6, 0.8, 0.5, 2650.0, 0.2
RATE = float(sys.argv[5]) if len(sys.argv) > 5 else 0.1
CONF, GAIN, EVERY, MAX_RATE = 100e3, 0.05, 4, 10 * RATE
AXIAL = float(sys.argv[4]) if len(sys.argv) > 4 else 0.15
ALPHA_R = float(sys.argv[6]) if len(sys.argv) > 6 else 0.0
ETA_R = float(sys.argv[7]) if len(sys.argv) > 7 else 0.0
INTERVAL = 0.002

DISCRETIZATION = 20
lines = [ln for ln in open(packing) if not ln.startswith("#")]
h = np.array([float(v) for v in lines[0].split()]).reshape(3, 3)
data = np.array([[float(v) for v in ln.split()] for ln in lines[1:] if ln.strip()])
CLUMPS = data.shape[1] == 5
O.periodic = True
O.cell.hSize = Matrix3(*h.ravel())
if HERTZ:
    E, NU = (float(v) for v in HERTZ[0].split("=")[1].split(","))
    mat = O.materials.append(FrictMat(young=E, poisson=NU, frictionAngle=math.atan(MU),
                                      density=RHO))
elif ALPHA_R > 0.0:
    mat = O.materials.append(CohFrictMat(
        young=E, poisson=RATIO, frictionAngle=math.atan(MU), density=RHO,
        isCohesive=False, momentRotationLaw=True, alphaKr=ALPHA_R, etaRoll=ETA_R,
        alphaKtw=0.0, etaTwist=-1.0))
else:
    mat = O.materials.append(FrictMat(young=E, poisson=RATIO, frictionAngle=math.atan(MU),
                                      density=RHO))
rng = np.random.default_rng(seed) if seed >= 0 else None
clump_of = {}  # member id -> clump id (YADE's)
if CLUMPS:
    m_min = np.inf
    for k in np.unique(data[:, 4]):
        rows = data[data[:, 4] == k]
        cid, ids = O.bodies.appendClumped(
            [utils.sphere(Vector3(x, y, z), r, material=mat) for x, y, z, r, _ in rows],
            discretization=DISCRETIZATION)
        for i in ids:
            clump_of[i] = cid
        st = O.bodies[cid].state
        reach = max(np.linalg.norm(np.array(O.bodies[i].state.pos - st.pos))
                    + O.bodies[i].shape.radius for i in ids)
        m_min = min(m_min, st.mass, min(st.inertia) / reach**2)
        if rng is not None:
            st.vel = Vector3(*rng.normal(0.0, 1e-9, 3))
else:
    for x, y, z, r in data:
        b = utils.sphere(Vector3(x, y, z), r, material=mat)
        O.bodies.append(b)
        if rng is not None:  # a different realisation: grain velocities differ by ~1e-9 m/s
            b.state.vel = Vector3(*rng.normal(0.0, 1e-9, 3))
    m_min = RHO * 4.0 / 3.0 * math.pi * data[:, 3].min() ** 3
O.dt = 0.3 * math.sqrt(m_min / (E * data[:, 3].max()))
if HERTZ:
    E_STAR = E / (2.0 * (1.0 - NU * NU))
    O.dt = 0.3 * math.sqrt(m_min / (E_STAR * data[:, 3].max() * math.sqrt(0.01)))
    loop = InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [Ip2_FrictMat_FrictMat_MindlinPhys()],
                           [Law2_ScGeom_MindlinPhys_Mindlin()])
elif ALPHA_R > 0.0:
    O.dt /= math.sqrt(1.0 + ALPHA_R * data[:, 3].max() / data[:, 3].min())
    loop = InteractionLoop(
        [Ig2_Sphere_Sphere_ScGeom6D()], [Ip2_CohFrictMat_CohFrictMat_CohFrictPhys()],
        [Law2_ScGeom6D_CohFrictPhys_CohesionMoment(useIncrementalForm=True,
                                                   always_use_moment_law=True)])
else:
    loop = InteractionLoop([Ig2_Sphere_Sphere_ScGeom()], [Ip2_FrictMat_FrictMat_FrictPhys()],
                           [Law2_ScGeom_FrictPhys_CundallStrack()])
O.engines = [
    ForceResetter(),
    InsertionSortCollider([Bo1_Sphere_Aabb()]),
    loop,
    NewtonIntegrator(damping=DAMP),
]
l0 = h[2, 2]
V0 = abs(np.linalg.det(h))


def stiffness():
    """C_kk of the servo (module docstring)."""
    V = O.cell.volume
    c = np.zeros(3)
    for i in O.interactions:
        if not i.isReal:
            continue
        n = np.array(i.geom.normal)
        d = (i.geom.refR1 + i.geom.refR2 - i.geom.penetrationDepth)
        if not CLUMPS:
            c += i.phys.kn * d * d * n**4
            continue
        ri = np.array(O.bodies[i.id1].state.pos - O.bodies[clump_of[i.id1]].state.pos)
        rj = np.array(O.bodies[i.id2].state.pos - O.bodies[clump_of[i.id2]].state.pos)
        b = d * n - rj + ri
        c += i.phys.kn * (b * n) ** 2
    return c / V


def row():
    s = np.array(utils.getStress())
    p = -np.trace(s) / 3.0
    dev = s + p * np.eye(3)
    q = math.sqrt(1.5 * np.sum(dev * dev))
    hs = np.array(O.cell.hSize)
    return [(l0 - hs[2, 2]) / l0, q / p, math.log(abs(np.linalg.det(hs)) / V0),
            -s[0, 0], -s[1, 1], -s[2, 2], p, q]


steps_row = max(1, round(INTERVAL / (RATE * O.dt)))
n_rows = math.ceil(AXIAL / (steps_row * RATE * O.dt) - 1e-9)
rows = [row()]
t = 0.0
lat = np.zeros(2)
c = np.zeros(3)


def servo():
    """Every EVERY steps: sample the stress, set the cell's velocity gradient."""
    global c
    s = np.array(utils.getStress())
    if O.iter % (10 * EVERY) == 0:
        c = stiffness()
    for a in range(2):
        err = -CONF - s[a, a]
        rate = (GAIN * err / (c[a] * O.dt) if c[a] > 0
                else (MAX_RATE if err > 0 else -MAX_RATE))
        lat[a] = min(max(rate, -MAX_RATE), MAX_RATE)
    O.cell.velGrad = Matrix3(lat[0], 0, 0, 0, lat[1], 0, 0, 0, -RATE / (1.0 - RATE * O.time))


O.engines = O.engines[:3] + [PyRunner(command="servo()", iterPeriod=EVERY)] + O.engines[3:]
for k in range(n_rows):
    O.run(steps_row, True)
    rows.append(row())
    if k % 10 == 0:
        print(k, n_rows, rows[-1][:3], flush=True)
np.savetxt(out, np.array(rows), delimiter=",",
           header="axial_strain,q_over_p,volumetric_strain,sigma_xx,sigma_yy,sigma_zz,p,q",
           comments="")
