"""``kinemaforge bench``: the benchmark.

* :mod:`.discovery` — mismatch discovery (diagnose vs :mod:`.baselines`) on concealed effects;
* :mod:`.stages` — real Sturm logs, calibration on the demo door, time per stage and scaling;
* :func:`kinemaforge_opt.arm.side_by_side.compare_arm_models` — the robot arm: nominal vs IDIM-LS
  vs kinemaforge_opt (held-out torque and tracking RMS);
* :mod:`.reconstruction` — the RGB-D reconstruction benchmark (seed Table 1 and Table 2, drift vs
  horizon, sensitivity to the energy weight and the number of views, time per stage vs frames,
  views and joints), scored with :mod:`.metrics`, tabulated by :mod:`.reco_report`;
* :mod:`.report` — JSON, Markdown and PNG output;
* :mod:`.run` — the sizes (``QUICK``, ``FULL``) and the runner.
"""

from .run import FULL, QUICK, Size, run_bench

__all__ = ["FULL", "QUICK", "Size", "run_bench"]
