"""Small builders shared by the MPM tests (no case file needed)."""


from grainscale.mpm import boundary
from grainscale.mpm.grid import Grid
from grainscale.mpm.materials import LinearElastic
from grainscale.mpm.points import fill_box, make_points
from grainscale.mpm.step import MPMState


def elastic_box(grid: Grid, lo, hi, n=2, E=1e6, nu=0.3, rho=1000.0, **kw) -> MPMState:
    x, vol = fill_box(grid, lo, hi, n)
    pts = make_points(x, vol, rho, 0)
    mat = LinearElastic("m", pts.n, density=rho, youngs_modulus=E, poisson_ratio=nu)
    return MPMState(grid=grid, points=pts, materials=[mat], mat_points=[None], **kw)


def rollers(grid: Grid, faces) -> list:
    out = []
    for f in faces:
        axis = boundary.FACES[f][0]
        out.append(boundary.constraint(boundary.face_nodes(grid, f), "roller", axis))
    return out


def run(s: MPMState, t_end: float, record=None):
    from grainscale.mpm.step import step

    while s.time < t_end - 1e-15:
        dt = min(s.stable_dt(), t_end - s.time)
        step(s, dt)
        if record is not None:
            record(s)
    return s
