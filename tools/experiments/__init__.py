"""The experiments of the SALO paper, on simulated data (``salo experiment ...``).

One module per idea:

- ``truth``:         true correspondences between two scans, from the simulator's sidecar.
- ``levels``, ``map_target``: the rejector study's perturbation levels and its map target.
- ``table``:         Table I: mean / std of the relative error per 100 m, BL / NCF / SALO and the peers.
- ``rejector_study``: Sec. IV-A / Fig. 3: GCR against the distance rejector from perturbed guesses.
- ``ncf_study``:     NCF's predicted normal uncertainty against the true normal error.
- ``generalize``:    every method on the held-out suite of scene families (``tools.family_suite``).
- ``plots``:         the experiments' own figures (matplotlib, imported inside the functions).
- ``report``:        one HTML or Markdown page from a results folder.

They build on what the rest of ``tools`` shares, and nothing outside the experiments
(and their commands) imports them: the methods and their one interface
(``tools.methods.run_method``; the peers in ``tools.peers``), run folders and writers
(``tools.records``), the cached simulated sequences (``tools.sequence_cache``), the shared
figures (``tools.plotting``) and the Markdown-to-HTML page (``tools.html_page``).

Library code logs and shows optional progress bars; the commands
(``tools.cli.experiment``) print.
"""
