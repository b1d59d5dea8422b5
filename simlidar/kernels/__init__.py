"""Compiled per-return passes of the simulator (numba): one loop where numpy made a dozen passes.

A sweep's returns are a hundred thousand rows or more; after Embree has named the
triangle each ray hits, numpy's expressions over them (gathers, products, the
rotation into the scan frame, the noise, the intensity) each read and write every
row again. These kernels fuse them into one loop per stage, a module per idea:
``sweep`` (the plane solve after the cast, the measured range, the scan's rows and the
moving objects' truth rows), ``actors`` (which rays may meet each actor, the rays in its
frame, the nearest hits and their merge), ``files`` (a frame's scan records, truth sections
and octahedral normal codes), ``information`` (the point-to-plane information of the
degeneracy figures). Each docstring names the numpy expression
it replaces; the tests compare them bit for bit, and a simulated sequence's files
keep their sha256 (``docs/traffic.md``, "Cost"). Where numpy's own loops round in a
particular order (its 3-element dot sums ``(a0 + a2) + a1``; BLAS's small products are
fused multiply-adds, ``fma(x2, m2, fma(x1, m1, x0 m0))``) the kernels round the same
way, through ``fma.fma``. Compiled on first use and cached beside these files
(``cache=True``).
"""
