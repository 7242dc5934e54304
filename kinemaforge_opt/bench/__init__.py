"""``kinemaforge bench``: the benchmark.

* :mod:`.discovery` — mismatch discovery (diagnose vs :mod:`.baselines`) on concealed effects;
* :mod:`.stages` — real Sturm logs, calibration on the demo door, time per stage and scaling;
* :mod:`.report` — JSON, Markdown and PNG output (placeholders for the RGB-D tables);
* :mod:`.run` — the sizes (``QUICK``, ``FULL``) and the runner.
"""

from .run import FULL, QUICK, Size, run_bench

__all__ = ["FULL", "QUICK", "Size", "run_bench"]
