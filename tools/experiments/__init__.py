"""The experiments of the SALO paper, on simulated data (``salo experiment ...``).

One module per idea:

- ``records``:       run folders: provenance (``run.json``), JSON / CSV / Markdown writers.
- ``suite``:         the simulated sequences an experiment runs on, cached on disk by parameters.
- ``peer``:          what the peer methods share (optional extra ``peer``): availability, the run
                     loop, the conversion of their poses to sweep starts.
- ``peer_kiss_icp``, ``peer_genz_icp``, ``peer_small_gicp``: one runner per peer, through its Python API.
- ``truth``:         true correspondences between two scans, from the simulator's sidecar.
- ``table``:         Table I: mean / std of the relative error per 100 m, BL / NCF / SALO and the peers.
- ``rejector_study``: Sec. IV-A / Fig. 3: GCR against the distance rejector from perturbed guesses.
- ``ncf_study``:     NCF's predicted normal uncertainty against the true normal error.
- ``plots``:         every figure (matplotlib, imported inside the functions).
- ``report``:        one HTML or Markdown page from a results folder.

Library code logs and shows optional progress bars; the commands
(``tools.cli.experiment``) and ``tools.demo`` print.
"""
