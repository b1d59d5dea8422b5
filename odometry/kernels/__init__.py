"""Compiled inner loops of the odometry (numba): one pass over the rows where numpy needs a dozen.

The odometry's per-frame arrays are thousands of rows, not millions: a numpy
expression over them costs more in its calls and temporaries than in its
arithmetic (a frame of the default made about 12,000 numpy calls before them). These
kernels fuse the few hottest chains into one loop each, a module per idea they
serve (``plane_system``, ``normals``, ``ncf``, ``screw``, ``nearest``,
``voxel_hash``, ``range_image``, ``gcr``, ``poles``, ``free_space``); each one's
docstring names the numpy expression it computes, which the tests compare it against
(``isolation``'s ring look has none: its tests are walls and flakes whose answer is known). Compiled
on first use and cached beside these files (``cache=True``), so a process pays
the compilation once per machine, not per run.
"""
