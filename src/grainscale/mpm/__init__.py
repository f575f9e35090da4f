"""Explicit 3D Material Point Method: grid, GIMP/linear shape functions, fixed-point
(deterministic) transfers, the USF/USL/MUSL step, boundary conditions, rigid bodies and
phenomenological materials. Never imports `grainscale.dem`. See docs/mpm.md."""
