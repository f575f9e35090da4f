"""Small builders shared by the MPM tests."""

from pathlib import Path

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


def small_case(tmp_path, *, grid="cells = [2, 2, 2]", solver="", hi="[0.1, 0.1, 0.1]",
               extra="") -> Path:
    """A minimal elastic case file (0.1 m cells, one box body from the origin to `hi`)
    written to tmp_path/case.toml, with lines added to [grid] and [solver] and tables
    appended (`extra`)."""
    p = tmp_path / "case.toml"
    p.write_text(f"""
[grid]
cell_size = 0.1
{grid}
[solver]
{solver}
[time]
end = 1.0
[materials.m]
type = "linear_elastic"
density = 1000.0
youngs_modulus = 1e6
poisson_ratio = 0.3
[[bodies]]
shape = "box"
material = "m"
lo = [0, 0, 0]
hi = {hi}
[output]
interval = 0.1
{extra}
""")
    return p


def run(s: MPMState, t_end: float, record=None):
    from grainscale.mpm.step import step

    while s.time < t_end - 1e-15:
        dt = min(s.stable_dt(), t_end - s.time)
        step(s, dt)
        if record is not None:
            record(s)
    return s


def impulse_errors(s: MPMState, t_end: float, weight: float) -> list[float]:
    """Step to t_end; per step, the material's vertical momentum change less the impulse
    of gravity and the rigid body, -dt (m g + F_z), over dt m g."""
    from grainscale.mpm.step import step

    errors = []
    while s.time < t_end - 1e-12:
        dt = min(s.stable_dt(), t_end - s.time)
        before = s.points.m @ s.points.v
        step(s, dt)
        change = s.points.m @ s.points.v - before
        errors.append((change[2] + dt * (weight + s.rigid.force[2])) / (dt * weight))
    return errors
